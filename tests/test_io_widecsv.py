"""Wide CSV logs: layouts, repeated rows, sample-and-hold loggers, errors."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from fingerfit.errors import FingerfitError
from fingerfit.io.widecsv import parse_layout, read_wide_csv, wide_table, write_wide_csv
from fingerfit.session import PoseSeries, Recording
from fingerfit.transforms import quat_wxyz_from_matrix

MAP2 = {1: "hand", 2: "index.proximal"}
COLS = ["Time", "w1", "x1", "y1", "z1", "w2", "x2", "y2", "z2"]
COLS += ["loc1_x", "loc1_y", "loc1_z", "loc2_x", "loc2_y", "loc2_z"]


def truth(n: int, seed: int = 0, rate: float = 120.0) -> Recording:
    """Two sensors ~9 cm apart, the second turning about a fixed axis (cm-like numbers)."""
    rng = np.random.default_rng(seed)
    t = 1_686_230_000.0 + np.arange(n) / rate
    r1 = Rotation.from_rotvec(rng.normal(scale=0.001, size=(n, 3)) + np.array([0.1, 0.2, 0.3]))
    ang = np.linspace(0, np.pi / 2, n)
    r2 = Rotation.from_rotvec(ang[:, None] * [0.0, 0.0, 1.0]) * Rotation.from_rotvec([0.4, 0, 0])
    p1 = np.array([1.0, -22.0, -2.5]) + rng.normal(scale=0.001, size=(n, 3))
    p2 = p1 + np.c_[9.0 * np.cos(ang), 9.0 * np.sin(ang), np.zeros(n)]
    return Recording(
        "truth",
        t,
        {
            "hand": PoseSeries(p1 * 10, r1.as_matrix()),
            "index.proximal": PoseSeries(p2 * 10, r2.as_matrix()),
        },
    )


def logger_rows(rec: Recording, jitter: float = 0.0, seed: int = 1) -> pd.DataFrame:
    """Rows as a sample-and-hold logger writes them: both, then (1, 2, repeat) per frame."""
    rng = np.random.default_rng(seed)
    wide = wide_table(rec, units="cm")[COLS].to_numpy()
    s1 = [1, 2, 3, 4, 9, 10, 11]
    s2 = [5, 6, 7, 8, 12, 13, 14]
    rows = [wide[0].copy()]
    # The logger sees each frame after a random delay, never before an earlier one.
    seen = np.maximum.accumulate(rec.time + np.abs(rng.normal(scale=jitter, size=rec.n_frames)))
    for k in range(1, rec.n_frames):
        t0 = seen[k]
        a = rows[-1].copy()
        a[s1] = wide[k, s1]
        a[0] = t0
        b = a.copy()
        b[s2] = wide[k, s2]
        b[0] = t0 + 3e-5
        c = b.copy()
        c[0] = t0 + 6e-5
        rows += [a, b, c]
    out = np.array(rows)
    out[:, 0] = np.maximum.accumulate(out[:, 0]) + 1e-6 * np.arange(len(rows))
    return pd.DataFrame(out, columns=COLS)


def test_round_trip_with_gaps(tmp_path) -> None:
    rec = truth(30)
    rec.poses["hand"].position[5:8] = np.nan
    rec.poses["hand"].rotation[5:8] = np.nan
    for pose in rec.poses.values():  # two frames empty for every sensor: not "repeats"
        pose.position[20:22] = np.nan
        pose.rotation[20:22] = np.nan
    path = write_wide_csv(tmp_path / "w.csv", rec, units="cm")
    back = read_wide_csv(path, units="cm", sensors=MAP2, rate_hz=120)
    assert back.n_frames == 30
    for name in MAP2.values():
        np.testing.assert_allclose(back.poses[name].position, rec.poses[name].position, rtol=1e-15)
        np.testing.assert_allclose(back.poses[name].rotation, rec.poses[name].rotation, atol=1e-14)
    np.testing.assert_array_equal(back.time, rec.time)
    assert "sensor 'hand': 5 of 30 frames missing" in back.notes
    assert not any("repeated" in n for n in back.notes)


def test_sample_and_hold_logger_assembled_into_frames(tmp_path) -> None:
    rec = truth(60)
    df = logger_rows(rec, jitter=0.02)
    df.to_csv(tmp_path / "log.csv", index=False)
    back = read_wide_csv(tmp_path / "log.csv", units="cm", sensors=MAP2, rate_hz=120)
    assert back.n_frames == 60
    assert "59 exactly repeated rows dropped (a logger polling faster than the tracker)" in (
        back.notes
    )
    assert any("60 frames assembled by station cycle" in n for n in back.notes)
    assert any("too irregular for the 120 Hz grid" in n for n in back.notes)
    for name in MAP2.values():
        np.testing.assert_allclose(back.poses[name].position, rec.poses[name].position, rtol=1e-12)
        np.testing.assert_allclose(back.poses[name].rotation, rec.poses[name].rotation, atol=1e-12)
    np.testing.assert_allclose(back.time, rec.time[0] + np.arange(60) / 120)
    # A wrong rate is caught by the time column's span.
    with pytest.raises(FingerfitError, match=r"field 'rate': the time column spans .* not 240 Hz"):
        read_wide_csv(tmp_path / "log.csv", units="cm", sensors=MAP2, rate_hz=240)
    # Without jitter the logger's times sit on the grid: frames placed by time.
    logger_rows(rec).to_csv(tmp_path / "even.csv", index=False)
    even = read_wide_csv(tmp_path / "even.csv", units="cm", sensors=MAP2, rate_hz=120)
    assert even.n_frames == 60 and not any("irregular" in n for n in even.notes)


def test_still_sensor_repeating_is_not_a_logger(tmp_path) -> None:
    """A sensor repeating now and then (a still sensor at low precision) keeps its samples."""
    rec = truth(20)
    table = wide_table(rec, units="cm")
    table.loc[[4, 9, 14], ["w1", "x1", "y1", "z1", "loc1_x", "loc1_y", "loc1_z"]] = table.loc[
        [3, 8, 13], ["w1", "x1", "y1", "z1", "loc1_x", "loc1_y", "loc1_z"]
    ].to_numpy()
    table.to_csv(tmp_path / "s.csv", index=False)
    back = read_wide_csv(tmp_path / "s.csv", units="cm", sensors=MAP2, rate_hz=120)
    assert back.n_frames == 20 and back.poses["hand"].valid.all()
    assert not any("station cycle" in n for n in back.notes)


def test_euler_layout_and_no_time_column(tmp_path) -> None:
    lay = parse_layout("time=;x=X{n};y=Y{n};z=Z{n};az=A{n};el=E{n};roll=R{n}")
    rec = truth(10)
    table = wide_table(rec, units="mm", layout=lay)
    assert list(table.columns[:6]) == ["A1", "E1", "R1", "X1", "Y1", "Z1"]
    table.to_csv(tmp_path / "e.csv", index=False)
    back = read_wide_csv(tmp_path / "e.csv", units="mm", layout=lay, sensors=MAP2, rate_hz=50)
    np.testing.assert_allclose(back.time, np.arange(10) / 50)
    np.testing.assert_allclose(back.poses["hand"].rotation, rec.poses["hand"].rotation, atol=1e-12)
    # Euler angles by hand: R = Rz(az) Ry(el) Rx(roll).
    az, el, roll = np.radians(table.loc[0, ["A1", "E1", "R1"]].to_numpy(dtype=float))
    rz = Rotation.from_rotvec([0, 0, az]).as_matrix()
    ry = Rotation.from_rotvec([0, el, 0]).as_matrix()
    rx = Rotation.from_rotvec([roll, 0, 0]).as_matrix()
    np.testing.assert_allclose(back.poses["hand"].rotation[0], rz @ ry @ rx, atol=1e-12)
    with pytest.raises(FingerfitError, match="--rate is needed"):
        read_wide_csv(tmp_path / "e.csv", units="mm", layout=lay, sensors=MAP2)
    for bad in ("x=a;y=b", "x=a;y=b;z=c;qw=w;az=q", "foo=1", "x"):
        with pytest.raises(FingerfitError, match="columns"):
            parse_layout(bad)


def write_lines(path, lines):
    path.write_text("\n".join(lines) + "\n")
    return path


def set_field(line: str, i: int, value: str) -> str:
    parts = line.split(",")
    parts[i] = value
    return ",".join(parts)


def good_lines(n=5):
    rec = truth(n)
    return wide_table(rec, units="cm").to_csv(index=False, lineterminator="\n").splitlines()


@pytest.mark.parametrize(
    ("edit", "match", "kwargs"),
    [
        (lambda ls: ls, r"w\.csv: field 'units': the wide CSV does not state", {"units": None}),
        (lambda ls: [ls[0].replace("loc2_z", "loc2_q"), *ls[1:]], r"w\.csv:1: .*'loc2_z' missing", {}),
        (lambda ls: [*ls[:3], set_field(ls[3], 1, "abc"), *ls[4:]], r"w\.csv:4: field 'w1': not a finite number: 'abc'", {}),
        (lambda ls: [*ls[:2], ls[2][:30]], r"w\.csv:3: expected 15 comma-separated fields, found \d+", {}),
        (lambda ls: [*ls[:2], "", *ls[2:]], r"w\.csv:3: empty line inside the data", {}),
        (lambda ls: [ls[0], ls[1], ls[3], ls[2], *ls[4:]], r"w\.csv:4: field 'time': time goes backwards", {}),
        (lambda ls: ls, r"w\.csv:1: field 'loc2_x': unknown station 2", {"sensors": {1: "hand"}}),
        (lambda ls: ls, r"w\.csv: field 'units': sensor 'hand' is 22.16 m from the tracker", {"units": "m"}),
    ],
)  # fmt: skip
def test_errors_name_file_and_line(tmp_path, edit, match, kwargs) -> None:
    path = write_lines(tmp_path / "w.csv", edit(good_lines()))
    args = {"units": "cm", "sensors": MAP2, "rate_hz": 120.0} | kwargs
    with pytest.raises(FingerfitError, match=match) as err:
        read_wide_csv(path, **args)
    assert "\n" not in str(err.value)


def test_quaternion_norm_error(tmp_path) -> None:
    table = wide_table(truth(5), units="cm")
    table.loc[3, "w2"] = 3.0
    table.to_csv(tmp_path / "q.csv", index=False)
    with pytest.raises(FingerfitError, match=r"q\.csv:5: field 'w2': quaternion of station 2"):
        read_wide_csv(tmp_path / "q.csv", units="cm", sensors=MAP2, rate_hz=120)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    n=st.integers(1, 25),
    seed=st.integers(0, 10_000),
    drop=st.lists(st.integers(0, 24), max_size=6),
    units=st.sampled_from(["mm", "cm", "m", "in"]),
)
def test_random_tables_round_trip(tmp_path, n, seed, drop, units) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 100.0
    poses = {}
    for name in ("hand", "index.proximal", "index.middle"):
        pos = rng.normal(scale=300.0, size=(n, 3))
        rot = Rotation.random(n, random_state=seed).as_matrix()
        gone = [d for d in drop if d < n]
        pos[gone] = np.nan
        rot[gone] = np.nan
        poses[name] = PoseSeries(pos, rot)
    rec = Recording("r", t, poses)
    path = write_wide_csv(tmp_path / "r.csv", rec, units=units)
    sensors = {1: "hand", 2: "index.proximal", 3: "index.middle"}
    back = read_wide_csv(path, units=units, sensors=sensors, rate_hz=100.0, check=False)
    assert back.n_frames == n
    for name, pose in poses.items():
        got = back.poses[name]
        assert (got.valid == pose.valid).all()
        np.testing.assert_allclose(got.position, pose.position, rtol=1e-14, atol=1e-12)
        np.testing.assert_allclose(
            quat_wxyz_from_matrix(got.rotation), quat_wxyz_from_matrix(pose.rotation), atol=1e-14
        )


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    kind=st.sampled_from(["truncate", "garbage", "extra", "backwards", "empty"]),
    where=st.integers(0, 7),
    col=st.integers(0, 14),
    bad=st.sampled_from(["abc", "1.2.3", "inf", "--1", "0x1"]),
)
def test_random_corruptions_end_in_a_clear_error(tmp_path, kind, where, col, bad) -> None:
    lines = good_lines(10)  # header + 10 rows
    i = 2 + where  # a data line (1-based line number i + 1)
    if kind == "truncate":
        lines = [*lines[:i], lines[i][: len(lines[i]) // 2]]
    elif kind == "garbage":
        lines[i] = set_field(lines[i], col, bad)
    elif kind == "extra":
        lines[i] += ",1.0"
    elif kind == "backwards":
        lines[i] = set_field(lines[i], 0, "1000.0")
    else:
        lines.insert(i, "")
    path = write_lines(tmp_path / "c.csv", lines)
    with pytest.raises(FingerfitError) as err:
        read_wide_csv(path, units="cm", sensors=MAP2, rate_hz=120.0, check=False)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}:{i + 1}: ")
