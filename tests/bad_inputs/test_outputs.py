"""Outputs: version, verbatim user text, no writes onto inputs, all-or-nothing files.

Items 6, 7, 8, 12, 13 and 14 of the trust issue; every refusal is one ``error:`` line,
exit 2, and the folders involved are unchanged.
"""

from __future__ import annotations

import importlib.util
import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from fingerfit import __version__
from fingerfit.simulate import write_subject
from fingerfit.simulate.trackerfiles import write_tracker_subject

from ..conftest import subject
from ._cli import listing, refused, run

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def fitted(tmp_path_factory) -> Path:
    """A realistic simulated session fitted by ``fingerfit fit`` (model.json inside)."""
    d = write_subject(subject("realistic", 2), tmp_path_factory.mktemp("fit") / "S")
    res = run("fit", d)
    assert res.exit_code == 0, res.output
    return d


def test_version_from_the_console_script() -> None:
    exe = Path(sys.executable).with_name("fingerfit")
    res = subprocess.run([exe, "--version"], capture_output=True, text=True, check=False)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"fingerfit {__version__}"


def test_user_text_is_printed_verbatim(tmp_path: Path) -> None:
    weird = tmp_path / "s:x: [bold]P[/bold] :thumbs_up:"
    write_subject(subject("realistic", 2), weird)
    res = run("fit", weird)
    assert res.exit_code == 0, res.output
    flat = re.sub(r"\s+", "", res.output)
    assert re.sub(r"\s+", "", str(weird / "model.json")) in flat
    assert "❌" not in res.output and "👍" not in res.output
    # and in an error line
    line = refused(run("fit", tmp_path / ":x: [red]nope[/red]"))
    assert ":x: [red]nope[/red]" in line


def test_session_errors_name_the_users_folder(tmp_path: Path) -> None:
    src = write_subject(subject("realistic", 2), tmp_path / "src")
    events = (src / "events.csv").read_text().splitlines()
    events[1] = "nosuch.csv," + events[1].split(",", 1)[1]
    (src / "events.csv").write_text("\n".join(events) + "\n")
    out = tmp_path / "P7"
    before = listing(tmp_path)
    res = run(
        "session", out, "--subject", "P7", "--reference", src / "reference.csv",
        "--grasp", src / "grasp.csv", "--landmarks", src / "landmarks.csv",
        "--events", src / "events.csv",
    )  # fmt: skip
    line = refused(res, str(out / "events.csv"), "nosuch.csv")
    assert ".partial" not in line
    assert listing(tmp_path) == before


@pytest.mark.parametrize("target", ["recording", "model", "link"])
def test_angles_never_writes_onto_an_input(fitted: Path, tmp_path: Path, target: str) -> None:
    rec, model = fitted / "grasp.csv", fitted / "model.json"
    link = tmp_path / "alias.csv"
    link.symlink_to(rec)
    dest = {"recording": rec, "model": model, "link": link}[target]
    before = listing(fitted, tmp_path)
    line = refused(run("angles", model, rec, "-o", dest), "would overwrite the input")
    assert str(dest) in line
    assert listing(fitted, tmp_path) == before


def test_angles_urdf_names_onto_an_input_writes_nothing(fitted: Path, tmp_path: Path) -> None:
    before = listing(fitted, tmp_path)
    res = run(
        "angles", fitted / "model.json", fitted / "grasp.csv", "-o", tmp_path / "a.csv",
        "--urdf-names", fitted / "model.json",
    )  # fmt: skip
    refused(res, "would overwrite the input")
    assert listing(fitted, tmp_path) == before


needs_robot = pytest.mark.skipif(
    not all(importlib.util.find_spec(m) for m in ("yourdfpy", "mujoco")),
    reason="robot export needs the extra fingerfit[robot] (yourdfpy, mujoco)",
)


@needs_robot
def test_export_is_all_or_nothing_when_one_target_is_a_folder(fitted, tmp_path) -> None:
    (tmp_path / "h.urdf").mkdir()
    before = listing(tmp_path)
    res = run(
        "export", fitted / "model.json", "--urdf", tmp_path / "h.urdf", "--mjcf", tmp_path / "h.xml"
    )
    refused(res, str(tmp_path / "h.urdf"), "is a folder")
    assert listing(tmp_path) == before


@needs_robot
def test_export_replaces_only_with_overwrite(fitted: Path, tmp_path: Path) -> None:
    urdf, mjcf = tmp_path / "h.urdf", tmp_path / "h.xml"
    urdf.write_text("old urdf")
    before = listing(tmp_path)
    res = run("export", fitted / "model.json", "--urdf", urdf, "--mjcf", mjcf)
    refused(res, str(urdf), "exists", "--overwrite")
    assert listing(tmp_path) == before
    res = run("export", fitted / "model.json", "--urdf", urdf, "--mjcf", mjcf, "--overwrite")
    assert res.exit_code == 0, res.output
    assert urdf.read_text().startswith("<") and mjcf.read_text().startswith("<")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.urdf", "h.xml"]


