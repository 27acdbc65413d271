"""Progress bars: shown on a terminal (stderr), never when piped or with --quiet."""

from __future__ import annotations

import importlib

import pytest
from rich.console import Console
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.simulate import write_subject

from .conftest import subject

cli_app = importlib.import_module("fingerfit.cli.app")  # the module, not the Typer app


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory):
    return write_subject(subject("exact", 11), tmp_path_factory.mktemp("progress") / "S")


def _run(args, terminal: bool, monkeypatch):
    if terminal:  # what a user at a terminal gets: stderr is a tty
        monkeypatch.setattr(
            cli_app, "console", Console(stderr=True, force_terminal=True, width=100)
        )
    return CliRunner().invoke(app, args)


@pytest.mark.parametrize(
    "command, shown",
    [
        (["fit", "{s}", "-o", "{t}/m.json", "--method", "tang2018"], "fitting 1 digit(s)"),
        (["simulate", "{t}/sim", "--subjects", "2", "--exact"], "simulating"),
    ],
)
def test_bar_on_a_terminal_only(command, shown, session_dir, tmp_path, monkeypatch) -> None:
    args = [a.format(s=session_dir, t=tmp_path) for a in command]
    res = _run(args, True, monkeypatch)
    assert res.exit_code == 0, res.output
    assert shown in res.stderr and "\x1b[" in res.stderr  # drawn, with cursor control
    quiet = tmp_path / "quiet"
    quiet.mkdir()
    args = [a.format(s=session_dir, t=quiet) for a in command]
    res = _run([*args, "--quiet"], True, monkeypatch)
    assert res.exit_code == 0, res.output
    assert shown not in res.stderr
    piped = tmp_path / "piped"
    piped.mkdir()
    args = [a.format(s=session_dir, t=piped) for a in command]
    monkeypatch.undo()
    res = _run(args, False, monkeypatch)
    assert res.exit_code == 0 and shown not in res.stderr and "\x1b[" not in res.stderr


def test_every_long_command_has_quiet() -> None:
    for command in ("convert", "session", "fit", "angles", "study", "demo", "simulate"):
        res = CliRunner().invoke(app, [command, "--help"])
        assert "--quiet" in res.output, command
