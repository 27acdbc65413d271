"""Parquet tables: bit-exact round trips, the checks of the reader, atomic writes, fuzzing.

Every refusal must be one :class:`FingerfitError` line naming the file and the column (or
metadata key); a damaged file -- truncated or with random bytes changed -- must never give
another exception.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fingerfit import transforms
from fingerfit.errors import FingerfitError
from fingerfit.io import parquet as fpq
from fingerfit.io import read_pose_csv, write_pose_csv
from fingerfit.io.widecsv import read_wide_csv, write_wide_csv

from .conftest import subject

#: Values a float column must keep bit for bit.
ODD = np.array([0.0, -0.0, 5e-324, -5e-324, 2.2250738585072014e-308 / 3, 1e308, 0.1, np.nan])


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


@pytest.fixture(scope="module")
def recording():
    return subject("exact", 1).session.grasp[0]


def test_table_round_trip_is_bit_exact(tmp_path: Path, monkeypatch) -> None:
    from fingerfit.io import parquet_read

    monkeypatch.setattr(parquet_read, "_READ_COLUMNS", 3)  # columns read 3, then 1
    rng = np.random.default_rng(0)
    n = 10_000
    cols = {
        "time": np.arange(n) / 240.0,
        "a": rng.standard_normal(n),
        "b": np.resize(ODD, n),
        "c": rng.standard_normal(n) * 1e-310,  # subnormals
    }
    path = fpq.write_parquet(
        tmp_path / "t.parquet", cols, fpq.TableMeta(fpq.ANGLES), row_group_rows=999
    )
    assert pq.ParquetFile(path).metadata.num_row_groups == 11
    got = fpq.read_parquet(path, fpq.ANGLES, columns=list(cols))
    for k, v in cols.items():
        assert np.array_equal(bits(got.columns[k]), bits(v)), k  # -0.0, subnormals, NaN bits
        assert np.array_equal(got.columns[k], v, equal_nan=True)
    assert np.signbit(got.columns["b"][1])
    assert pq.ParquetFile(path).metadata.row_group(0).column(0).compression == "ZSTD"
    assert pd.read_parquet(path).shape == (n, 4)


@pytest.mark.parametrize("row_group_rows", [999, 1 << 20])
@pytest.mark.parametrize("bad", [-np.inf, np.inf])
def test_an_infinity_is_named_by_its_row_in_any_row_group(
    tmp_path: Path, monkeypatch, row_group_rows: int, bad: float
) -> None:
    from fingerfit.io import parquet_read

    monkeypatch.setattr(parquet_read, "_READ_COLUMNS", 1)
    n = 5_000
    c = np.ones(n)
    c[[10, 3_210]] = np.nan  # NaN is a missing value, before and after the infinity
    c[3_000] = bad
    cols = {"time": np.arange(n) / 240.0, "a": np.zeros(n), "c": c}
    path = fpq.write_parquet(
        tmp_path / "t.parquet", cols, fpq.TableMeta(fpq.ANGLES), row_group_rows=row_group_rows
    )
    with pytest.raises(FingerfitError) as err:
        fpq.read_parquet(path, fpq.ANGLES, columns=list(cols))
    assert str(err.value) == f"{path}:3001: field 'c': not a finite number: {bad!r}"
    c[3_000] = 1e308  # finite values whose sum overflows are not infinities
    c[3_001] = 1e308
    path = fpq.write_parquet(tmp_path / "big.parquet", cols, fpq.TableMeta(fpq.ANGLES))
    got = fpq.read_parquet(path, fpq.ANGLES, columns=list(cols))
    assert np.array_equal(got.columns["c"], c, equal_nan=True)


def test_pose_round_trip_equals_the_csv(tmp_path: Path, recording) -> None:
    for units in ("mm", "cm"):
        write_pose_csv(tmp_path / "g.csv", recording, units=units)
        write_pose_csv(tmp_path / "g.parquet", recording, units=units)
        a = read_pose_csv(tmp_path / "g.csv", units=units, rate_hz=240)
        b = read_pose_csv(tmp_path / "g.parquet", units=units, rate_hz=240)
        assert a.notes == b.notes and list(a.poses) == list(b.poses)
        assert np.array_equal(bits(a.time), bits(b.time))
        for s in a.poses:
            assert np.array_equal(bits(a.poses[s].position), bits(b.poses[s].position))
            assert np.array_equal(bits(a.poses[s].rotation), bits(b.poses[s].rotation))
    meta = pq.read_schema(tmp_path / "g.parquet").metadata
    assert meta[b"fingerfit.format"] == b"fingerfit.pose/1"
    assert meta[b"fingerfit.units"] == b"cm"
    assert meta[b"fingerfit.quaternion_order"] == b"w,x,y,z"
    assert meta[b"fingerfit.frame"] == b"tracker"
    df = pd.read_parquet(tmp_path / "g.parquet")
    assert list(df.columns) == ["time", "sensor", "x", "y", "z", "qw", "qx", "qy", "qz"]


def test_pose_columns_round_trip_bit_exact(tmp_path: Path) -> None:
    """The written numbers come back bit for bit, -0.0 and subnormals included."""
    n = 8
    cols = {
        "time": np.arange(n) / 240.0,
        "sensor": (np.zeros(n, np.int32), ["hand"]),
        "x": np.resize(ODD[[0, 1, 2, 3, 4, 6]], n),  # coordinates stay within 1000 km
        "y": -np.resize(ODD[[0, 1, 2, 3, 4, 6]], n),
        "z": np.full(n, -0.0),
        "qw": np.ones(n),
        "qx": np.full(n, 5e-324),
        "qy": np.full(n, -0.0),
        "qz": np.zeros(n),
    }
    path = fpq.write_parquet(tmp_path / "p.parquet", cols, fpq.pose_meta("mm"))
    got = fpq.read_parquet(path, fpq.POSE, columns=list(cols), text=("sensor",))
    for k, v in cols.items():
        if k == "sensor":
            codes, names = got.columns[k]
            assert names == ["hand"] and (codes == 0).all()
        else:
            assert np.array_equal(bits(got.columns[k]), bits(v)), k
    rec = read_pose_csv(path)
    assert np.array_equal(bits(rec.poses["hand"].position[:, 2]), bits(cols["z"]))


def test_wide_round_trip_equals_the_csv(tmp_path: Path, recording) -> None:
    write_wide_csv(tmp_path / "w.csv", recording, units="cm")
    write_wide_csv(tmp_path / "w.parquet", recording, units="cm")
    a = read_wide_csv(tmp_path / "w.csv", units="cm", rate_hz=240, check=False)
    b = read_wide_csv(tmp_path / "w.parquet", units=None, rate_hz=240, check=False)
    assert a.notes == b.notes
    for s in a.poses:
        assert np.array_equal(bits(a.poses[s].position), bits(b.poses[s].position))
        assert np.array_equal(bits(a.poses[s].rotation), bits(b.poses[s].rotation))
    with pytest.raises(
        FingerfitError, match=r"w\.parquet: field 'fingerfit\.units': .*in cm, not mm"
    ):
        read_wide_csv(tmp_path / "w.parquet", units="mm", rate_hz=240)


def _pose_file(tmp_path: Path, recording, name: str = "g.parquet") -> Path:
    return write_pose_csv(tmp_path / name, recording, units="mm")


def _rewrite(src: Path, dst: Path, change) -> Path:
    table = pq.read_table(src)
    pq.write_table(change(table), dst)
    return dst


def _set(table: pa.Table, name: str, values) -> pa.Table:
    i = table.schema.get_field_index(name)
    return table.set_column(i, name, values)


def _refused(path: Path, *fragments: str, read=None) -> str:
    with pytest.raises(FingerfitError) as info:
        (read or (lambda p: read_pose_csv(p, units="mm")))(path)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    for f in fragments:
        assert f in msg, (f, msg)
    return msg


def test_wrong_schema_and_metadata_are_refused(tmp_path: Path, recording) -> None:
    src = _pose_file(tmp_path, recording)
    n = pq.read_metadata(src).num_rows
    cases = {
        "missing.parquet": (lambda t: t.drop_columns(["qz"]), ["field 'qz'", "column missing"]),
        "extra.parquet": (
            lambda t: t.append_column("speed", pa.array(np.zeros(n))),
            ["field 'speed'", "unexpected column"],
        ),
        "nometa.parquet": (
            lambda t: t.replace_schema_metadata({}),
            ["field 'fingerfit.format'", "no 'fingerfit.format' metadata"],
        ),
        "angles.parquet": (
            lambda t: t.replace_schema_metadata(
                {**t.schema.metadata, b"fingerfit.format": b"fingerfit.angles/1"}
            ),
            ["field 'fingerfit.format'", "fingerfit.angles/1"],
        ),
        "noquat.parquet": (
            lambda t: t.replace_schema_metadata(
                {k: v for k, v in t.schema.metadata.items() if k != b"fingerfit.quaternion_order"}
            ),
            ["field 'fingerfit.quaternion_order'", "missing"],
        ),
        "xyzw.parquet": (
            lambda t: t.replace_schema_metadata(
                {**t.schema.metadata, b"fingerfit.quaternion_order": b"x,y,z,w"}
            ),
            ["field 'fingerfit.quaternion_order'", "'x,y,z,w', expected 'w,x,y,z'"],
        ),
        "int.parquet": (
            lambda t: _set(t, "y", pa.array(np.zeros(n, np.int64))),
            ["field 'y'", "column type int64, not float64"],
        ),
        "float32.parquet": (
            lambda t: _set(t, "qx", t.column("qx").cast(pa.float32())),
            ["field 'qx'", "column type float, not float64"],
        ),
        "sensor.parquet": (
            lambda t: _set(t, "sensor", pa.array(np.zeros(n))),
            ["field 'sensor'", "not string"],
        ),
        "inf.parquet": (
            lambda t: _set(t, "z", pa.array(np.r_[np.zeros(4), np.inf, np.zeros(n - 5)])),
            [":5: field 'z': not a finite number: inf"],
        ),
        "nantime.parquet": (
            lambda t: _set(t, "time", pa.array(np.r_[np.zeros(6), np.nan, np.ones(n - 7)])),
            [":7: field 'time': time is missing or not finite"],
        ),
        "units.parquet": (
            lambda t: t.replace_schema_metadata({**t.schema.metadata, b"fingerfit.units": b"cm"}),
            ["field 'fingerfit.units'", "in cm, not mm"],
        ),
    }
    for name, (change, fragments) in cases.items():
        _refused(_rewrite(src, tmp_path / name, change), *fragments)


def test_nan_positions_are_missing_samples_like_the_csv(tmp_path: Path, recording) -> None:
    src = _pose_file(tmp_path, recording)
    n = pq.read_metadata(src).num_rows
    x = np.r_[np.full(3, np.nan), np.ones(n - 3)]
    path = _rewrite(src, tmp_path / "nan.parquet", lambda t: _set(t, "x", pa.array(x)))
    table = pq.read_table(path)
    csv = tmp_path / "nan.csv"
    from fingerfit.io.fastcsv import write_table

    write_table(csv, table.to_pandas())
    a = read_pose_csv(csv, units="mm")
    b = read_pose_csv(path, units="mm")
    assert a.notes == b.notes and "3 samples with empty fields treated as missing" in b.notes
    # a null where a number belongs reads as NaN (missing), as an empty CSV field
    nulls = _rewrite(
        src, tmp_path / "null.parquet", lambda t: _set(t, "x", pa.array(x, from_pandas=True))
    )
    assert read_pose_csv(nulls, units="mm").notes == b.notes


def test_damaged_files_are_one_line(tmp_path: Path, recording) -> None:
    src = _pose_file(tmp_path, recording)
    raw = src.read_bytes()
    (tmp_path / "short.parquet").write_bytes(raw[: len(raw) // 2])
    (tmp_path / "empty.parquet").write_bytes(b"")
    (tmp_path / "text.parquet").write_bytes(
        b"time,sensor,x,y,z,qw,qx,qy,qz\n0,hand,1,2,3,1,0,0,0\n"
    )
    for name in ("short.parquet", "empty.parquet", "text.parquet"):
        _refused(tmp_path / name, "not a readable Parquet file")
    _refused(tmp_path / "gone.parquet", "cannot read")


def test_sink_is_atomic(tmp_path: Path) -> None:
    target = tmp_path / "r.parquet"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError), fpq.ParquetSink(target, fpq.TableMeta(fpq.ANGLES)) as sink:
        sink.write({"time": np.arange(3.0), "a": np.ones(3)})
        raise RuntimeError("the stream failed")
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.parquet"]
    with fpq.ParquetSink(target, fpq.TableMeta(fpq.ANGLES), row_group_rows=2) as sink:
        for k in range(3):
            sink.write({"time": np.arange(3.0) + 3 * k, "a": np.full(3, float(k))})
            assert target.read_bytes() == b"old"  # nothing visible before the end
    got = fpq.read_parquet(target, fpq.ANGLES, columns=["time", "a"])
    assert np.array_equal(got.columns["time"], np.arange(9.0))
    assert pq.ParquetFile(target).metadata.num_row_groups == 6
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.parquet"]


FUZZ = settings(
    max_examples=150,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


@pytest.fixture(scope="module")
def small_files(tmp_path_factory, recording) -> dict[str, bytes]:
    folder = tmp_path_factory.mktemp("valid")
    short = recording.slice(slice(0, 40))
    return {
        "pose": write_pose_csv(folder / "p.parquet", short, units="mm").read_bytes(),
        "wide": write_wide_csv(folder / "w.parquet", short, units="mm").read_bytes(),
    }


@FUZZ
@given(
    kind=st.sampled_from(["pose", "wide"]),
    flips=st.lists(
        st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), min_size=1, max_size=8
    ),
    cut=st.one_of(st.none(), st.floats(0, 1)),
)
def test_fuzz_corrupted_parquet(tmp_path: Path, small_files, kind: str, flips, cut) -> None:
    """Random bytes changed (and perhaps the end cut off): the file reads with its
    invariants or is refused in one line, never another exception."""
    data = bytearray(small_files[kind])
    for where, value in flips:
        data[int(where * len(data))] = value
    if cut is not None:
        data = data[: int(cut * len(data))]
    path = tmp_path / f"{kind}.parquet"
    path.write_bytes(bytes(data))
    try:
        if kind == "pose":
            rec = read_pose_csv(path, units="mm")
        else:
            rec = read_wide_csv(path, units=None, check=False)
    except FingerfitError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(path) in msg
        return
    assert np.isfinite(rec.time).all() and (np.diff(rec.time) >= 0).all()
    for p in rec.poses.values():
        ok = np.isfinite(p.position).all(axis=1)
        assert (np.isfinite(p.rotation).all(axis=(1, 2)) == ok).all()


def _same_recording(a, b) -> None:
    assert a.notes == b.notes and list(a.poses) == list(b.poses) and a.name == b.name
    assert np.array_equal(bits(a.time), bits(b.time))
    for s in a.poses:
        assert np.array_equal(bits(a.poses[s].position), bits(b.poses[s].position)), s
        assert np.array_equal(bits(a.poses[s].rotation), bits(b.poses[s].rotation)), s


def _messy_pose_table(recording, rng) -> pd.DataFrame:
    """The recording's long table with frames lost, samples lost, empty fields, sensors in
    varying order within a frame, and an unused sensor name in the dictionary."""
    from fingerfit.io.posewrite import pose_table

    df = pose_table(recording)
    keep = rng.random(len(df)) > 0.05
    df = df[keep].reset_index(drop=True)
    df.loc[rng.random(len(df)) < 0.02, "qx"] = np.nan
    df = df.sample(frac=1.0, random_state=1).sort_values("time", kind="stable")
    return df.reset_index(drop=True)


@pytest.mark.parametrize("row_group_rows", [97, 1 << 20])
def test_streamed_pose_read_is_the_reference_bit_for_bit(
    tmp_path: Path, recording, monkeypatch, row_group_rows
) -> None:
    """The streaming reader of pose Parquet files is taken for ordinary files and gives
    what the reference path (the whole table, then the CSV reader's assembly) gives."""
    from fingerfit.io import posecsv, poseparquet, posewrite

    rng = np.random.default_rng(3)
    tables = {
        "plain": posewrite.pose_columns(recording, 1.0),
        "messy": {c: v for c, v in _messy_pose_table(recording, rng).items()},
    }
    for name, cols in tables.items():
        path = fpq.write_parquet(
            tmp_path / f"{name}.parquet", cols, fpq.pose_meta("mm"), row_group_rows=row_group_rows
        )
        fast = posecsv.read_pose_csv(path, units="mm", rate_hz=240)
        with monkeypatch.context() as m:
            m.setattr(poseparquet, "assemble_rows", _no_assembly)  # the streaming path only
            _same_recording(fast, posecsv.read_pose_csv(path, units="mm", rate_hz=240))
            _same_recording(
                posecsv.read_pose_csv(path, units="mm"),
                posecsv.read_pose_csv(path, units="mm"),
            )
        with monkeypatch.context() as m:
            m.setattr(poseparquet, "_read_parquet_fast", _no_assembly)  # the reference only
            _same_recording(fast, posecsv.read_pose_csv(path, units="mm", rate_hz=240))
            slow = posecsv.read_pose_csv(path, units="mm")
        _same_recording(slow, posecsv.read_pose_csv(path, units="mm"))
        csv = tmp_path / f"{name}.csv"
        from fingerfit.io.fastcsv import write_table

        write_table(csv, pq.read_table(path).to_pandas())
        ref = posecsv.read_pose_csv(csv, units="mm", rate_hz=240)
        assert ref.notes == fast.notes
        for s in ref.poses:
            assert np.array_equal(bits(ref.poses[s].rotation), bits(fast.poses[s].rotation))


@pytest.mark.parametrize(
    ("qw_scale", "x", "fragment"),
    [
        (1.0009, 10.0, None),  # a norm within the tolerance but near it: read as the reference
        (1.0011, 10.0, "has norm 1.0011, not 1"),
        (1.0, 2e9, "field 'x': coordinate 2e+09 mm is implausible"),
    ],
)
def test_pose_checks_near_their_limits_are_the_reference(
    tmp_path: Path, recording, monkeypatch, qw_scale: float, x: float, fragment: str | None
) -> None:
    """The streaming reader's checks of whole blocks give what the reference path says,
    at the edge of the quaternion norm's tolerance and of plausible coordinates."""
    from fingerfit.io import posecsv, poseparquet, posewrite

    cols = posewrite.pose_columns(recording, 1.0)
    for c in ("qw", "qx", "qy", "qz"):
        cols[c] = cols[c].copy()
        cols[c][7] *= qw_scale
    cols["x"] = cols["x"].copy()
    cols["x"][9] = x
    path = fpq.write_parquet(tmp_path / "edge.parquet", cols, fpq.pose_meta("mm"))
    if fragment is not None:
        _refused(path, fragment, ":10:" if x > 1e9 else ":8:")
        return
    got = posecsv.read_pose_csv(path, units="mm", rate_hz=240)
    with monkeypatch.context() as m:
        m.setattr(poseparquet, "_read_parquet_fast", _no_assembly)  # the reference only
        _same_recording(got, posecsv.read_pose_csv(path, units="mm", rate_hz=240))


def test_pose_duplicates_go_to_the_reference_path(tmp_path: Path, recording) -> None:
    from fingerfit.io import posecsv, posewrite

    df = posewrite.pose_table(recording)
    dup = pd.concat([df.iloc[:5], df]).sort_values("time", kind="stable").reset_index(drop=True)
    path = fpq.write_parquet(tmp_path / "dup.parquet", dict(dup.items()), fpq.pose_meta("mm"))
    rec = posecsv.read_pose_csv(path, units="mm", rate_hz=240)
    assert "5 exact duplicate rows dropped" in rec.notes
    bad = dup.copy()
    bad.loc[1, "x"] += 1.0
    path = fpq.write_parquet(tmp_path / "bad.parquet", dict(bad.items()), fpq.pose_meta("mm"))
    _refused(path, "second, different sample")


def _no_assembly(*args, **kwargs):
    raise AssertionError("not this path")


def test_blocked_writers_write_the_whole_table(tmp_path: Path, recording, monkeypatch) -> None:
    """Pose and wide recordings are written a row group of frames at a time: the same
    rows and numbers, bit for bit, as the whole table."""
    from fingerfit.io import posecsv, posewrite, widecsv

    monkeypatch.setattr(fpq, "ROW_GROUP_ROWS", 1000)
    monkeypatch.setattr(transforms, "_QUAT_BLOCK", 77)
    rec = posecsv.read_pose_csv(_pose_file(tmp_path, recording), units="mm")
    for units in ("mm", "cm"):
        got = pq.read_table(write_pose_csv(tmp_path / "p.parquet", rec, units=units))
        assert pq.ParquetFile(tmp_path / "p.parquet").metadata.num_row_groups > 2
        want = posewrite.pose_columns(rec, {"mm": 1.0, "cm": 10.0}[units])
        codes, names = want.pop("sensor")
        assert got.column("sensor").to_pylist() == [names[c] for c in codes]
        for c, v in want.items():
            assert np.array_equal(bits(got.column(c).to_numpy()), bits(v)), c
        got = pq.read_table(write_wide_csv(tmp_path / "w.parquet", rec, units=units))
        want = widecsv.wide_table(rec, units=units)
        assert got.column_names == list(want.columns)
        for c in want.columns:
            assert np.array_equal(bits(got.column(c).to_numpy()), bits(want[c].to_numpy())), c


@pytest.mark.parametrize("block", [50, 1 << 16])
def test_streamed_wide_read_is_the_reference_bit_for_bit(
    tmp_path: Path, recording, monkeypatch, block
) -> None:
    """The streaming reader of wide Parquet files is taken for ordinary files (lost frames,
    empty fields) and gives what the reference path gives; repeated rows go to the
    reference path, which drops them."""
    from fingerfit.io import widecsv

    monkeypatch.setattr(widecsv, "_PARQUET_BLOCK", block)
    rng = np.random.default_rng(5)
    plain = widecsv.wide_table(recording)
    messy = plain[rng.random(len(plain)) > 0.03].reset_index(drop=True)
    messy.loc[rng.random(len(messy)) < 0.05, "x2"] = np.nan
    repeated = pd.concat([plain.iloc[:40], plain.iloc[39:]]).reset_index(drop=True)
    # the first row of a block repeating the last of the block before
    edge = pd.concat([plain.iloc[:50], plain.iloc[49:]]).reset_index(drop=True)
    # station 2 holding its values into the next row, within a block and across blocks
    held = plain.copy()
    st2 = [c for c in plain.columns if c.endswith("2")]
    for row in (7, 50, 100):
        held.loc[row, st2] = held.loc[row - 1, st2].to_numpy()
    # a quaternion norm within the tolerance, near it
    near = plain.copy()
    near.loc[10, ["w1", "x1", "y1", "z1"]] *= 1.0009
    meta = widecsv._wide_meta("mm", widecsv.DEFAULT_LAYOUT)
    tables = {"plain": plain, "messy": messy, "repeated": repeated, "edge": edge}
    for name, table in (tables | {"held": held, "near": near}).items():
        path = fpq.write_parquet(tmp_path / f"{name}.parquet", table, meta, row_group_rows=333)
        for rate in (240, None):
            with monkeypatch.context() as m:
                m.setattr(widecsv, "_read_parquet_fast", _no_assembly)  # the reference only
                ref = read_wide_csv(path, units="mm", rate_hz=rate, check=False)
            if name in ("repeated", "edge"):
                with monkeypatch.context() as m:
                    m.setattr(widecsv, "_assemble", _no_assembly)
                    with pytest.raises(AssertionError, match="not this path"):
                        read_wide_csv(path, units="mm", rate_hz=rate, check=False)
                assert any("exactly repeated rows dropped" in n for n in ref.notes)
                _same_recording(ref, read_wide_csv(path, units="mm", rate_hz=rate, check=False))
                continue
            if name == "near":  # decided by the reference path, which reads it
                _same_recording(ref, read_wide_csv(path, units="mm", rate_hz=rate, check=False))
                continue
            with monkeypatch.context() as m:
                m.setattr(widecsv, "_assemble", _no_assembly)  # the streaming path only
                fast = read_wide_csv(path, units="mm", rate_hz=rate, check=False)
            _same_recording(ref, fast)


def test_blocks_made_ahead_are_written_in_order_and_fail_whole(tmp_path: Path) -> None:
    made: list[int] = []

    def blocks(n: int, fail_at: int | None = None):
        for k in range(n):
            made.append(k)
            if k == fail_at:
                raise OSError("the source failed")
            yield {"time": np.arange(5.0) + 5 * k, "a": np.full(5, float(k))}

    target = tmp_path / "t.parquet"
    with fpq.ParquetSink(target, fpq.TableMeta(fpq.ANGLES), row_group_rows=3) as sink:
        sink.write_blocks(blocks(9))
    got = fpq.read_parquet(target, fpq.ANGLES, columns=["time", "a"])
    assert np.array_equal(got.columns["time"], np.arange(45.0))
    assert np.array_equal(got.columns["a"], np.repeat(np.arange(9.0), 5))
    made.clear()
    with (
        pytest.raises(OSError, match="the source failed"),
        fpq.ParquetSink(tmp_path / "u.parquet", fpq.TableMeta(fpq.ANGLES)) as sink,
    ):
        sink.write_blocks(blocks(50, fail_at=3))
    assert not (tmp_path / "u.parquet").exists()
    assert max(made) == 3  # the blocks after the failure are not made
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.parquet"]


def test_blocks_decoded_ahead_stop_and_fail_like_the_plain_ones() -> None:
    import threading

    def items(fail_at=None):
        for i in range(50):
            if i == fail_at:
                raise OSError("damaged page")
            yield i

    from fingerfit.io import parquet_read

    assert list(parquet_read._ahead(items())) == list(range(50))
    with pytest.raises(OSError, match="damaged page"):
        list(parquet_read._ahead(items(fail_at=7)))
    gen = parquet_read._ahead(items())
    assert [next(gen) for _ in range(3)] == [0, 1, 2]
    gen.close()  # the consumer stops early: the thread ends
    assert not [t for t in threading.enumerate() if t.name == "fingerfit-parquet-ahead"]


def test_files_are_standard_with_the_documented_encodings(tmp_path: Path, recording) -> None:
    """Float columns BYTE_STREAM_SPLIT (no dictionary), text dictionary-encoded, every
    column chunk zstd, min/max statistics for the time column alone; pandas and Dask read
    the files and give the numbers bit for bit."""
    import dask.dataframe as dd

    pose = write_pose_csv(tmp_path / "g.parquet", recording, units="cm")
    wide = write_wide_csv(tmp_path / "w.parquet", recording, units="cm")
    n = 1000
    table = {"time": np.arange(n) / 240.0, "a": np.resize(ODD, n)}
    angles = fpq.write_parquet(tmp_path / "a.parquet", table, fpq.angles_meta("mm"))
    for path, time in ((pose, "time"), (wide, "Time"), (angles, "time")):
        meta = pq.ParquetFile(path).metadata
        for g in range(meta.num_row_groups):
            for j in range(meta.num_columns):
                col = meta.row_group(g).column(j)
                assert col.compression == "ZSTD", col
                if col.path_in_schema == "sensor":
                    assert "RLE_DICTIONARY" in col.encodings, col
                    continue
                assert "BYTE_STREAM_SPLIT" in col.encodings, col
                assert not {"PLAIN_DICTIONARY", "RLE_DICTIONARY"} & set(col.encodings), col
                assert col.is_stats_set == (col.path_in_schema == time), col
        lo = meta.row_group(0).column(0).statistics
        assert lo.min == pq.read_table(path).column(time).to_numpy()[0]
    want = pq.read_table(pose)
    for got in (pd.read_parquet(pose), dd.read_parquet(pose).compute()):
        assert got["sensor"].astype(str).tolist() == want.column("sensor").to_pylist()
        for c in ("time", "x", "y", "z", "qw", "qx", "qy", "qz"):
            assert np.array_equal(bits(got[c].to_numpy()), bits(want.column(c).to_numpy()))
    got = pd.read_parquet(angles)
    assert np.array_equal(bits(got["a"].to_numpy()), bits(table["a"]))
    assert np.signbit(got["a"].to_numpy()[1])


def test_files_written_with_pyarrows_defaults_read_the_same(tmp_path: Path, recording) -> None:
    """A file of the earlier layout (floats dictionary-encoded, statistics for every
    column, one row group) or of another writer (snappy) gives the same recording."""
    for write, read in (
        (write_pose_csv, lambda p: read_pose_csv(p, units="cm", rate_hz=240)),
        (write_wide_csv, lambda p: read_wide_csv(p, units="cm", rate_hz=240, check=False)),
    ):
        ours = write(tmp_path / "ours.parquet", recording, units="cm")
        for options in ({"compression": "zstd"}, {"compression": "snappy"}):
            other = tmp_path / "other.parquet"
            pq.write_table(pq.read_table(ours), other, **options)
            col = pq.ParquetFile(other).metadata.row_group(0).column(2)
            assert "BYTE_STREAM_SPLIT" not in col.encodings
            a, b = read(ours), read(other)
            _same_recording(a, type(b)(a.name, b.time, b.poses, b.notes))


def test_blocked_writers_raise_the_whole_recordings_error(
    tmp_path: Path, recording, monkeypatch
) -> None:
    """A matrix that is not a rotation, met while the blocks are made ahead of the
    writer, is the error of the whole recording's conversion (the first sensor in order,
    the matrix by its frame), and no file is left."""
    monkeypatch.setattr(fpq, "ROW_GROUP_ROWS", 100)
    poses = dict(recording.poses)
    names = list(poses)
    for k, frame in ((1, 250), (2, 10)):  # a later sensor has one in an earlier block
        rot = poses[names[k]].rotation.copy()
        rot[frame] = np.diag([1.0, 1.0, -1.0])
        poses[names[k]] = type(poses[names[k]])(poses[names[k]].position, rot)
    bad = type(recording)(recording.name, recording.time, poses)
    for write in (write_pose_csv, write_wide_csv):
        with pytest.raises(ValueError, match=r"rotation matrix 250$"):
            write(tmp_path / "bad.parquet", bad)
        assert not list(tmp_path.iterdir())
