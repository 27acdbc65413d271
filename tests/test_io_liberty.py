"""Polhemus Liberty/Patriot ASCII and binary readers against streams of known poses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fingerfit.errors import FingerfitError
from fingerfit.io.liberty import (
    LibertyRecords,
    format_liberty_ascii,
    liberty_binary_bytes,
    parse_items,
    parse_liberty_ascii,
    parse_liberty_binary,
    read_liberty_ascii,
    read_liberty_binary,
    write_liberty_ascii,
    write_liberty_binary,
)
from fingerfit.io.liberty import binary as liberty_binary

MAP2 = {1: "hand", 2: "index.proximal"}


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


def polhemus_matrix(az, el, roll):
    """R = Rz(az) Ry(el) Rx(roll), degrees, written out by hand (no scipy)."""
    return rz(np.radians(az)) @ ry(np.radians(el)) @ rx(np.radians(roll))


def make_records(
    n_frames: int,
    stations=(1, 2),
    items=("position", "euler"),
    seed: int = 0,
    decimals: int = 3,
    frame0: int = 1000,
    ts0: int = 50_000,
    dt_ms: int = 4,
) -> LibertyRecords:
    """Random records on an exact decimal grid (so ASCII round-trips exactly)."""
    rng = np.random.default_rng(seed)
    n = n_frames * len(stations)
    q = 10**decimals
    values = {}
    if "position" in items:
        # Two sensors about 2 in apart (a plausible hand -> proximal distance).
        base = np.array([[3.0, -4.0, 2.0], [5.0, -4.0, 2.0], [6.0, -4.0, 2.0], [7.0, -4, 2]])
        pos = np.concatenate([base[: len(stations)]] * n_frames)
        pos = pos + rng.uniform(-0.1, 0.1, (n, 3))
        values["position"] = np.round(pos * q) / q
    if "euler" in items:
        e = rng.uniform([-179, -89, -179], [179, 89, 179], (n, 3))
        values["euler"] = np.round(e * q) / q
    if "quaternion" in items:
        v = rng.normal(size=(n, 4))
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        values["quaternion"] = np.round(v * 10_000) / 10_000
    if "timestamp" in items:
        values["timestamp"] = (ts0 + dt_ms * np.repeat(np.arange(n_frames), len(stations))).astype(
            float
        )
    if "frame" in items:
        values["frame"] = (frame0 + np.repeat(np.arange(n_frames), len(stations))).astype(float)
    return LibertyRecords(
        tuple(items),
        np.tile(np.asarray(stations), n_frames),
        values,
        np.array([""] * n),
        np.arange(1, n + 1),
    )


def test_parse_items_codes_and_names() -> None:
    assert parse_items(None) == ("position", "euler")
    assert parse_items("2,4,1") == ("position", "euler")
    assert parse_items("0,2,7,8,9,1") == ("position", "quaternion", "timestamp", "frame")
    assert parse_items("pos,quat,time") == ("position", "quaternion", "timestamp")
    for bad in ("2,6,1", "2,4,4", "2,12", "4,7", "pos"):
        with pytest.raises(FingerfitError, match="items"):
            parse_items(bad)


def test_euler_convention_and_inches(tmp_path) -> None:
    """ASCII position + Euler read back to the generating poses (R = Rz Ry Rx, inches)."""
    recs = make_records(40, items=("position", "euler"))
    path = write_liberty_ascii(tmp_path / "s.txt", recs)
    rec = read_liberty_ascii(path, rate_hz=240, sensors=MAP2)
    assert rec.n_frames == 40
    np.testing.assert_allclose(np.diff(rec.time), 1 / 240)
    for k, name in enumerate(("hand", "index.proximal")):
        e = recs.values["euler"][k::2]
        truth = np.stack([polhemus_matrix(*row) for row in e])
        got = rec.poses[name].rotation
        # ASCII keeps 3 decimals of a degree: rotation error well below 0.002 deg.
        cos = (np.einsum("nij,nij->n", truth, got) - 1) / 2
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 2e-3
        np.testing.assert_allclose(
            rec.poses[name].position, recs.values["position"][k::2] * 25.4, atol=1e-9
        )


def test_quaternion_is_scalar_first(tmp_path) -> None:
    """90 deg about z, written as w,x,y,z = (0.7071, 0, 0, 0.7071), maps x to y."""
    recs = make_records(3, stations=(1,), items=("position", "quaternion"))
    recs.values["quaternion"][:] = [0.7071, 0.0, 0.0, 0.7071]
    path = write_liberty_ascii(tmp_path / "q.txt", recs)
    rec = read_liberty_ascii(path, items="2,7,1", rate_hz=120, sensors={1: "hand"}, units="cm")
    np.testing.assert_allclose(rec.poses["hand"].rotation[0] @ [1, 0, 0], [0, 1, 0], atol=1e-4)
    np.testing.assert_allclose(rec.poses["hand"].position, recs.values["position"] * 10)


def test_binary_float32_exact_and_patriot(tmp_path) -> None:
    recs = make_records(25, items=("position", "quaternion", "timestamp", "frame"))
    for key in ("position", "quaternion"):
        recs.values[key] = recs.values[key].astype(np.float32).astype(float)
    for family in ("LY", "PA"):
        path = tmp_path / f"s{family}.bin"
        path.write_bytes(liberty_binary_bytes(recs, family=family))
        back = parse_liberty_binary(path, "2,7,8,9")
        assert back.family == family
        for key, v in recs.values.items():
            np.testing.assert_array_equal(back.values[key], v)
        np.testing.assert_array_equal(back.station, recs.station)
    rec = read_liberty_binary(path, items="2,7,8,9", sensors=MAP2, rate_hz=250)
    # Frames by frame count, time from the timestamp item (ms).
    np.testing.assert_allclose(rec.time, (50_000 + 4 * np.arange(25)) / 1000)
    np.testing.assert_allclose(rec.poses["hand"].position, recs.values["position"][::2] * 25.4)


def test_glued_numbers_and_indicator(tmp_path) -> None:
    text = "01  1.000-2.000  3.000  10.000-20.000  30.000\r\n02D 2.500 -2.000 3.000 0.0 0.0 0.0\r\n"
    (tmp_path / "g.txt").write_text(text, newline="")
    recs = parse_liberty_ascii(tmp_path / "g.txt")
    np.testing.assert_array_equal(recs.values["position"][0], [1.0, -2.0, 3.0])
    np.testing.assert_array_equal(recs.values["euler"][0], [10.0, -20.0, 30.0])
    rec = read_liberty_ascii(tmp_path / "g.txt", rate_hz=240, sensors=MAP2)
    assert any("indicator 'D'" in n for n in rec.notes)


def test_station_cycles_missing_records_and_repeats(tmp_path) -> None:
    recs = make_records(6)
    text = format_liberty_ascii(recs).splitlines(keepends=True)
    # Drop station 2 of frame 2 (line 6); repeat frame 4 (lines 9-10) right after itself.
    lines = text[:5] + text[6:10] + text[8:10] + text[10:]
    (tmp_path / "c.txt").write_text("".join(lines), newline="")
    rec = read_liberty_ascii(tmp_path / "c.txt", rate_hz=100, sensors=MAP2)
    assert rec.n_frames == 6
    valid = rec.poses["index.proximal"].valid
    assert valid.tolist() == [True, True, False, True, True, True]
    assert "1 exactly repeated frames (2 records) dropped" in rec.notes
    kept = read_liberty_ascii(tmp_path / "c.txt", rate_hz=100, sensors=MAP2, keep_repeats=True)
    assert kept.n_frames == 7


def test_frame_count_gaps_become_nan_rows(tmp_path) -> None:
    recs = make_records(10, items=("position", "euler", "frame"))
    text = format_liberty_ascii(recs).splitlines(keepends=True)
    # Remove frames 3 and 4 entirely and repeat one record exactly (same frame count).
    lines = text[:6] + text[10:] + text[-1:]
    (tmp_path / "f.txt").write_text("".join(lines), newline="")
    rec = read_liberty_ascii(tmp_path / "f.txt", items="2,4,9,1", rate_hz=240, sensors=MAP2)
    assert rec.n_frames == 10
    assert np.flatnonzero(~rec.poses["hand"].valid).tolist() == [3, 4]
    assert "2 frames missing for every sensor (kept as NaN rows)" in rec.notes
    assert any("1 exactly repeated records" in n for n in rec.notes)
    np.testing.assert_allclose(rec.time, (1000 + np.arange(10)) / 240)


def test_timestamps_on_grid_and_without_rate(tmp_path) -> None:
    recs = make_records(8, items=("position", "euler", "timestamp"), dt_ms=5)
    text = format_liberty_ascii(recs).splitlines(keepends=True)
    lines = text[:4] + text[6:]  # frame 2 lost
    (tmp_path / "t.txt").write_text("".join(lines), newline="")
    rec = read_liberty_ascii(tmp_path / "t.txt", items="2,4,8,1", rate_hz=200, sensors=MAP2)
    assert rec.n_frames == 8
    assert not rec.poses["hand"].valid[2]
    np.testing.assert_allclose(rec.time, 50 + 0.005 * np.arange(8))
    free = read_liberty_ascii(tmp_path / "t.txt", items="2,4,8,1", sensors=MAP2)
    assert free.n_frames == 7


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (lambda ls: [*ls[:3], ls[3][:20] + "\r\n", *ls[4:]], r"s\.txt:4: expected 7 fields"),
        (lambda ls: [*ls[:-1], ls[-1][:15]], r"s\.txt:12: expected 7 fields"),
        (lambda ls: [*ls[:2], ls[2].replace("-", "x", 1), *ls[3:]], r"s\.txt:3: .*not a finite"),
        (lambda ls: [*ls[:1], "17" + ls[1][2:], *ls[2:]], r"s\.txt:2: unknown station 17"),
        (lambda ls: [*ls[:1], "03" + ls[1][2:], *ls[2:]], r"s\.txt:2: unknown station 3 \(not in"),
        (lambda ls: [*ls[:1], "x1" + ls[1][2:], *ls[2:]], r"s\.txt:2: field 'station'"),
        (lambda ls: [*ls[:4], "\x00\x01garbage\r\n", *ls[4:]], r"s\.txt:5: garbled record"),
    ],
)
def test_bad_ascii_is_one_line_error_with_line(tmp_path, edit, match) -> None:
    lines = format_liberty_ascii(make_records(6)).splitlines(keepends=True)
    (tmp_path / "s.txt").write_text("".join(edit(lines)), newline="")
    with pytest.raises(FingerfitError, match=match) as err:
        read_liberty_ascii(tmp_path / "s.txt", rate_hz=240, sensors=MAP2)
    assert "\n" not in str(err.value)


def test_time_errors(tmp_path) -> None:
    recs = make_records(5, items=("position", "euler", "frame"))
    recs.values["frame"][6:8] = 900  # frame count goes backwards at record 7
    write_liberty_ascii(tmp_path / "b.txt", recs)
    with pytest.raises(FingerfitError, match=r"b\.txt:7: field 'frame count': .*backwards"):
        read_liberty_ascii(tmp_path / "b.txt", items="2,4,9", rate_hz=240)
    recs = make_records(5, items=("position", "euler", "frame"))
    recs.values["frame"][2:4] = recs.values["frame"][0]  # same frame, different values
    write_liberty_ascii(tmp_path / "d.txt", recs)
    with pytest.raises(FingerfitError, match=r"d\.txt:3: second, different record"):
        read_liberty_ascii(tmp_path / "d.txt", items="2,4,9", rate_hz=240)
    recs = make_records(5, items=("position", "euler", "timestamp"))
    recs.values["timestamp"][4:] -= 100
    write_liberty_ascii(tmp_path / "ts.txt", recs)
    with pytest.raises(FingerfitError, match=r"ts\.txt:5: field 'timestamp'"):
        read_liberty_ascii(tmp_path / "ts.txt", items="2,4,8", rate_hz=240)
    write_liberty_ascii(tmp_path / "n.txt", make_records(3))
    with pytest.raises(FingerfitError, match="--rate is needed"):
        read_liberty_ascii(tmp_path / "n.txt")


def test_unit_mistake_and_quaternion_norm(tmp_path) -> None:
    recs = make_records(5)
    write_liberty_ascii(tmp_path / "u.txt", recs)
    # The stations are 2 in (51 mm) apart; read as metres that is 2 m.
    with pytest.raises(FingerfitError, match=r"u\.txt: field 'units': implausible distance"):
        read_liberty_ascii(tmp_path / "u.txt", rate_hz=240, sensors=MAP2, units="m")
    recs = make_records(4, items=("position", "quaternion"))
    recs.values["quaternion"][5] = [0.5, 0.5, 0.5, 0.0]
    write_liberty_ascii(tmp_path / "q.txt", recs)
    with pytest.raises(FingerfitError, match=r"q\.txt:6: quaternion .* norm 0\.866"):
        read_liberty_ascii(tmp_path / "q.txt", items="2,7", rate_hz=240)


def test_bad_binary(tmp_path) -> None:
    recs = make_records(4, items=("position", "euler", "frame"))
    raw = liberty_binary_bytes(recs)
    size = len(raw) // recs.n_records
    cases = {
        "trunc": (raw[:-5], rf"record 8 \(byte {7 * size}\): truncated"),
        "magic": (raw[:size] + b"XX" + raw[size + 2 :], r"record 2 \(byte \d+\): header b'XX'"),
        "ascii": (b"01  1.0 2.0 3.0 0 0 0\r\n" * 3, r"record 1 \(byte 0\): not a Liberty"),
        "short": (raw[:5], "truncated header"),
    }
    for name, (data, match) in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(FingerfitError, match=match):
            read_liberty_binary(tmp_path / name, items="2,4,9", rate_hz=240)
    (tmp_path / "items").write_bytes(raw)
    with pytest.raises(FingerfitError, match="wrong --items"):
        read_liberty_binary(tmp_path / "items", items="2,4", rate_hz=240)


# ------------------------------------------------------------------ property-based

ITEM_SETS = [
    ("position", "euler"),
    ("position", "quaternion"),
    ("position", "euler", "timestamp"),
    ("position", "quaternion", "frame"),
    ("position", "euler", "quaternion", "timestamp", "frame"),
]


@st.composite
def streams(draw):
    items = draw(st.sampled_from(ITEM_SETS))
    stations = tuple(sorted(draw(st.sets(st.integers(1, 16), min_size=1, max_size=4))))
    n = draw(st.integers(1, 12))
    seed = draw(st.integers(0, 2**16))
    recs = make_records(n, stations=stations, items=items, seed=seed)
    recs.station = np.tile(np.asarray(stations), n)
    ind = draw(st.lists(st.sampled_from(["", "", "D", "E"]), min_size=recs.n_records,
                        max_size=recs.n_records))  # fmt: skip
    recs.indicator = np.array(ind, dtype=str)
    return recs


@settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(recs=streams())
def test_random_streams_round_trip_exactly(tmp_path, recs) -> None:
    spec = ",".join(recs.items)
    write_liberty_ascii(tmp_path / "r.txt", recs)
    back = parse_liberty_ascii(tmp_path / "r.txt", spec)
    np.testing.assert_array_equal(back.station, recs.station)
    np.testing.assert_array_equal(back.indicator, recs.indicator)
    for key, v in recs.values.items():
        np.testing.assert_array_equal(back.values[key], v)
    b32 = {k: v.astype(np.float32).astype(float) for k, v in recs.values.items()}
    recs32 = LibertyRecords(recs.items, recs.station, b32, recs.indicator, recs.where)
    write_liberty_binary(tmp_path / "r.bin", recs32)
    back = parse_liberty_binary(tmp_path / "r.bin", spec)
    for key, v in b32.items():
        np.testing.assert_array_equal(back.values[key], v)
    np.testing.assert_array_equal(back.indicator, recs.indicator)


CORRUPTIONS = ("truncate", "drop_token", "extra_token", "garbage", "station", "control")


@settings(
    max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(recs=streams(), kind=st.sampled_from(CORRUPTIONS), where=st.floats(0, 1), data=st.data())
def test_random_corruptions_end_in_a_clear_error(tmp_path, recs, kind, where, data) -> None:
    spec = ",".join(recs.items)
    lines = format_liberty_ascii(recs).splitlines(keepends=True)
    i = min(int(where * len(lines)), len(lines) - 1)
    tokens = lines[i].split()
    if kind == "truncate":
        keep = data.draw(st.integers(1, len(tokens) - 1))
        lines = [*lines[:i], " ".join(tokens[:keep])]
    elif kind == "drop_token":
        j = data.draw(st.integers(1, len(tokens) - 1))
        lines[i] = " ".join(tokens[:j] + tokens[j + 1 :]) + "\r\n"
    elif kind == "extra_token":
        lines[i] = lines[i].rstrip() + " 1.5\r\n"
    elif kind == "garbage":
        j = data.draw(st.integers(1, len(tokens) - 1))
        bad = data.draw(st.sampled_from(["1.2.3", "abc", "--1", "nan", "inf", "1,5", "?"]))
        tokens[j] = bad
        lines[i] = " ".join(tokens) + "\r\n"
    elif kind == "station":
        tokens[0] = data.draw(st.sampled_from(["00", "17", "99", "A1", "1.5", "123"]))
        lines[i] = " ".join(tokens) + "\r\n"
    else:
        lines[i] = lines[i][:3] + "\x07" + lines[i][3:]
    path = tmp_path / "bad.txt"
    path.write_text("".join(lines), newline="")
    with pytest.raises(FingerfitError) as err:
        read_liberty_ascii(path, items=spec, rate_hz=240, check=False)
    msg = str(err.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}:{i + 1}: ")


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(recs=streams(), cut=st.floats(0, 1), flip=st.booleans())
def test_random_binary_corruptions_end_in_a_clear_error(tmp_path, recs, cut, flip) -> None:
    spec = ",".join(recs.items)
    raw = liberty_binary_bytes(recs)
    size = len(raw) // recs.n_records
    if flip:  # misalign: drop one byte inside the stream
        k = int(cut * (len(raw) - 1))
        bad = raw[:k] + raw[k + 1 :]
    else:  # truncate anywhere but on a record boundary
        k = int(cut * (len(raw) - 1))
        k += 1 if k % size == 0 else 0
        bad = raw[:k]
    path = tmp_path / "bad.bin"
    path.write_bytes(bad)
    try:
        read_liberty_binary(path, items=spec, rate_hz=240, check=False)
    except FingerfitError as err:
        assert "\n" not in str(err)
        assert str(err).startswith(f"{path}: record ")
    else:  # pragma: no cover - the assertion below reports it
        pytest.fail("a corrupted binary stream was read without an error")


@pytest.mark.parametrize("records_per_block", [1, 3, 7, 1000])
def test_binary_blocks_give_the_whole_file_and_name_the_record(
    tmp_path, monkeypatch, records_per_block
) -> None:
    """The binary parse converts a block of records at a time into its arrays: any block
    size gives the same records, from a file or from bytes, and a garbled record in a
    later block is named by its own number and byte."""
    recs = make_records(5, items=("position", "quaternion", "frame"))
    raw = liberty_binary_bytes(recs)
    size = len(raw) // recs.n_records
    (tmp_path / "r.bin").write_bytes(raw)
    whole = parse_liberty_binary(tmp_path / "r.bin", "2,7,9")
    monkeypatch.setattr(liberty_binary, "_BINARY_BLOCK_BYTES", records_per_block * size)
    for got in (
        parse_liberty_binary(tmp_path / "r.bin", "2,7,9"),
        parse_liberty_binary("r.bin", "2,7,9", data=raw),
    ):
        assert np.array_equal(got.station, whole.station)
        assert np.array_equal(got.indicator, whole.indicator)
        for item in whole.items:
            assert np.array_equal(got.values[item], whole.values[item])
            assert got.values[item].dtype == whole.values[item].dtype
    k = 8  # record 9: in the third block of 3, the second of 7, the first of 1000
    bad = (
        raw[: k * size]
        + b"LY"
        + raw[k * size + 2 : k * size + 6]
        + b"\x00\x00"
        + raw[k * size + 8 :]
    )
    (tmp_path / "bad.bin").write_bytes(bad)
    with pytest.raises(FingerfitError, match=rf"record 9 \(byte {k * size}\): body size 0 "):
        parse_liberty_binary(tmp_path / "bad.bin", "2,7,9")