@needs_robot
def test_export_refuses_a_read_only_target_even_as_root(fitted: Path, tmp_path: Path) -> None:
    urdf, mjcf = tmp_path / "h.urdf", tmp_path / "h.xml"
    urdf.write_text("keep me")
    os.chmod(urdf, stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)
    before = listing(tmp_path)
    res = run("export", fitted / "model.json", "--urdf", urdf, "--mjcf", mjcf, "--overwrite")
    refused(res, str(urdf), "read-only")
    assert listing(tmp_path) == before and urdf.read_text() == "keep me"


@needs_robot
def test_export_never_writes_onto_its_model(fitted: Path) -> None:
    before = listing(fitted)
    res = run("export", fitted / "model.json", "--urdf", fitted / "model.json", "--overwrite")
    refused(res, "would overwrite the input")
    assert listing(fitted) == before


def test_quick_start_environment_has_every_extra_the_readme_uses() -> None:
    make = (ROOT / "Makefile").read_text()
    demo_install = re.search(
        r'^\$\(BIN\)/fingerfit:.*?pip install --quiet -e "\.\[([^\]]*)\]"', make, re.S | re.M
    )
    assert demo_install, "the .venv bootstrap rule installs fingerfit with extras"
    extras = set(demo_install.group(1).split(","))
    readme = (ROOT / "README.md").read_text()
    needed = {"stats"}  # the study's ANOVA
    if re.search(r"--from c3d|\bc3d\b", readme):
        needed.add("c3d")
    if "fingerfit export" in readme:
        needed.add("robot")
    assert needed <= extras, f"make demo's environment lacks {needed - extras}"


@pytest.mark.parametrize("name", ["grasp.csv", "session.toml", "landmarks.csv"])
def test_fit_never_writes_onto_a_session_file(tmp_path: Path, name: str) -> None:
    d = write_subject(subject("realistic", 2), tmp_path / "S")
    before = listing(tmp_path)
    line = refused(run("fit", d, "-o", d / name), "would overwrite the input")
    assert str(d / name) in line
    assert listing(tmp_path) == before


def test_convert_never_writes_onto_its_source(tmp_path: Path) -> None:
    d = write_subject(subject("realistic", 2), tmp_path / "S")
    liberty = write_tracker_subject(subject("realistic", 2), tmp_path / "L", "liberty-ascii")
    src = liberty.files["grasp.csv"]
    alias = tmp_path / "alias.txt"
    os.link(src, alias)  # a hard link: another name of the same file
    before = listing(tmp_path)
    res = run("convert", src, "-o", alias, "--from", "liberty", "--items", "2,7,9,1",
              "--rate", "240", "--map", "1=hand,2=index.proximal,3=index.middle,4=index.distal")  # fmt: skip
    refused(res, "would overwrite the input", str(alias))
    assert listing(tmp_path) == before and d.is_dir()


def test_a_failed_write_leaves_no_folder_it_made(tmp_path: Path) -> None:
    """A file or a folder written all-or-nothing into folders that did not exist: on
    failure the new folders go too; a folder that existed, or holds something else, stays."""
    from fingerfit.io.atomic import atomic_write, staged_directory, write_files

    (tmp_path / "old").mkdir()
    with pytest.raises(RuntimeError), atomic_write(tmp_path / "a/b/f.txt") as fh:
        fh.write("half")
        raise RuntimeError("fails part-way")
    with pytest.raises(KeyboardInterrupt), staged_directory(tmp_path / "old/c/d/out") as tmp:
        (tmp / "x.txt").write_text("half")
        raise KeyboardInterrupt
    with pytest.raises(TypeError):  # the second file's content cannot be written
        write_files({tmp_path / "e/f/g.txt": "x", tmp_path / "e/i/h.txt": None})  # type: ignore[dict-item]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old"]
    assert not any((tmp_path / "old").iterdir())
    with pytest.raises(RuntimeError), staged_directory(tmp_path / "new/out"):
        (tmp_path / "new" / "other.txt").write_text("someone else's")
        raise RuntimeError
    assert (tmp_path / "new" / "other.txt").exists()  # not removed: not empty


def test_quiet_prints_no_table(fitted: Path, tmp_path: Path) -> None:
    """``-q`` on ``fit`` and ``joint`` leaves out the table (only the line naming the file
    written); ``export -q`` prints nothing; without it each prints its table or line."""
    for quiet in ([], ["-q"]):
        res = run("fit", fitted, "-o", tmp_path / f"m{len(quiet)}.json", *quiet)
        assert res.exit_code == 0, res.output
        assert ("s5/s6" in res.output) is not bool(quiet), res.output
        assert f"model written to {tmp_path / f'm{len(quiet)}.json'}" in res.output
        j = tmp_path / f"j{len(quiet)}.json"
        res = run("joint", fitted / "grasp.csv", "--parent", "index.proximal", "--child",
                  "index.middle", "--kind", "hinge", "-o", j, *quiet)  # fmt: skip
        assert res.exit_code == 0, res.output
        assert ("pivot residual" in res.output) is not bool(quiet), res.output
        assert f"joint written to {j}" in res.output and j.exists()
        res = run("export", fitted / "model.json", "--urdf", tmp_path / f"h{len(quiet)}.urdf",
                  *quiet)  # fmt: skip
        assert res.exit_code == 0, res.output
        assert (res.output.strip() == "") is bool(quiet), res.output
