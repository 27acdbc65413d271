"""`fingerfit stream` with a model fitted from skin markers: a marker recording replayed,
an LSL stream of marker positions, the robot lane frame by frame, and the refusals."""

from __future__ import annotations

import functools
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.estimate.markers.angles import angles_table, marker_angles
from fingerfit.estimate.markers.fit import fit_marker_session
from fingerfit.io.markers import read_marker_recording
from fingerfit.io.opensim import write_markers
from fingerfit.live.outputs import RecordOutput
from fingerfit.live.sources import Block
from fingerfit.live.stream import Streamer
from fingerfit.model import load_model, save_model
from fingerfit.session import Recording
from fingerfit.simulate.markers import simulate_markers, write_marker_subject
from fingerfit.simulate.study import SimConfig, simulate_subject

from ._live import HANG_S, FakeLsl, fitted, stream_from_outlet, write_recording

FINGERFIT = str(Path(sys.executable).with_name("fingerfit"))
#: How far a frame solved in a block of the stream may lie from `fingerfit angles`' solve
#: of the whole recording: each frame is solved on its own (estimate/markers/frames.py),
#: so only rounding (measured below 1e-11 deg and 1e-12 mm).
BLOCK_DEG, BLOCK_MM = 1e-6, 1e-6


@functools.cache
def marker_subject() -> tuple[Path, Path]:
    """``(session_dir, model.json)``: a simulated subject's marker session (the realistic
    world, index finger, Todorov's layout, 0.3 mm noise, skin sliding) and its fit."""
    root = Path(tempfile.mkdtemp(prefix="fingerfit-live-markers-"))
    sim = simulate_subject(SimConfig(fingers=["index"], cycles=2), 3)
    ms = simulate_markers(sim, "todorov", seed=3)
    d = write_marker_subject(ms, root / "S01")
    fit = fit_marker_session(ms.session, mp_axes="hinge")
    return d, save_model(fit.model, root / "model.json")


def _compare(got: pd.DataFrame, want: pd.DataFrame) -> None:
    assert sorted(got.columns) == sorted(want.columns) and len(got) == len(want)
    for c in want.columns:
        tol = BLOCK_MM if ".tip." in c else BLOCK_DEG if c != "time" else 1e-9
        np.testing.assert_allclose(got[c], want[c], atol=tol, err_msg=c)


