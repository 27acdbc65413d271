"""The batched Arrow readers and the CSV writer against the exact reference decoders.

Every reader has a fast path (Arrow, in batches) and the reference decoder that names
the line of any error; the fast path must give the very same recording or defer to the
reference. Here each reader runs twice on the same bytes -- normally, and with its fast
path switched off -- and the results (arrays bit for bit, notes, or the error message)
must agree, on valid files cut into many tiny batches and on files with a mutation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fingerfit.errors import FingerfitError
from fingerfit.io import fastcsv, liberty, posecsv, widecsv
from fingerfit.io.fastcsv import NotPlain, write_table
from fingerfit.io.liberty import ascii as liberty_ascii
from fingerfit.io.posewrite import write_pose_csv
from fingerfit.session import PoseSeries, Recording
from fingerfit.transforms import quat_wxyz_from_matrix

SETTINGS = settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)


def _off(*args, **kwargs):
    raise NotPlain("fast path switched off for the comparison")


def outcome(read, path: Path):
    """The recording's arrays and notes, or the error's message."""
    try:
        rec = read(path)
    except FingerfitError as exc:
        return ("error", str(exc))
    arrays = [rec.time] + [a for p in rec.poses.values() for a in (p.position, p.rotation)]
    return ("ok", list(rec.poses), rec.notes, arrays)


def same(a, b) -> None:
    assert a[0] == b[0], (a, b)
    if a[0] == "error":
        assert a[1] == b[1]
        return
    assert a[1] == b[1] and a[2] == b[2]
    for x, y in zip(a[3], b[3], strict=True):
        assert x.shape == y.shape
        assert np.array_equal(x, y, equal_nan=True)


def both(monkeypatch, module, fast_name: str, read, path: Path):
    fast = outcome(read, path)
    with monkeypatch.context() as m:
        m.setattr(module, fast_name, _off)
        exact = outcome(read, path)
    same(fast, exact)
    return fast


def recording(n: int, seed: int) -> Recording:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 2, 4))
    q /= np.linalg.norm(q, axis=2, keepdims=True)
    from fingerfit.transforms import matrix_from_quat_wxyz

    poses = {
        name: PoseSeries(
            rng.normal(scale=100.0, size=(n, 3)) + np.array([0.0, 0.0, 300.0 * k]),
            matrix_from_quat_wxyz(q[:, k]),
        )
        for k, name in enumerate(("hand", "index.proximal"))
    }
    return Recording("r", np.arange(n) / 240.0, poses)


# Mutations of one line: each either keeps the file valid (another spelling) or breaks it.
MUTATIONS = [
    lambda s: s.replace(",", ",,", 1),  # field count
    lambda s: s[: len(s) // 2],  # truncated
    lambda s: "",  # empty line
    lambda s: s.replace("0", "nan", 1),
    lambda s: s.replace("1", "inf", 1),
    lambda s: s.replace("2", "1_2", 1),
    lambda s: s.replace("3", " 3", 1),
    lambda s: s.replace(".", "", 1),
    lambda s: s + "\r",
    lambda s: s.replace(",", "\r,", 1),
    lambda s: s.replace("hand", "h\x01and"),
    lambda s: s.replace("hand", "thumb"),
    lambda s: s.replace("hand", ""),
    lambda s: s.replace("5", "e", 1),
    lambda s: s.replace("4", '"4"', 1),
    lambda s: "\ufeff" + s,
    lambda s: s.replace("7", "\xe9", 1),
]


def _mutated(path: Path, text: str, line: int, which: int) -> None:
    lines = text.split("\n")
    i = 1 + line % (len(lines) - 2)
    lines[i] = MUTATIONS[which](lines[i])
    path.write_bytes("\n".join(lines).encode("utf-8", "surrogateescape"))


def test_pose_csv_many_batches_bit_identical(tmp_path, monkeypatch):
    rec = recording(500, 1)
    path = write_pose_csv(tmp_path / "a.csv", rec)
    monkeypatch.setattr(fastcsv, "CHUNK_BYTES", 256)  # about 2 rows per batch
    for rate in (None, 240.0):
        res = both(
            monkeypatch,
            posecsv,
            "_decode_fast",
            lambda p, rate=rate: posecsv.read_pose_csv(p, rate_hz=rate),
            path,
        )
        assert res[0] == "ok"
        back = posecsv.read_pose_csv(path, rate_hz=rate)
        for name, pose in rec.poses.items():
            assert np.array_equal(back.poses[name].position, pose.position)  # exact text
            assert np.allclose(back.poses[name].rotation, pose.rotation, atol=1e-15)


@SETTINGS
@given(
    line=st.integers(0, 10_000),
    which=st.integers(0, len(MUTATIONS) - 1),
    chunk=st.sampled_from([64, 300, 1 << 16]),
)
def test_pose_csv_mutations_agree(tmp_path, monkeypatch, line, which, chunk):
    text = (write_pose_csv(tmp_path / "a.csv", recording(20, 2))).read_text()
    path = tmp_path / "m.csv"
    _mutated(path, text, line, which)
    monkeypatch.setattr(fastcsv, "CHUNK_BYTES", chunk)
    both(
        monkeypatch, posecsv, "_decode_fast", lambda p: posecsv.read_pose_csv(p, rate_hz=240), path
    )


@SETTINGS
@given(
    line=st.integers(0, 10_000),
    which=st.integers(0, len(MUTATIONS) - 1),
    chunk=st.sampled_from([64, 1 << 16]),
)
def test_wide_csv_mutations_agree(tmp_path, monkeypatch, line, which, chunk):
    text = widecsv.write_wide_csv(tmp_path / "a.csv", recording(20, 3)).read_text()
    path = tmp_path / "m.csv"
    _mutated(path, text, line, which)
    monkeypatch.setattr(fastcsv, "CHUNK_BYTES", chunk)

    def read(p):
        return widecsv.read_wide_csv(p, units="mm", rate_hz=240.0, check=False)

    both(monkeypatch, widecsv, "_decode_fast", read, path)


def _liberty_text(tmp_path: Path, seed: int) -> str:
    rec = recording(20, seed)
    n = rec.n_frames
    station = np.tile([1, 2], n)
    pos = np.stack([rec.poses[s].position for s in rec.poses], axis=1).reshape(-1, 3) / 25.4
    rot = np.stack([rec.poses[s].rotation for s in rec.poses], axis=1).reshape(-1, 3, 3)
    records = liberty.LibertyRecords(
        ("position", "quaternion", "frame"),
        station,
        {
            "position": pos,
            "quaternion": quat_wxyz_from_matrix(rot),
            "frame": np.repeat(np.arange(n), 2).astype(float),
        },
        np.array(["", "D"] * n),
        np.arange(1, 2 * n + 1),
    )
    return liberty.format_liberty_ascii(records)


@SETTINGS
@given(
    line=st.integers(0, 10_000),
    which=st.integers(0, len(MUTATIONS) + 3),
    chunk=st.sampled_from([40, 1 << 16]),
)
def test_liberty_ascii_mutations_agree(tmp_path, monkeypatch, line, which, chunk):
    text = _liberty_text(tmp_path, 4)
    lines = text.split("\r\n")
    i = 1 + line % (len(lines) - 2)
    extra = [
        lambda s: s.replace(" ", "   "),  # wider spacing (device padding)
        lambda s: "  " + s + "  ",
        lambda s: s.replace(" -", "-", 1),  # numbers glued by a sign
        lambda s: s.replace("01", "1", 1),
    ]
    mutate = (MUTATIONS + extra)[which]
    lines[i] = mutate(lines[i])
    path = tmp_path / "m.txt"
    path.write_bytes("\r\n".join(lines).encode("utf-8", "surrogateescape"))
    monkeypatch.setattr(liberty_ascii, "_ASCII_CHUNK", chunk)

    def read(p):
        return liberty.read_liberty_ascii(p, items="pos,quat,frame", rate_hz=240.0, check=False)

    both(monkeypatch, liberty_ascii, "_parse_ascii_fast", read, path)


def test_liberty_ascii_fast_path_taken_and_identical(tmp_path, monkeypatch):
    path = tmp_path / "a.txt"
    path.write_text(_liberty_text(tmp_path, 5), newline="")
    monkeypatch.setattr(liberty_ascii, "_ASCII_CHUNK", 100)
    recs = liberty._parse_ascii_fast(path, ("position", "quaternion", "frame"))
    assert recs.n_records == 40 and set(recs.indicator.tolist()) == {"", "D"}

    def read(p):
        return liberty.read_liberty_ascii(p, items="pos,quat,frame", rate_hz=240.0, check=False)

    res = both(monkeypatch, liberty_ascii, "_parse_ascii_fast", read, path)
    assert res[0] == "ok"


def test_write_table_round_trip_and_atomic(tmp_path):
    rng = np.random.default_rng(0)
    x = np.concatenate(
        [
            rng.standard_normal(5000) * 10.0 ** rng.integers(-300, 300, 5000),
            [0.0, -0.0, 5e-324, 1.7976931348623157e308, 0.1, 1e-5, 1e16, np.nan],
        ]
    )
    path = write_table(
        tmp_path / "t.csv", {"a.b": x, "s": (np.zeros(x.size, np.int32), ["hand"]), "k": x > 0}
    )
    text = path.read_text().splitlines()
    assert text[0] == "a.b,s,k"
    back = np.array([float(r.split(",")[0]) if r.split(",")[0] else np.nan for r in text[1:]])
    assert np.array_equal(back.view(np.int64)[:-1], x.view(np.int64)[:-1])  # bit for bit
    assert np.isnan(back[-1]) and text[-1].startswith(",")  # NaN written as an empty field
    # a value that would need quoting: refused, and nothing is left behind
    before = sorted(tmp_path.iterdir())
    with pytest.raises(FingerfitError, match="cannot write as CSV"):
        write_table(tmp_path / "u.csv", {"s": np.array(["a,b"], dtype=object)})
    assert sorted(tmp_path.iterdir()) == before


def test_write_table_parallel_batches_are_the_one_batch_bytes(tmp_path, monkeypatch):
    """Batches are formatted in threads and written in order: the file is the same bytes
    as one batch on one thread, the progress counts every row once, and an error in a
    later batch leaves nothing behind."""
    import fingerfit.io.fastcsv as fastcsv

    rng = np.random.default_rng(1)
    n = 1000
    x = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20, n)
    x[::97] = np.nan
    names = np.array(["hand", "index_proximal", "stylus"], dtype=object)[rng.integers(0, 3, n)]
    table = {"time": np.arange(n) / 240.0, "x": x, "sensor": names, "k": np.arange(n)}
    monkeypatch.setattr(fastcsv, "WRITE_ROWS", 10**9)
    monkeypatch.setattr(fastcsv, "_WRITE_THREADS", 1)
    one = write_table(tmp_path / "one.csv", table).read_bytes()
    monkeypatch.setattr(fastcsv, "WRITE_ROWS", 37)
    monkeypatch.setattr(fastcsv, "_WRITE_THREADS", 3)
    seen: list[int] = []
    many = write_table(tmp_path / "many.csv", table, progress=seen.append).read_bytes()
    assert many == one and one.count(b"\n") == n + 1
    assert sum(seen) == n and len(seen) == -(-n // 37)
    bad = dict(table, sensor=np.where(np.arange(n) == 900, "a,b", names))  # batch 25 of 28
    before = sorted(tmp_path.iterdir())
    with pytest.raises(FingerfitError, match="cannot write as CSV"):
        write_table(tmp_path / "bad.csv", bad)
    assert sorted(tmp_path.iterdir()) == before
