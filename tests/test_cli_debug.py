"""The global ``--debug``: an unexpected exception (a bug, not bad input) with its traceback.

Without it the study names an unexpected exception of a session in one line (exit 2);
with it the exception is raised as it is and Python shows its traceback (exit 1). Run in
a subprocess, as a user sees it; the study's worker processes through the API.
"""

from __future__ import annotations

import contextlib
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from fingerfit.errors import FingerfitError
from fingerfit.evaluate import run_study
from fingerfit.simulate import write_subject

from .conftest import subject

_PROBE = """
import sys
import fingerfit.evaluate.subject as subject

def a_bug_in_the_fit(*_args, **_kwargs):
    raise ValueError("a bug in the fit")

subject.evaluate_subject = a_bug_in_the_fit
from fingerfit.cli import main
sys.argv = ["fingerfit", *sys.argv[1:]]
main()
"""


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    return write_subject(subject("exact", 3), tmp_path_factory.mktemp("debug") / "S01")


def _study(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", _PROBE, *args], capture_output=True, text=True, timeout=120
    )


def test_study_error_is_one_line_and_with_debug_its_traceback(session, tmp_path) -> None:
    plain = _study("study", str(session), "--out", str(tmp_path / "a"))
    assert plain.returncode == 2, plain.stderr
    lines = [ln for ln in plain.stderr.splitlines() if ln.strip()]
    assert lines == [
        "error: S01: unexpected ValueError while fitting and evaluating (a bug in the fit); "
        "please report this"
    ]
    debug = _study("--debug", "study", str(session), "--out", str(tmp_path / "b"))
    assert debug.returncode == 1, debug.stderr
    assert "Traceback (most recent call last)" in debug.stderr
    assert "in a_bug_in_the_fit" in debug.stderr
    assert debug.stderr.rstrip().endswith("ValueError: a bug in the fit")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_debug_is_in_the_help_and_changes_no_bad_input_error(session, tmp_path) -> None:
    from typer.testing import CliRunner

    from fingerfit.cli import app

    assert "--debug" in CliRunner().invoke(app, ["--help"]).output
    res = CliRunner().invoke(app, ["--debug", "study", str(tmp_path / "none"), "--out", "x"])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert res.output.startswith("error: ")


class BrokenSource:
    """A session source with a bug: making its folder raises an unexpected error."""

    def __str__(self) -> str:
        return "broken-source"

    @contextlib.contextmanager
    def open(self) -> Iterator[Path]:
        raise KeyError("a bug in the source")
        yield Path()  # pragma: no cover


def test_a_workers_unexpected_error_with_debug(tmp_path) -> None:
    with pytest.raises(FingerfitError, match=r"^broken-source: could not be made \('a bug"):
        run_study([BrokenSource()], tmp_path / "a", jobs=2)
    with pytest.raises(KeyError, match="a bug in the source") as caught:
        run_study([BrokenSource()], tmp_path / "b", jobs=2, debug=True)
    # The worker's traceback comes along as the cause (concurrent.futures).
    assert "in open" in str(caught.value.__cause__)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
