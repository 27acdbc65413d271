"""``fingerfit simulate --format``: refusals leave every folder as it was."""

from __future__ import annotations

import shlex
import stat
import sys
from pathlib import Path

import pytest

from ._cli import listing, refused, run

SIM = ("--subjects", 1, "--seed", 3)


def test_output_folder_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "out").write_text("not a folder")
    before = listing(tmp_path)
    line = refused(run("simulate", "out", *SIM, "--format", "liberty-ascii", cwd=tmp_path))
    assert line == "error: out: exists and is not a folder"
    assert listing(tmp_path) == before


def test_subject_folder_is_a_file(tmp_path: Path) -> None:
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "S01").write_text("x")
    before = listing(tmp_path)
    refused(
        run("simulate", "out", *SIM, "--format", "liberty-binary", cwd=tmp_path),
        "out/S01: exists and is not a folder",
    )
    assert listing(tmp_path) == before


def test_existing_subject_needs_overwrite_and_then_is_replaced_whole(tmp_path: Path) -> None:
    res = run("simulate", "my out", *SIM, "--format", "liberty-ascii", cwd=tmp_path)
    assert res.exit_code == 0, res.output
    session = tmp_path / "my out" / "S01" / "session"
    session.mkdir()  # as if the printed commands had been run
    (session / "model.json").write_text("{}")
    before = listing(tmp_path)
    refused(
        run("simulate", "my out", *SIM, "--format", "c3d", cwd=tmp_path),
        "my out/S01: exists and is not empty; pass --overwrite",
    )
    assert listing(tmp_path) == before
    res = run("simulate", "my out", *SIM, "--format", "c3d", "--overwrite", cwd=tmp_path)
    assert res.exit_code == 0, res.output
    files = sorted(p.name for p in (tmp_path / "my out" / "S01").iterdir())
    assert files == [
        "events.csv",
        "grasp.c3d",
        "landmarks.csv",
        "reference.c3d",
        "targets.c3d",
        "test.c3d",
        "truth",
        "truth.json",
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["my out"]
    # the printed commands quote the folder name
    first = next(ln for ln in res.output.splitlines() if ln.startswith("fingerfit convert"))
    assert shlex.split(first)[2] == "my out/S01/reference.c3d"


def test_read_only_commands_file_is_not_replaced(tmp_path: Path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    script = out / "commands.sh"
    script.write_text("# mine\n")
    script.chmod(stat.S_IRUSR)
    before = listing(tmp_path)
    refused(
        run("simulate", "out", *SIM, "--format", "liberty-ascii", "--overwrite", cwd=tmp_path),
        "out/commands.sh: is read-only",
    )
    assert listing(tmp_path) == before


def test_c3d_without_ezc3d(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ezc3d", None)  # import ezc3d -> ImportError
    line = refused(
        run("simulate", "out", *SIM, "--format", "c3d", cwd=tmp_path),
        "writing C3D files needs the Python package 'ezc3d': pip install fingerfit[c3d]",
    )
    assert "--format" in line
    assert list(tmp_path.iterdir()) == []


def test_unknown_format(tmp_path: Path) -> None:
    res = run("simulate", "out", *SIM, "--format", "vicon", cwd=tmp_path)
    assert res.exit_code == 2
    assert "Traceback" not in res.output and "--format" in res.output
    assert list(tmp_path.iterdir()) == []
