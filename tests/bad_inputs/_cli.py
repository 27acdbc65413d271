"""Helpers of the bad-inputs suite: run the CLI, assert a clean refusal, compare folders."""

from __future__ import annotations

import os
import re
from pathlib import Path

from typer.testing import CliRunner

from fingerfit.cli import app

_ANSI = re.compile(r"\x1b\[[0-9;]*m")


def run(*args: object, cwd: Path | None = None):
    """Invoke ``fingerfit ARGS`` in-process (optionally in ``cwd``); returns the result."""
    old = Path.cwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        return CliRunner().invoke(app, [str(a) for a in args])
    finally:
        os.chdir(old)


def refused(result, *fragments: str) -> str:
    """Assert exit 2 and one ``error:`` line of our own containing every fragment; return it."""
    text = _ANSI.sub("", result.output)
    assert result.exit_code == 2, f"exit {result.exit_code}: {text}"
    assert "Traceback" not in text, text
    errors = [ln for ln in text.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, f"expected one error line: {text!r}"
    line = errors[0]
    for f in fragments:
        assert f in line, f"{f!r} not in {line!r}"
    return line


def listing(*folders: Path) -> dict[str, tuple[int, int]]:
    """Every file below the folders (hidden ones included) -> (size, mtime_ns)."""
    out = {}
    for folder in folders:
        for p in sorted(Path(folder).rglob("*")):
            if p.is_file() or p.is_symlink():
                st = p.lstat()
                out[str(p)] = (st.st_size, st.st_mtime_ns)
    return out
