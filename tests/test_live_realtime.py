"""``--realtime``: one line saying what the OS granted, and a stream identical to one
without it (whether or not this machine grants it); the refused case by stand-ins.

"Identical" is to 1e-9, with the same empty fields: the data lane computes the frames in
blocks whose split follows the timing, and a different split changes the last bits of a
value (5.7e-14 deg here), with or without ``--realtime``.
"""

from __future__ import annotations

import errno
import os
import re
import threading
from pathlib import Path

import pandas as pd
import pytest

from fingerfit.io import write_pose_csv
from fingerfit.live import realtime as rt_mod
from fingerfit.live.outputs import RecordOutput
from fingerfit.live.realtime import Realtime
from fingerfit.live.sources import ReplaySource
from fingerfit.live.stream import Streamer, run
from fingerfit.model import load_model

from ._live import FakeLsl, fitted, short_recording
from .bad_inputs._cli import run as cli

pytestmark = pytest.mark.skipif(
    not hasattr(os, "sched_setscheduler"), reason="POSIX real-time scheduling"
)

LINE = re.compile(
    r"^realtime: SCHED_FIFO (50 granted( \(and to the outputs' \d+ threads?\))?"
    r"|not permitted \(E[A-Z]+\)), "
    r"memory (locked|lock not permitted \(E[A-Z]+\)), robot lane on CPU \d+"
)


def _same_csv(a: Path, b: Path) -> None:
    x, y = pd.read_csv(a), pd.read_csv(b)
    assert list(x.columns) == list(y.columns) and len(x) == len(y)
    pd.testing.assert_frame_equal(x, y, check_exact=False, rtol=0, atol=1e-9)


def _state() -> tuple:
    return os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0)


def test_cli_realtime_prints_one_line_and_streams_the_same(tmp_path: Path) -> None:
    _, model_path = fitted()
    csv = write_pose_csv(tmp_path / "rec.csv", short_recording(120))
    before = _state()
    outs = {}
    for flag in ([], ["--realtime"]):
        out = tmp_path / f"live{len(flag)}.csv"
        res = cli(
            "stream", model_path, "--source", f"replay:{csv}@4", "--record", out, "-q", *flag
        )  # fmt: skip
        assert res.exit_code == 0, res.output
        lines = [ln for ln in res.output.splitlines() if ln.startswith("realtime:")]
        assert len(lines) == (1 if flag else 0), res.output
        if flag:  # granted or not, the line says which; with only a file: the loop's CPU
            assert re.match(LINE.pattern.replace("robot lane", "stream loop"), lines[0])
        outs[bool(flag)] = out
    _same_csv(outs[True], outs[False])
    assert _state() == before  # the class, priority and CPUs given back


def test_robot_lane_realtime_line_and_the_same_record(tmp_path: Path) -> None:
    model = load_model(fitted()[1])
    rec = short_recording(120)
    got, notes = {}, []
    for realtime in (False, True):
        out = tmp_path / f"live{realtime}.csv"
        lsl = FakeLsl()
        streamer = Streamer(model, lsl=lsl, record=RecordOutput(out), record_units="mm")
        s = run(
            ReplaySource(rec, 4.0), streamer, status=False, realtime=realtime, note=notes.append
        )
        assert s.received == 120 == s.recorded == s.sent + s.skipped + s.stale
        got[realtime] = out
    assert len(notes) == 1 and LINE.match("realtime: " + notes[0]), notes
    if os.cpu_count() and len(os.sched_getaffinity(0)) > 1:
        assert "(data lane on CPU" in notes[0]
    _same_csv(got[True], got[False])


def test_refused_realtime_is_one_line_and_the_stream_runs(monkeypatch, tmp_path: Path) -> None:
    def refuse(*_):
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    monkeypatch.setattr(rt_mod, "mlockall", lambda: "ENOMEM")
    model = load_model(fitted()[1])
    notes: list[str] = []
    streamer = Streamer(model, lsl=FakeLsl())
    s = run(ReplaySource(short_recording(48), 4.0), streamer, status=False, realtime=True,
            note=notes.append)  # fmt: skip
    assert s.received == 48 == s.sent + s.skipped + s.stale
    assert len(notes) == 1
    assert notes[0].startswith(
        "SCHED_FIFO not permitted (EPERM), memory lock not permitted (ENOMEM), robot lane on CPU"
    )
    assert notes[0].endswith("; running at normal priority")


def test_realtime_line_wording() -> None:
    r = Realtime()
    r.fifo, r.locked, r.cpu, r.other_cpus = None, None, 1, [0]
    assert (
        r.line() == "SCHED_FIFO 50 granted, memory locked, robot lane on CPU 1 (data lane on CPU 0)"
    )
    r.raised = [101, 102]
    assert r.line().startswith("SCHED_FIFO 50 granted (and to the outputs' 2 threads), memory")
    r.fifo, r.locked, r.cpu, r.other_cpus, r.cpu_note = (
        "EPERM",
        "EPERM",
        0,
        [],
        "the only CPU allowed",
    )
    assert r.line() == (
        "SCHED_FIFO not permitted (EPERM), memory lock not permitted (EPERM), robot lane on "
        "CPU 0 (the only CPU allowed); running at normal priority"
    )
    r.fifo, r.locked, r.cpu, r.cpu_note = "not available on this system", "not available", None, ""
    assert r.line() == (
        "SCHED_FIFO not available on this system, memory lock not available; running at "
        "normal priority"
    )


def test_realtime_restores_a_thread_it_pinned() -> None:
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, daemon=True)
    t.start()
    before = os.sched_getaffinity(t.native_id), _state()
    with Realtime(others=[t]) as r:
        r.line()
    stop.set()
    assert (os.sched_getaffinity(t.native_id), _state()) == before
    t.join()


def test_the_outputs_threads_get_the_class_and_get_it_back() -> None:
    """The native threads a library started (Cyclone DDS's, here) are found, Python's are
    not; they get SCHED_FIFO with the robot lane's thread when it is granted, and their
    own class back at the end."""
    from cyclonedds.domain import DomainParticipant

    before = rt_mod.task_ids()
    stop = threading.Event()
    ours = threading.Thread(target=stop.wait, daemon=True)
    ours.start()
    participant = DomainParticipant(77)
    native = rt_mod.threads_started(before)
    assert native and ours.native_id not in native
    was = {t: os.sched_getscheduler(t) for t in native}
    with Realtime(threads=[*native, 2**22 + 12345]) as r:  # and one that does not exist
        if r.fifo is None:
            assert r.raised == native
            assert all(os.sched_getscheduler(t) == os.SCHED_FIFO for t in native)
            assert f"(and to the outputs' {len(native)} threads)" in r.line()
        else:
            assert r.raised == []
    assert {t: os.sched_getscheduler(t) for t in native} == was
    stop.set()
    ours.join()
    del participant
