"""``fingerfit capture``: a replayed grasp recorded into a session folder, with the fit's
own evidence per joint."""

from __future__ import annotations

import shutil
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.capture import EvidenceProcess, evidence, thresholds
from fingerfit.cli import app
from fingerfit.estimate import FitOptions
from fingerfit.estimate.cycles import extract_cycles
from fingerfit.io import load_session, read_pose_csv
from fingerfit.io.posewrite import write_pose_csv
from fingerfit.session import PoseSeries, joint_sensors
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.transforms import relative_pose

from .conftest import subject

DIGITS = ("index", "middle")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    sub = subject("realistic", 2, DIGITS)
    folder = write_subject(sub, tmp_path_factory.mktemp("capture") / "S01")
    return sub, folder


def _start(folder, tmp_path, name):
    """A new session folder holding only the reference and the landmarks."""
    new = tmp_path / name
    new.mkdir()
    for f in ("reference.csv", "landmarks.csv"):
        shutil.copyfile(folder / f, new / f)
    return new


def _capture(sub, new, source, protocol="grasp", digits=DIGITS, extra=()):
    return CliRunner().invoke(
        app,
        [
            "capture",
            str(new),
            "--source",
            source,
            "--protocol",
            protocol,
            "--subject",
            "S01",
            "--hand",
            sub.session.hand,
            "--units",
            sub.session.units,
            "--rate",
            str(sub.session.rate_hz),
            "--fingers",
            ",".join(digits),
            *extra,
        ],
    )


