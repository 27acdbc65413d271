"""``fingerfit session``: assemble a session from loose recordings, all or nothing."""

from __future__ import annotations

import numpy as np
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.io import load_session
from fingerfit.simulate import write_subject

from .conftest import subject


def _args(src, out, **extra):
    args = [
        "session",
        str(out),
        "--subject",
        "P7",
        "--hand",
        "left",
        "--rate",
        "240",
        "--reference",
        str(src / "reference.csv"),
        "--grasp",
        str(src / "grasp.csv"),
        "--landmarks",
        str(src / "landmarks.csv"),
        "--targets",
        str(src / "targets.csv"),
        "--test",
        str(src / "test.csv"),
        "--events",
        str(src / "events.csv"),
    ]
    for k, v in extra.items():
        args += [f"--{k}", v]
    return args


def test_assembles_a_loadable_session_byte_for_byte(tmp_path) -> None:
    src = write_subject(subject("realistic", 2), tmp_path / "src")
    res = CliRunner().invoke(app, _args(src, tmp_path / "P7"))
    assert res.exit_code == 0, res.output
    s, ref = load_session(tmp_path / "P7"), load_session(src)
    assert s.subject == "P7" and [r.name for r in s.recordings()] == [
        r.name for r in ref.recordings()
    ]
    for name in ("grasp.csv", "landmarks.csv", "events.csv"):
        assert (tmp_path / "P7" / name).read_bytes() == (src / name).read_bytes()
    np.testing.assert_array_equal(
        s.grasp[0].poses["hand"].position, ref.grasp[0].poses["hand"].position
    )


def test_bad_recording_leaves_nothing_behind(tmp_path) -> None:
    src = write_subject(subject("realistic", 2), tmp_path / "src")
    lines = (src / "grasp.csv").read_text().splitlines()
    (src / "grasp.csv").write_text(
        "\n".join(ln for ln in lines if ",index.distal," not in ln) + "\n"
    )
    res = CliRunner().invoke(app, _args(src, tmp_path / "P7"))
    assert res.exit_code == 2
    assert "grasp.csv: no samples for sensor 'index.distal'" in res.output
    assert not (tmp_path / "P7").exists()
    assert not list(tmp_path.glob(".P7*"))
