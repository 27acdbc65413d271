"""`fingerfit stream` refuses bad input with one line, exit 2, and writes nothing."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from .._live import fitted, write_recording
from ._cli import listing, refused, run


@pytest.fixture(scope="module")
def setup(tmp_path_factory) -> tuple[Path, Path, Path]:
    """``(folder, model.json, recording.csv)``; the folder holds both inputs."""
    _, model_src = fitted()
    d = tmp_path_factory.mktemp("stream")
    model = d / "model.json"
    model.write_bytes(model_src.read_bytes())
    return d, model, write_recording(d / "rec.csv", 48)


CASES = [
    # (extra args (RECORDING/MODEL/DIR substituted), environment, fragments of the error line)
    (["--source", "rec.csv"], {}, ["--source", "not a source", "replay:FILE"]),
    (["--source", "serial:/dev/x"], {}, ["--source", "not a source"]),
    (["--source", "replay:DIR/none.csv"], {}, ["none.csv"]),
    (["--source", "replay:RECORDING@0"], {}, ["--source", "replay speed", "positive"]),
    (["--source", "replay:RECORDING@fast"], {}, ["--source", "replay speed", "'fast'"]),
    (["--source", "liberty:DIR/no-such-tty"], {}, ["no-such-tty", "cannot open the serial port"]),
    (["--source", "liberty:DIR/tty@9600.5"], {}, ["--source", "baud rate", "whole"]),
    (["--source", "replay:RECORDING", "--ros2", "1bad//topic"], {}, ["--ros2", "topic name"]),
    (
        ["--source", "replay:RECORDING", "--ros2", "/joint_states"],
        {"ROS_DOMAIN_ID": "abc"},
        ["ROS_DOMAIN_ID", "0-232"],
    ),
    (
        ["--source", "replay:RECORDING", "--ros2", "/joint_states"],
        {"ROS_DOMAIN_ID": "300"},
        ["ROS_DOMAIN_ID", "0-232"],
    ),
    (["--source", "replay:RECORDING", "--record", "RECORDING"], {}, ["rec.csv"]),
    (["--source", "replay:RECORDING", "--record", "MODEL"], {}, ["model.json"]),
    (["--source", "replay:RECORDING", "--ros2-bag", "DIR"], {}, ["exists", "new folder"]),
    (["--source", "liberty:DIR/tty", "--wait"], {}, ["--wait", "only a replay source"]),
    (["--source", "replay:RECORDING", "--stations", "1=hand"], {}, ["--stations", "liberty"]),
    (
        ["--source", "liberty:DIR/tty", "--stations", "1=hand,2=thumb.x"],
        {},
        ["--stations", "thumb.x"],
    ),
    (["--source", "liberty:DIR/tty", "--stations", "0=hand"], {}, ["--stations", "1-16"]),
    (
        ["--source", "liberty:DIR/tty", "--stations", "1=hand"],
        {},
        ["--stations", "no sensor on the digit", "would determine every joint"],
    ),
    (["--source", "replay:RECORDING", "--units", "m"], {}, ["rec.csv"]),
    (["--source", "replay:RECORDING", "--tips-frame", "world"], {}, ["--tips-frame"]),
]


@pytest.mark.parametrize(("args", "env", "fragments"), CASES)
def test_stream_refuses(setup, monkeypatch, args, env, fragments) -> None:
    d, model, rec = setup
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    sub = {"RECORDING": str(rec), "MODEL": str(model), "DIR": str(d)}
    args = [
        a.replace("RECORDING", sub["RECORDING"])
        .replace("MODEL", sub["MODEL"])
        .replace("DIR", sub["DIR"])
        for a in args
    ]
    before = listing(d)
    if "--record" not in args:
        args += ["--record", str(d / "out" / "live.csv")]
    res = run("stream", model, *args, "-q")
    if "--tips-frame" in fragments:  # typer's own usage error: exit 2, names the option
        assert res.exit_code == 2 and "--tips-frame" in res.output
    else:
        refused(res, *fragments)
    assert listing(d) == before
    assert not (d / "out").exists()


def test_missing_extra_is_one_line(setup, monkeypatch) -> None:
    d, model, rec = setup
    monkeypatch.setitem(sys.modules, "pylsl", None)  # import pylsl -> ImportError
    before = listing(d)
    res = run("stream", model, "--source", f"replay:{rec}", "--lsl", "--record", d / "o.csv")
    refused(res, "pylsl", "pip install fingerfit[live]")
    assert listing(d) == before


def test_wait_without_consumer_times_out(setup, monkeypatch) -> None:
    pytest.importorskip("pylsl")
    d, model, rec = setup
    before = listing(d)
    res = run(
        "stream", model, "--source", f"replay:{rec}", "--lsl", "--lsl-name", "ffnobody",
        "--wait", "--wait-timeout", "0.3", "--record", d / "new" / "o.csv",
        "--ros2-bag", d / "new2" / "bag", "-q",
    )  # fmt: skip
    refused(res, "--wait", "no consumer within 0.3 s")
    assert listing(d) == before
