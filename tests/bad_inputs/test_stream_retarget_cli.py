"""`fingerfit stream --retarget` refuses a bad robot, map or option before the source opens:
one line naming the file and field, exit 2, nothing written."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")
pytest.importorskip("rosbags")

from .._live import fitted, write_recording
from ..test_retarget import MAP, ROBOT_XML
from ._cli import listing, refused, run

#: The toy map without its index finger: none of the (index-only) model's digits.
MIDDLE_ONLY = MAP.replace(
    '[digits.index]\ntip = "a_tip"\nbase = "a_mp"\n[digits.index.joints]\n'
    'mp = { robot = "a_mp", sign = -1, scale = 0.5, offset = 0.1 }\npip = "a_pip"\n',
    "",
)


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """Inputs: model.json (index finger), rec.csv, the toy robot toy.xml and maps."""
    _, model_src = fitted()
    d = tmp_path_factory.mktemp("stream-retarget")
    (d / "model.json").write_bytes(model_src.read_bytes())
    write_recording(d / "rec.csv", 48)
    (d / "toy.xml").write_text(ROBOT_XML)
    (d / "toy.toml").write_text(MAP)
    (d / "bad.toml").write_text(MAP.replace('tip = "a_tip"', 'tip = "nope"'))
    (d / "middle.toml").write_text(MIDDLE_ONLY)
    (d / "notoml.toml").write_text(MAP.replace("[robot]", "[robot\n"))
    return d


def _subst(d: Path, args: list[str]) -> list[str]:
    return [a.replace("DIR", str(d)) for a in args]


CASES = [
    # (args after MODEL (DIR = the inputs' folder), fragments of the one error line)
    (["--retarget", "optimus"], ["--retarget", "unknown robot 'optimus'"]),
    (["--retarget", "DIR/toy.xml"], ["--map", "needs a map"]),
    (
        ["--retarget", "DIR/toy.xml", "--map", "DIR/bad.toml"],
        ["bad.toml", "digits.index.tip", "unknown robot frame 'nope'"],
    ),
    (["--retarget", "DIR/toy.xml", "--map", "DIR/notoml.toml"], ["notoml.toml", "not valid TOML"]),
    (["--retarget", "DIR/toy.xml", "--map", "DIR/gone.toml"], ["gone.toml", "not found"]),
    (
        ["--retarget", "DIR/toy.xml", "--map", "DIR/middle.toml"],
        ["middle.toml", "field 'digits'", "none of the map's"],
    ),
    (["--retarget", "DIR/toy.urdf", "--map", "DIR/toy.toml"], ["toy.urdf", "not found"]),
    (["--retarget", "shadow", "--method", "magic"], ["--method", "tip, joint"]),
    (["--retarget", "shadow", "--contact-mm=-1"], ["--contact-mm", ">= 0"]),
    (["--map", "DIR/toy.toml"], ["--map", "only with --retarget"]),
    (["--method", "joint"], ["--method", "only with --retarget"]),
    (["--orthogonal"], ["--orthogonal", "only with --retarget"]),
    (["--contact-mm", "5"], ["--contact-mm", "only with --retarget"]),
    (
        ["--retarget", "DIR/toy.xml", "--map", "DIR/toy.toml", "--record", "DIR/toy.toml"],
        ["toy.toml", "would overwrite the input"],
    ),
]


@pytest.mark.parametrize("source", ["replay:DIR/rec.csv", "liberty:DIR/no-such-tty"])
@pytest.mark.parametrize(("args", "fragments"), CASES)
def test_refused_before_the_source_opens(folder, source, args, fragments) -> None:
    """The same line whether the source would open (a replay) or not (a serial port that
    does not exist): the robot and the map are checked first; no output appears."""
    out = folder / "out"
    before = listing(folder)
    outputs = (
        [] if "--record" in args else ["--record", out / "live.csv", "--ros2-bag", out / "bag"]
    )
    spec = _subst(folder, [source])[0]
    r = run(
        "stream", folder / "model.json", "--source", spec, *_subst(folder, args), *outputs, "-q"
    )
    line = refused(r, *fragments)
    assert "no-such-tty" not in line
    assert listing(folder) == before and not out.exists()


def test_missing_optional_package_is_one_line(folder, monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` raises ImportError
    before = listing(folder)
    r = run(
        "stream", folder / "model.json", "--source", f"replay:{folder / 'rec.csv'}",
        "--retarget", "shadow", "--record", folder / "out" / "live.csv", "-q",
    )  # fmt: skip
    refused(r, "'mujoco'", "pip install fingerfit[retarget]")
    assert listing(folder) == before and not (folder / "out").exists()


def test_a_robot_file_with_its_map_streams(folder, tmp_path: Path) -> None:
    """The same toy robot and map stream (exit 0): the bag holds its three joints."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    bag = tmp_path / "bag"
    r = run(
        "stream", folder / "model.json", "--source", f"replay:{folder / 'rec.csv'}@50",
        "--retarget", folder / "toy.xml", "--map", folder / "toy.toml", "--ros2-bag", bag, "-q",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(bag) as reader:
        topics = [c.topic for c, _, _ in reader.messages()]
        msgs = [
            store.deserialize_cdr(raw, c.msgtype)
            for c, _, raw in reader.messages()
            if not c.topic.endswith("/source")
        ]
    assert len(msgs) == 48 and list(msgs[0].name) == ["a_mp", "a_pip", "b_mp"]
    assert sum(t.endswith("/source") for t in topics) == 1  # every sensor there throughout
