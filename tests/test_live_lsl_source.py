"""`fingerfit stream --source lsl:NAME`: sensor poses from another program's LSL stream."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.live.stream import model_sensors
from fingerfit.model import load_model

from ._live import HANG_S, angles_of, assert_close_where_solved, fitted, short_recording

pylsl = pytest.importorskip("pylsl")
FINGERFIT = str(Path(sys.executable).with_name("fingerfit"))
N = 120


def test_lsl_source_equals_angles(tmp_path: Path) -> None:
    _, model_path = fitted()
    model = load_model(model_path)
    sensors = model_sensors(model)
    rec = short_recording(N, ((40, "index.distal"),))
    name = f"ffmocap{os.getpid()}"
    labels, units, cols = [], [], []
    for s in sensors:  # positions in cm, quaternions w, x, y, z
        p = rec.poses[s]
        q = np.full((N, 4), np.nan)
        ok = p.valid
        q[ok] = Rotation.from_matrix(p.rotation[ok]).as_quat(scalar_first=True)
        labels += [f"{s}.{c}" for c in ("x", "y", "z", "qw", "qx", "qy", "qz")]
        units += ["centimeters"] * 3 + ["normalized"] * 4
        cols += [p.position / 10.0, q]
    data = np.hstack(cols)
    info = pylsl.StreamInfo(name, "MoCap", len(labels), 240.0, pylsl.cf_double64, name)
    chans = info.desc().append_child("channels")
    for lab, unit in zip(labels, units, strict=True):
        ch = chans.append_child("channel")
        ch.append_child_value("label", lab)
        ch.append_child_value("unit", unit)
        ch.append_child_value("type", "PositionX")
    outlet = pylsl.StreamOutlet(info)
    record = tmp_path / "live.csv"
    proc = subprocess.Popen(
        [FINGERFIT, "stream", str(model_path), "--source", f"lsl:{name}", "--record",
         str(record), "--duration", "2", "-q"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert outlet.wait_for_consumers(HANG_S), "the stream did not connect"
        time.sleep(0.3)
        t0 = pylsl.local_clock()
        for i in range(0, N, 10):  # 10 samples every 10 ms
            outlet.push_chunk(data[i : i + 10], (t0 + rec.time[i : i + 10]).tolist())
            time.sleep(0.01)
        out, err = proc.communicate(timeout=HANG_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, out + err
    got = pd.read_csv(record)
    want, solved = angles_of(model, rec)
    assert list(got.columns) == list(want.columns) and len(got) == N
    np.testing.assert_allclose(got["time"], rec.time - rec.time[0], atol=1e-6)
    cols = [c for c in want.columns if c != "time" and "ik_rms" not in c]
    # Frame 40 lacks index.distal: solved by the model (block by block here, the whole
    # recording in `angles`); every other frame from its sensors.
    assert solved.tolist() == [i == 40 for i in range(N)]
    assert_close_where_solved(got[cols].to_numpy(), want[cols].to_numpy(), solved)
    assert (
        np.isfinite(got.loc[40, "index.ik_rms_mm"]) and got["index.ik_rms_mm"].isna().sum() == N - 1
    )