def test_replay_of_a_marker_recording_equals_angles(tmp_path: Path) -> None:
    """`stream --source replay:test.trc --record` writes the angles of `fingerfit angles`,
    under the channel names of a 6-DOF model (flexion joints, then the fingertip)."""
    d, model = marker_subject()
    want_csv, got_csv = tmp_path / "angles.csv", tmp_path / "stream.csv"
    rec = read_marker_recording(d / "test.trc")
    trc = write_markers(tmp_path / "test.trc", rec, units="mm")
    res = CliRunner().invoke(app, ["angles", str(model), str(trc), "-o", str(want_csv)])
    assert res.exit_code == 0, res.output
    proc = subprocess.run(
        [FINGERFIT, "stream", str(model), "--source", f"replay:{trc}@50", "--record",
         str(got_csv), "-q"],
        capture_output=True, text=True, timeout=HANG_S,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    got, want = pd.read_csv(got_csv), pd.read_csv(want_csv)
    assert list(got.columns) == [
        "time", "index.mp", "index.pip", "index.dip", "index.tip.x", "index.tip.y", "index.tip.z"
    ]  # fmt: skip
    assert f"{rec.n_frames} recorded" in proc.stdout, proc.stdout
    _compare(got, want)


def test_robot_lane_frame_by_frame_and_a_gap() -> None:
    """The robot lane solves each frame alone: the same angles as the whole recording's
    solve; a frame with a marker unseen is solved from the others with valid 0 (source 1),
    a frame without the hand's frame holds the last values sent (source 2)."""
    _, model_path = marker_subject()
    model = load_model(model_path)
    rec = read_marker_recording(marker_subject()[0] / "test.trc").slice(slice(0, 40))
    markers = {k: v.copy() for k, v in rec.markers.items()}
    markers["IND2_1"][10] = np.nan  # one middle-phalanx marker unseen
    for k in ("HAND_1", "HAND_2"):  # two of four hand markers: no hand frame
        markers[k][20] = np.nan
    rec = Recording(rec.name, rec.time, {}, markers=markers)
    want = marker_angles(model, rec)["index"]
    lsl = FakeLsl()
    streamer = Streamer(model, lsl=lsl, max_age=3600.0)
    assert streamer.channels.angle_labels == ["index.mp", "index.pip", "index.dip"]
    for i in range(rec.n_frames):
        streamer.process(Block(rec.slice(slice(i, i + 1)), np.array([time.monotonic()])))
    got = np.vstack(lsl.angles)
    valid = np.concatenate(lsl.valid)
    source = np.vstack(lsl.source)[:, 0]
    assert got.shape == (40, 3)
    exp = np.degrees(want.angles)
    exp[20] = exp[19]  # held
    np.testing.assert_allclose(got, exp, atol=BLOCK_DEG)
    assert np.isnan(want.angles[20]).all() and np.isfinite(want.angles[10]).all()
    assert np.flatnonzero(valid == 0).tolist() == [10, 20]
    assert source[10] == 1 and source[20] == 2 and (np.delete(source, [10, 20]) == 0).all()
    s = streamer.summary
    assert (s.received, s.sent, s.invalid, s.held) == (40, 40, 2, 1)


def test_lsl_stream_of_markers_equals_angles(tmp_path: Path) -> None:
    """An LSL stream of marker positions as the Qualisys LSL app sends them (type
    ``Mocap``, channels ``<marker>_X|_Y|_Z`` in meters), a marker unseen in some
    frames: the record equals the angles of the same frames."""
    pytest.importorskip("pylsl")
    d, model_path = marker_subject()
    model = load_model(model_path)
    n = 120
    rec = read_marker_recording(d / "test.trc").slice(slice(0, n))
    markers = {k: v.copy() for k, v in rec.markers.items()}
    markers["IND3_1"][30:34] = np.nan
    rec = Recording(rec.name, rec.time - rec.time[0], {}, markers=markers)
    labels = [f"{k}_{c}" for k in markers for c in "XYZ"]
    data = np.hstack([markers[k] / 1000.0 for k in markers])
    record = tmp_path / "live.csv"
    units = ["meters"] * len(labels)
    code, out, err = stream_from_outlet("Mocap", labels, units, data, rec.time, model_path, record)
    assert code == 0, out + err
    assert "4 with a missing sensor: 4 solved by the model, 0 held" in out, out
    got = pd.read_csv(record)
    want = angles_table(rec.time, marker_angles(model, rec))
    np.testing.assert_allclose(got["time"], rec.time, atol=1e-6)
    _compare(got.drop(columns="time"), want.drop(columns="time"))


def _refused(args: list[str]) -> str:
    res = CliRunner().invoke(app, ["stream", *args])
    assert res.exit_code == 2, (res.output, repr(res.exception))
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert len(lines) == 1, res.output
    return lines[0]


def test_the_other_kind_of_source_is_refused_in_one_line(tmp_path: Path) -> None:
    d, marker_model = marker_subject()
    _, pose_model = fitted()
    trc = d / "test.trc"
    pose_csv = write_recording(tmp_path / "poses.csv", n=20)
    line = _refused([str(pose_model), "--source", f"replay:{trc}", "--record", "a.csv"])
    assert "fitted from 6-DOF sensors" in line and "model.json" in line
    line = _refused([str(marker_model), "--source", f"replay:{pose_csv}"])
    assert "fitted from markers" in line and "replay:X.trc" in line
    line = _refused([str(marker_model), "--source", "liberty:/dev/null"])
    assert "fitted from markers" in line
    line = _refused(
        [str(marker_model), "--source", f"replay:{trc}", "--retarget", "shadow", "--orthogonal"]
    )
    assert "fitted from markers" in line and "--orthogonal" in line
    # A recording without one of the model's markers: named, nothing written.
    rec = read_marker_recording(trc).slice(slice(0, 20))
    rec.markers.pop("IND3_1")
    short = write_markers(tmp_path / "short.trc", rec, units="mm")
    out = tmp_path / "out.csv"
    line = _refused([str(marker_model), "--source", f"replay:{short}", "--record", str(out)])
    assert "IND3_1" in line and "short.trc" in line
    assert not out.exists()


def test_unconverged_marker_solves_are_counted_and_said(monkeypatch) -> None:
    """Frames whose marker solve stops unconverged (here: the solver allowed 2 steps) are
    counted by the robot lane and by the data lane, as many as `fingerfit angles` counts
    frame by frame, and said in the stream's summary line."""
    from fingerfit.cli.stream import summary_line
    from fingerfit.estimate.markers import frames

    _, model_path = marker_subject()
    model = load_model(model_path)
    rec = read_marker_recording(marker_subject()[0] / "test.trc").slice(slice(0, 30))
    rec = Recording(rec.name, rec.time, {}, markers=rec.markers)
    monkeypatch.setattr(frames, "MAX_STEPS", 2)
    want = sum(
        marker_angles(model, rec.slice(slice(i, i + 1)))["index"].unconverged for i in range(30)
    )
    assert want > 0
    streamer = Streamer(model, lsl=FakeLsl(), max_age=3600.0)
    for i in range(rec.n_frames):
        streamer.process(Block(rec.slice(slice(i, i + 1)), np.array([time.monotonic()])))
    s = streamer.summary
    assert (s.sent, s.unconverged) == (30, want)
    line = summary_line(s, live=True, files=False, max_age_ms=100.0, retargets=False, view=False)
    assert f"{want} marker solves of them unconverged" in line
    # The data lane (a recording): every frame, in blocks, counted the same.
    with tempfile.TemporaryDirectory() as tmp:
        recorded = Streamer(model, record=RecordOutput(Path(tmp) / "out.csv"))
        recorded.process(Block(rec, np.full(rec.n_frames, time.monotonic())))
        recorded.close()
    assert (recorded.summary.recorded, recorded.summary.data_unconverged) == (30, want)
    line = summary_line(recorded.summary, live=False, files=True, max_age_ms=100.0)
    assert f"30 recorded ({want} marker solves unconverged)" in line
    monkeypatch.setattr(frames, "MAX_STEPS", 500)
    quiet = Streamer(model, lsl=FakeLsl(), max_age=3600.0)
    quiet.process(Block(rec.slice(slice(0, 1)), np.array([time.monotonic()])))
    assert quiet.summary.unconverged == 0
