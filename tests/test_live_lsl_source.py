"""`fingerfit stream --source lsl:NAME`: sensor poses from another program's LSL stream."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.live.stream import model_sensors
from fingerfit.model import load_model

from ._live import (
    angles_of,
    assert_close_where_solved,
    fitted,
    short_recording,
    solved_tolerance,
    stream_from_outlet,
)

pylsl = pytest.importorskip("pylsl")
N = 120


def test_lsl_source_equals_angles(tmp_path: Path) -> None:
    _, model_path = fitted()
    model = load_model(model_path)
    sensors = model_sensors(model)
    rec = short_recording(N, ((40, "index.middle"),))
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
    record = tmp_path / "live.csv"
    code, out, err = stream_from_outlet(
        "MoCap", labels, units, data, rec.time, model_path, record, "PositionX"
    )
    assert code == 0, out + err
    got = pd.read_csv(record)
    want, solved = angles_of(model, rec)
    assert list(got.columns) == list(want.columns) and len(got) == N
    np.testing.assert_allclose(got["time"], rec.time - rec.time[0], atol=1e-6)
    cols = [c for c in want.columns if c != "time" and "ik_rms" not in c]
    # Frame 40 lacks index.middle: solved by the model (block by block here, as the LSL
    # chunks arrive; the whole recording in `angles`), its joints determined by the other
    # sensors wherever the block ends (a missing distal sensor would leave the DIP to the
    # frames around it, which a block ending there does not have); every other frame from
    # its sensors.
    assert solved.tolist() == [i == 40 for i in range(N)]
    assert_close_where_solved(
        got[cols].to_numpy(), want[cols].to_numpy(), solved, solved_tolerance(cols)
    )
    assert (
        np.isfinite(got.loc[40, "index.ik_rms_mm"]) and got["index.ik_rms_mm"].isna().sum() == N - 1
    )