def _two_cycles(sub) -> int:
    """A frame after the second grasp cycle and before the third."""
    rec, s = sub.session.grasp[0], sub.session
    parent, child = joint_sensors("index")["pip"]
    ref = s.reference.pose(parent).mean()[1].T @ s.reference.pose(child).mean()[1]
    p, c = rec.pose(parent), rec.pose(child)
    r, _ = relative_pose(p.rotation, p.position, c.rotation, c.position)
    periods = extract_cycles(r, ref, s.rate_hz).periods
    assert len(periods) >= 4
    return int((periods[1].max() + periods[2].min()) // 2)


def _fits_and_assembles(
    new: Path, tmp_path: Path, hand: str, digits: list[str], grasp: list[str]
) -> None:
    """The folder capture wrote passes ``fingerfit fit``, and ``fingerfit session``
    assembles its files (reference, the ``grasp`` recordings, landmarks) into a session."""
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 0, res.output
    args = ["session", str(tmp_path / "assembled"), "--subject", "S01", "--hand", hand]
    args += ["--fingers", ",".join(digits), "--reference", str(new / "reference.csv")]
    for name in grasp:
        args += ["--grasp", str(new / name)]
    args += ["--landmarks", str(new / "landmarks.csv")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output


def test_thresholds_are_the_fits():
    o = FitOptions()
    assert thresholds() == (max(o.min_cycles, 2), o.min_rom_deg, o.max_axis_ci_deg)


def test_full_grasp_is_enough_and_the_folder_fits(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P01")
    grasp = folder / sub.session.grasp[0].name
    r = _capture(sub, new, f"replay:{grasp}@1000")
    assert r.exit_code == 0, r.output
    assert "enough for every joint" in r.output
    assert r.output.count("enough") >= 6  # one row per joint in the table
    rows = evidence(sub.session, list(DIGITS))
    assert all(row.enough for row in rows)
    assert max(row.axis_ci_deg for row in rows) < FitOptions().max_axis_ci_deg
    assert {row.joint: row.second for row in rows if row.digit == "index"} == {
        "mp": True,  # the simulated MP turns about two axes and the choice finds them
        "pip": None,
        "dip": None,
    }
    # The same frames as replayed, in the session's format.
    got = read_pose_csv(new / "grasp.csv", units=sub.session.units)
    want = read_pose_csv(grasp, units=sub.session.units)
    np.testing.assert_array_equal(got.time, want.time)
    for s in got.poses:
        np.testing.assert_array_equal(got.poses[s].position, want.poses[s].position)
    _fits_and_assembles(new, tmp_path, sub.session.hand, list(DIGITS), ["grasp.csv"])


def test_two_cycles_are_not_enough_as_the_fit_says(simulated, tmp_path):
    sub, folder = simulated
    cut = sub.session.grasp[0].slice(slice(0, _two_cycles(sub)))
    short = write_pose_csv(tmp_path / "cut.csv", cut, units=sub.session.units)
    new = _start(folder, tmp_path, "P02")
    r = _capture(sub, new, f"replay:{short}@1000")
    assert r.exit_code == 0, r.output
    assert "not enough for `fingerfit fit` yet" in r.output
    rows = evidence(replace(sub.session, grasp=[cut]), list(DIGITS))
    assert not any(row.enough for row in rows)
    assert max(row.cycles for row in rows) <= 2
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 2 and "cycle" in res.output  # the fit refuses it too


def test_a_folder_without_session_toml_needs_a_subject(simulated, tmp_path):
    _, folder = simulated
    new = _start(folder, tmp_path, "P03")
    r = CliRunner().invoke(
        app, ["capture", str(new), "--source", f"replay:{folder / 'grasp.csv'}@1000"]
    )
    assert r.exit_code == 2 and "--subject" in r.output
    assert not (new / "grasp.csv").exists()


def test_the_axis_confidence_narrows_as_cycles_are_added(simulated):
    sub, _ = simulated
    rec = sub.session.grasp[0]
    n = rec.n_frames

    def ci(frames: int) -> np.ndarray:
        cut = replace(sub.session, grasp=[rec.slice(slice(0, frames))])
        rows = evidence(cut, list(DIGITS))
        return np.array([r.axis_ci_deg for r in rows])

    third, half, full = ci(n // 3), ci(n // 2), ci(n)
    assert np.isfinite(third).all()
    assert np.mean(full) < np.mean(half) < np.mean(third)


@pytest.fixture(scope="module")
def with_thumb(tmp_path_factory):
    sub = simulate_subject(SimConfig(fingers=("thumb", "index")), 3)
    folder = write_subject(sub, tmp_path_factory.mktemp("capture_thumb") / "S01")
    return sub, folder


def test_thumb_protocol_after_the_grasp_is_enough_and_the_folder_fits(with_thumb, tmp_path):
    sub, folder = with_thumb
    digits = ("thumb", "index")
    new = _start(folder, tmp_path, "P04")
    r = _capture(sub, new, f"replay:{folder / 'grasp.csv'}@1000", "grasp", digits)
    assert r.exit_code == 0, r.output
    # A grasp alone does not turn the thumb's CMC about both axes: the capture says so,
    # and the fit refuses the CMC for the same reason.
    assert "thumb cmc" in r.output and "second axis not identified" in r.output
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 2 and "cmc" in res.output
    # The thumb protocol takes the circumduction next (its default name) and pools it
    # with the grasp, as the fit does.
    r = _capture(sub, new, f"replay:{folder / 'thumb_circumduction.csv'}@1000", "thumb", digits)
    assert r.exit_code == 0, r.output
    assert "enough for every joint" in r.output
    assert (new / "thumb_circumduction.csv").is_file()
    session = load_session(new)
    assert [g.name for g in session.grasp] == ["grasp.csv", "thumb_circumduction.csv"]
    rows = evidence(session, ["thumb"])
    assert [r.joint for r in rows if r.enough] == ["cmc", "mcp", "ip"]
    cmc = rows[0]
    assert cmc.second is True and cmc.axis_ci_deg < FitOptions().max_axis_ci_deg
    _fits_and_assembles(
        new, tmp_path, sub.session.hand, digits, ["grasp.csv", "thumb_circumduction.csv"]
    )


def test_thumb_protocol_needs_a_thumb(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P05")
    r = _capture(sub, new, f"replay:{folder / 'grasp.csv'}@1000", "thumb")
    assert r.exit_code == 2 and "--protocol" in r.output
    assert not (new / "thumb_circumduction.csv").exists()


def test_the_evidence_process_reports_what_evidence_gives(simulated):
    sub, _ = simulated
    rec = sub.session.grasp[0]
    base = replace(sub.session, grasp=[])
    child = EvidenceProcess(base, rec.name, list(rec.poses), list(DIGITS))
    try:
        for i in range(0, rec.n_frames, 500):
            child.add(rec.slice(slice(i, i + 500)))
        got, deadline = None, time.monotonic() + 300  # a guard, not a measurement
        while (got is None or got[1] < rec.n_frames) and time.monotonic() < deadline:
            got = child.latest() or got
            time.sleep(0.05)
    finally:
        child.close()
    assert got is not None and got[1] == rec.n_frames
    assert got[0] == evidence(replace(base, grasp=[rec]), list(DIGITS))


def _newest(series):
    """The value of a ``(frame, value)`` list at its last frame (the row logged last)."""
    return max(enumerate(series), key=lambda iv: (iv[1][0], iv[0]))[1]


def test_view_save_has_the_evidence_capture_prints_and_the_recording_is_whole(simulated, tmp_path):
    """``capture --view-save``: per joint the series, the bounds, the table and the
    sensors, the last update equal to the printed table; the recording the same as
    without the view."""
    pytest.importorskip("rerun")
    from fingerfit.capture import table_cells
    from fingerfit.session import digit_sensors

    from .test_view import _read

    sub, folder = simulated
    grasp = folder / sub.session.grasp[0].name
    plain, viewed = _start(folder, tmp_path, "P06"), _start(folder, tmp_path, "P07")
    rrd = tmp_path / "evidence.rrd"
    r = _capture(sub, plain, f"replay:{grasp}@1000")
    assert r.exit_code == 0, r.output
    r = _capture(sub, viewed, f"replay:{grasp}@1000", extra=["--view-save", str(rrd)])
    assert r.exit_code == 0, r.output
    assert f"view -> {rrd}" in r.output.replace("\n", "")
    # The recording is whole: the view takes nothing from it.
    assert (viewed / "grasp.csv").read_bytes() == (plain / "grasp.csv").read_bytes()
    rec = read_pose_csv(viewed / "grasp.csv", units=sub.session.units)
    last = rec.n_frames - 1

    rows, static = _read(rrd)
    printed = {}  # (digit, joint) -> the cells of the table's first line of the joint
    for line in r.output.splitlines():
        cells = [c.strip() for c in line.strip("│ ").split("│")]
        if len(cells) == 7 and cells[0] in DIGITS:
            printed[cells[0], cells[1]] = cells
    want = evidence(load_session(viewed), list(DIGITS))  # what capture printed
    assert set(printed) == {(w.digit, w.joint) for w in want}
    need = thresholds()
    for series, limit, value in (("axis_deg", "bound", need[2]), ("cycles", "needed", need[0]),
                                 ("rom_deg", "needed", need[1])):  # fmt: skip
        entity = f"/evidence/{series}/{limit}"
        assert "SeriesLines:names" in static[entity]
        assert _newest(rows[entity]["Scalars:scalars"]) == (last, [value])
    for w in want:
        got = {
            s: _newest(rows[f"/evidence/{s}/{w.digit}/{w.joint}"]["Scalars:scalars"])
            for s in ("axis_deg", "cycles", "rom_deg")
        }
        assert {v[0] for v in got.values()} == {last}  # the last update: the last frame
        shown = replace(
            w,
            cycles=int(got["cycles"][1][0]),
            rom_deg=got["rom_deg"][1][0],
            axis_ci_deg=got["axis_deg"][1][0],
        )
        cells = table_cells(shown)
        assert cells[2:5] == printed[w.digit, w.joint][2:5], (cells, printed)
        assert cells[6] == printed[w.digit, w.joint][6]
    frame, (text,) = _newest(rows["/evidence/table"]["TextDocument:text"])
    assert frame == last and text.startswith(f"**{rec.n_frames} frames")
    for w in want:  # the panel's rows: the printed cells, enough or more
        assert "| " + " | ".join(table_cells(w)) + " |" in text
    # The sensors' axes at the last frame, mm in the tracker frame.
    sensors = list(dict.fromkeys(s for d in DIGITS for s in digit_sensors(d)))
    frame, origins = _newest(rows["/sensors"]["Arrows3D:origins"])
    assert frame == last and len(origins) == 3 * len(sensors)
    expect = np.repeat([rec.poses[s].position[last] for s in sensors], 3, axis=0)
    np.testing.assert_allclose(np.array(origins), expect, atol=1e-3)


def test_view_options_are_refused_in_one_line(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P08")
    grasp = f"replay:{folder / 'grasp.csv'}@1000"
    r = _capture(sub, new, grasp, extra=["--view-save", str(tmp_path / "x.txt")])
    assert r.exit_code == 2 and ".rrd" in r.output
    r = _capture(sub, new, grasp, extra=["--view", "--view-save", str(tmp_path / "x.rrd")])
    assert r.exit_code == 2 and "--view" in r.output
    assert not (new / "grasp.csv").exists()


# --- Ctrl-C: what was recorded is kept, or nothing is left and the reason said ---------


def _listing(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())} if folder.exists() else {}


class _Replay:
    """A replay that sends this process a Ctrl-C (SIGINT) after ``after`` blocks."""

    def __init__(self, rec, after: int, size: int = 50):
        self.rec, self.after, self.size, self.closed = rec, after, size, False

    def blocks(self):
        import os
        import signal

        from fingerfit.live.sources import Block

        for k, i in enumerate(range(0, self.rec.n_frames, self.size)):
            if k == self.after:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(1.0)  # the handler raises before this ends
            part = self.rec.slice(slice(i, i + self.size))
            yield Block(part, np.zeros(part.n_frames))

    def close(self):
        self.closed = True


def _new_capture(sub, folder, tmp_path, name, extra=()):
    """``capture`` into a new folder, the reference and landmarks given as options."""
    return CliRunner().invoke(
        app,
        ["capture", str(tmp_path / name), "--source", f"replay:{folder / 'grasp.csv'}",
         "--subject", "S01", "--fingers", ",".join(DIGITS),
         "--reference", str(folder / "reference.csv"), "--landmarks", str(folder / "landmarks.csv"),
         *extra],
    )  # fmt: skip


@pytest.mark.parametrize("after", [0, 6])
def test_ctrl_c_while_recording_keeps_what_was_recorded(simulated, tmp_path, monkeypatch, after):
    import fingerfit.cli.capture as cli

    sub, folder = simulated
    rec = read_pose_csv(folder / "grasp.csv", units=sub.session.units)
    monkeypatch.setattr(cli, "open_source", lambda spec, **kw: _Replay(rec, after))
    r = _new_capture(sub, folder, tmp_path, "P09")
    new = tmp_path / "P09"
    if after == 0:  # before any frame: nothing left, and why
        assert r.exit_code == 2, r.output
        assert "interrupted before any frame was recorded; no file written" in r.output
        assert not new.exists()
        return
    assert r.exit_code == 0, r.output
    assert f"{after * 50} frames" in r.output and "(interrupted)" in r.output
    got = read_pose_csv(new / "grasp.csv", units=sub.session.units)
    np.testing.assert_array_equal(got.time, rec.time[: after * 50])
    assert sorted(_listing(new)) == ["grasp.csv", "landmarks.csv", "reference.csv", "session.toml"]
    assert load_session(new).grasp[0].n_frames == after * 50


def test_ctrl_c_before_recording_leaves_nothing(simulated, tmp_path, monkeypatch):
    """A Ctrl-C while the capture reads and checks the folder (here: the reference
    recording): no copy of --reference or --landmarks, no folder, the reason said."""
    import os
    import signal

    import fingerfit.io as fio

    sub, folder = simulated
    real = fio.read_pose_csv

    def read_and_interrupt(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)
        return real(*args, **kwargs)

    monkeypatch.setattr(fio, "read_pose_csv", read_and_interrupt)
    r = _new_capture(sub, folder, tmp_path, "P10")
    assert r.exit_code == 2, r.output
    assert "interrupted before recording began: nothing written" in r.output
    assert "Traceback" not in r.output
    assert not (tmp_path / "P10").exists()


def test_ctrl_c_after_recording_keeps_it_and_says_the_evidence_is_missing(
    simulated, tmp_path, monkeypatch
):
    """Ctrl-C twice: once while the files are written (held until they are), once in the
    final evidence: the recording is kept whole, the evidence said to be missing."""
    import os
    import signal

    import fingerfit.capture as cap
    from fingerfit.capture import folder as capture_folder

    sub, folder = simulated
    real_write, real_evidence = capture_folder.write_capture, cap.evidence

    def write_interrupted(plan, rec, extra=None):
        os.kill(os.getpid(), signal.SIGINT)  # held: the files are written first
        return real_write(plan, rec, extra)

    def evidence(session, digits, options=None, *, second=True):
        if second:  # the final evidence: Ctrl-C lands in it
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
        return real_evidence(session, digits, options, second=second)

    monkeypatch.setattr(cap, "write_capture", write_interrupted)
    monkeypatch.setattr(cap, "evidence", evidence)
    r = _capture(sub, _start(folder, tmp_path, "P11"), f"replay:{folder / 'grasp.csv'}@1000")
    assert r.exit_code == 0, r.output
    assert "interrupted: the recording is kept; its evidence was not computed" in r.output
    got = read_pose_csv(tmp_path / "P11" / "grasp.csv", units=sub.session.units)
    assert got.n_frames == sub.session.grasp[0].n_frames
    assert [g.name for g in load_session(tmp_path / "P11").grasp] == ["grasp.csv"]


def test_a_ctrl_c_while_a_child_starts_ends_it_without_a_word(capfd, monkeypatch):
    """The child is started with SIGINT blocked and ignores it; a Ctrl-C at its start
    reaches the parent once the child exists, which ends it: no traceback anywhere."""
    import signal
    import threading
    from multiprocessing.context import SpawnProcess

    from fingerfit import processes

    q = processes.context().Queue()
    child = processes.start_child(_report_signals, (q,), "probe")
    handler, blocked = q.get(timeout=60)
    processes.end_child(child, 60)
    assert handler == int(signal.SIG_IGN) and int(signal.SIGINT) not in blocked
    real_start, real_end, ended = SpawnProcess.start, processes.end_child, []

    def start_then_interrupt(self):
        real_start(self)
        # Ctrl-C as the child starts, sent to the main thread (where start_child blocks
        # it): not left to whichever thread of this process the kernel picks.
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    def end(proc, timeout_s=0.0):
        ended.append(proc)
        real_end(proc, timeout_s)

    monkeypatch.setattr(SpawnProcess, "start", start_then_interrupt)
    monkeypatch.setattr(processes, "end_child", end)
    # As at a terminal: Ctrl-C deliverable and handled by Python (a test process may have
    # inherited SIGINT blocked or ignored from what started it or ran in it before).
    mask = signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            processes.start_child(_report_signals, (q,), "probe")
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    assert len(ended) == 1 and ended[0].exitcode is not None  # ended, not left to start
    time.sleep(0.5)
    assert "Traceback" not in capfd.readouterr().err


def _report_signals(q) -> None:
    """A child's target: its SIGINT handler and blocked signals, after the fingerfit
    start (:func:`fingerfit.processes.child_ignores_interrupt`)."""
    import signal

    from fingerfit.processes import child_ignores_interrupt

    child_ignores_interrupt()
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, set())
    q.put((int(signal.getsignal(signal.SIGINT)), {int(s) for s in blocked}))


# --- refused before the source opens: what the capture could not use --------------------


def _never_opened(monkeypatch):
    """Make opening the source fail the test: the refusal must come before it."""
    import fingerfit.live.sources as src

    def refuse(*args, **kwargs):
        raise AssertionError("the source was opened")

    monkeypatch.setattr(src, "ReplaySource", refuse)


def test_a_replay_without_the_sessions_sensors_is_refused(with_thumb, tmp_path, monkeypatch):
    sub, folder = with_thumb
    rec = read_pose_csv(folder / "grasp.csv", units=sub.session.units)
    rec.poses = {k: v for k, v in rec.poses.items() if not k.startswith("thumb.")}
    j = write_pose_csv(tmp_path / "j.csv", rec, units=sub.session.units)
    new = _start(folder, tmp_path, "T1")
    before = _listing(new)
    _never_opened(monkeypatch)
    r = _capture(sub, new, f"replay:{j}@1000", digits=("thumb", "index"), extra=["--name", "j.csv"])
    assert r.exit_code == 2, r.output
    assert "j.csv: no samples for sensor 'thumb.metacarpal', which the session's digits" in r.output
    assert _listing(new) == before


def test_fingers_without_their_sensors_in_the_reference_are_refused(
    simulated, tmp_path, monkeypatch
):
    sub, folder = simulated
    new = _start(folder, tmp_path, "T2")
    _never_opened(monkeypatch)
    r = _capture(sub, new, f"replay:{folder / 'grasp.csv'}@1000", digits=("index", "ring"))
    assert r.exit_code == 2, r.output
    assert "no samples for sensor 'ring.proximal' of the ring (--fingers)" in r.output
    assert sorted(_listing(new)) == ["landmarks.csv", "reference.csv"]


def test_the_folder_is_checked_before_recording(simulated, tmp_path, monkeypatch):
    """A read-only session.toml, options that contradict it, and a listed recording that
    is missing: each said before the source opens, the folder untouched; options that
    repeat session.toml are fine."""
    sub, folder = simulated
    grasp = f"replay:{folder / 'grasp.csv'}@1000"
    new = _start(folder, tmp_path, "T3")
    r = _capture(sub, new, grasp)
    assert r.exit_code == 0, r.output
    before = _listing(new)
    toml = new / "session.toml"
    _never_opened(monkeypatch)
    toml.chmod(0o444)
    try:
        r = _capture(sub, new, grasp, extra=["--name", "g2.csv"])
    finally:
        toml.chmod(0o644)
    assert r.exit_code == 2 and "session.toml: is read-only" in r.output, r.output
    for option, value in (("--fingers", "index"), ("--subject", "S02"), ("--rate", "120"),
                          ("--hand", "right" if sub.session.hand == "left" else "left")):  # fmt: skip
        args = ["capture", str(new), "--source", grasp, option, value, "--name", "g2.csv"]
        r = CliRunner().invoke(app, args)
        assert r.exit_code == 2 and f"field '{option}': the folder's session.toml says" in r.output
    assert _listing(new) == before
    (new / "grasp.csv").unlink()  # listed, missing: recorded again under its name
    monkeypatch.undo()
    r = _capture(sub, new, grasp)  # repeats session.toml: accepted
    assert r.exit_code == 0, r.output
    assert [g.name for g in load_session(new).grasp] == ["grasp.csv"]
    r = _capture(sub, new, grasp)
    assert r.exit_code == 2 and "the folder has grasp.csv: give --name" in r.output


def test_a_thumb_dropout_neither_stops_the_fit_nor_reaches_the_table(with_thumb, tmp_path):
    """A few frames without a thumb sensor's sample: the thumb's CMC is fitted over the
    other frames (its saddle fit took no missing frame), and the capture's table says
    nothing of NumPy."""
    sub, folder = with_thumb
    new = shutil.copytree(folder, tmp_path / "T4")
    rec = read_pose_csv(new / "grasp.csv", units=sub.session.units)
    rec.poses["thumb.metacarpal"].position[1000:1005] = np.nan
    rec.poses["thumb.metacarpal"].rotation[1000:1005] = np.nan
    write_pose_csv(new / "grasp.csv", rec, units=sub.session.units)
    res = CliRunner().invoke(app, ["fit", str(new), "-q", "-o", str(tmp_path / "m.json")])
    assert res.exit_code == 0, res.output
    rec.poses = {k: PoseSeries(v.position.copy(), v.rotation.copy()) for k, v in rec.poses.items()}
    for s in ("thumb.metacarpal", "thumb.proximal", "thumb.distal"):
        rec.poses[s].position[40:] = np.nan
        rec.poses[s].rotation[40:] = np.nan
    j = write_pose_csv(tmp_path / "j.csv", rec, units=sub.session.units)
    r = _capture(sub, _start(folder, tmp_path, "T5"), f"replay:{j}@1000", digits=("thumb", "index"))
    assert r.exit_code == 0, r.output
    assert "NaN" not in r.output and "infinite" not in r.output, r.output
    assert "thumb cmc (0 cycle(s), ROM n/a, second axis not identified: " in r.output
