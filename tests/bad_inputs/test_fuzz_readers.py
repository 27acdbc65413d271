"""Property-based fuzzing of every reader: mutated files are read correctly or refused.

Each reader is given small valid files (written by fingerfit's own writers from a cached
simulated subject, or real recordings from ``../shared/data`` when present) with random
mutations: truncation, byte flips, NaN/Inf and other bad tokens, reordered and duplicated
lines or records, huge and negative values. Every case must either

* read, and then satisfy the reader's invariants (shapes, time finite and increasing,
  each sample complete or all-NaN, rotations orthonormal, positions finite mm), or
* raise :class:`FingerfitError` whose message is one line and names the file.

Any other exception, or a case taking longer than :data:`WALL_CLOCK_S`, fails. Examples
are derandomised so CI sees the same cases on every run.
"""

from __future__ import annotations

import contextlib
import json
import math
import shutil
import signal
import struct
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.io import load_session, read_pose_csv, save_session, write_pose_csv
from fingerfit.io.c3d import read_c3d_segments
from fingerfit.io.liberty import (
    format_liberty_ascii,
    liberty_binary_bytes,
    read_liberty_ascii,
    read_liberty_binary,
)
from fingerfit.io.sessiondir import read_events, read_landmarks
from fingerfit.io.widecsv import read_wide_csv, write_wide_csv
from fingerfit.model import load_model, save_model
from fingerfit.session import Recording, Session, TargetEvent

from ..conftest import subject
from ..test_io_liberty import make_records

#: Longest a single example may take (s): a reader that hangs fails the test.
WALL_CLOCK_S = 10.0
DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
FUZZ = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
#: Tokens put where a number (or a name) belongs.
BAD_TOKENS = [
    "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "-Infinity", "1e999", "-1e999",
    "1e308", "-1e308", "3.4e38", "-12345678.9", "0", "-0", "", "1_000", "0x10", "1e-320",
    "4294967295", "65535", "-1", "abc", '"', "'", "\x00", "\xe9", "12.5.3",
]  # fmt: skip
NAMES = ["hand", "index.proximal", "index.middle", "index.distal"]


@contextlib.contextmanager
def wall_clock(seconds: float = WALL_CLOCK_S) -> Iterator[None]:
    """Fail an example that runs longer than ``seconds`` (SIGALRM, main thread)."""

    def expired(signum, frame):
        raise TimeoutError(f"reader took more than {seconds:g} s")

    old = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def outcome(read: Callable[[], object], path: Path) -> object | None:
    """Run ``read``; a FingerfitError must be one line naming ``path`` (returns None)."""
    try:
        with wall_clock():
            got = read()
        event("read")
        return got
    except FingerfitError as exc:
        event("refused")
        msg = str(exc)
        assert "\n" not in msg and "\r" not in msg, msg
        assert exc.path is not None, msg
        assert msg.startswith(str(exc.path)), msg
        here = Path(path).resolve()
        named = exc.path.resolve()
        assert named == here or here in named.parents, f"{msg!r} does not name {path}"
        return None


# --------------------------------------------------------------------------- mutations


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def mutate_text(draw, base: bytes, sep: bytes = b",") -> bytes:
    """One to three random mutations of a text file (lines of ``sep``-separated fields)."""
    data = base
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["truncate", "flip", "token", "swap", "dup", "number"]))
        lines = _lines(data)
        i = draw(st.integers(0, len(lines) - 1))
        if kind == "truncate":
            data = data[: draw(st.integers(0, max(len(data) - 1, 0)))]
        elif kind == "flip":
            if data:
                k = draw(st.integers(0, len(data) - 1))
                data = data[:k] + bytes([data[k] ^ draw(st.integers(1, 255))]) + data[k + 1 :]
        elif kind in ("token", "number"):
            body = lines[i].rstrip(b"\r\n")
            end = lines[i][len(body) :]
            fields = body.split(sep) if sep else body.split()
            j = draw(st.integers(0, max(len(fields) - 1, 0)))
            if kind == "token":
                new = draw(st.sampled_from(BAD_TOKENS))
            else:
                x = draw(
                    st.one_of(
                        st.floats(allow_nan=True, allow_infinity=True),
                        st.sampled_from([1e300, -1e300, 1e15, -1e15, -1.0, 2.0**53 + 1]),
                        st.integers(-(2**70), 2**70),
                    )
                )
                new = repr(x)
            fields[j : j + 1] = [new.encode("utf-8", "surrogatepass")]
            lines[i] = (sep if sep else b" ").join(fields) + end
            data = b"".join(lines)
        elif kind == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[i], lines[j] = lines[j], lines[i]
            data = b"".join(lines)
        else:
            j = draw(st.integers(0, len(lines)))
            lines.insert(j, lines[i])
            data = b"".join(lines)
    return data


def mutate_binary(draw, base: bytes, record: int, start: int = 0) -> bytes:
    """One to three random mutations of a binary file of fixed-size records after ``start``."""
    data = bytearray(base)
    special = [np.nan, np.inf, -np.inf, 3.4e38, -3.4e38, -1.0, 1e6, 0.0]
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["truncate", "flip", "value", "swap", "dup"]))
        n_rec = max((len(data) - start) // record, 0)
        if kind == "truncate":
            data = data[: draw(st.integers(0, max(len(data) - 1, 0)))]
        elif kind == "flip" and data:
            k = draw(st.integers(0, len(data) - 1))
            data[k] ^= draw(st.integers(1, 255))
        elif kind == "value" and len(data) >= 4:
            k = draw(st.integers(0, (len(data) - 4) // 4)) * 4
            if draw(st.booleans()):
                data[k : k + 4] = struct.pack("<f", draw(st.sampled_from(special)))
            else:
                data[k : k + 4] = struct.pack("<I", draw(st.sampled_from([0, 2**31, 2**32 - 1])))
        elif kind in ("swap", "dup") and n_rec >= 1:
            i = draw(st.integers(0, n_rec - 1))
            j = draw(st.integers(0, n_rec - 1))
            a = bytes(data[start + i * record : start + (i + 1) * record])
            b = bytes(data[start + j * record : start + (j + 1) * record])
            if kind == "swap":
                data[start + i * record : start + (i + 1) * record] = b
                data[start + j * record : start + (j + 1) * record] = a
            else:
                data[start + j * record : start + j * record] = a
    return bytes(data)


# --------------------------------------------------------------------------- invariants


def check_recording(rec: Recording, rate_hz: float | None = None) -> None:
    """Invariants of every reader's output (mm, tracker frame, time-first)."""
    n = rec.n_frames
    assert rec.time.shape == (n,)
    assert np.isfinite(rec.time).all()
    assert (np.diff(rec.time) > 0).all()
    if rate_hz is not None and n > 1:
        k = (rec.time - rec.time[0]) * rate_hz
        assert np.abs(k - np.rint(k)).max() <= 0.25 + 1e-9
    assert all(isinstance(note, str) and "\n" not in note for note in rec.notes)
    for pose in rec.poses.values():
        assert pose.position.shape == (n, 3) and pose.rotation.shape == (n, 3, 3)
        pos_ok = np.isfinite(pose.position).all(axis=1)
        rot_ok = np.isfinite(pose.rotation).all(axis=(1, 2))
        # a sample is complete or entirely missing (finite-or-NaN rows)
        assert (pos_ok == rot_ok).all()
        assert np.isnan(pose.position[~pos_ok]).all() and np.isnan(pose.rotation[~rot_ok]).all()
        r = pose.rotation[rot_ok]
        if r.size:
            err = np.abs(np.swapaxes(r, 1, 2) @ r - np.eye(3)).max()
            assert err < 1e-2, err
            assert (np.linalg.det(r) > 0).all()


# ----------------------------------------------------------------------------- inputs


def small_recording(frames: int = 60) -> Recording:
    """The first ``frames`` frames of a cached simulated grasp recording (4 sensors)."""
    return subject("exact", 11).session.grasp[0].slice(slice(0, frames))


@pytest.fixture(scope="module")
def pose_csv(tmp_path_factory) -> Path:
    return write_pose_csv(tmp_path_factory.mktemp("pose") / "grasp.csv", small_recording())


@pytest.fixture(scope="module")
def wide_csv(tmp_path_factory) -> Path:
    rec = small_recording()
    rec = Recording(rec.name, rec.time, {n: rec.poses[n] for n in NAMES})
    return write_wide_csv(tmp_path_factory.mktemp("wide") / "log.csv", rec, units="cm")


LIBERTY_ITEMS = ("position", "quaternion", "timestamp", "frame")


def liberty_records(items=LIBERTY_ITEMS):
    return make_records(30, stations=(1, 2), items=items, seed=3)


def test_fuzz_inputs_are_valid(pose_csv, wide_csv, tmp_path) -> None:
    """The unmutated inputs read, so every refusal below comes from a mutation."""
    (tmp_path / "g.csv").write_bytes(pose_csv.read_bytes())
    check_recording(read_pose_csv(tmp_path / "g.csv", rate_hz=240.0), 240.0)
    (tmp_path / "w.csv").write_bytes(wide_csv.read_bytes())
    rec = read_wide_csv(
        tmp_path / "w.csv", units="cm", rate_hz=240.0, sensors=dict(enumerate(NAMES, 1))
    )
    check_recording(rec, 240.0)
    assert rec.n_frames == 60
    (tmp_path / "l.txt").write_text(format_liberty_ascii(liberty_records()), newline="")
    rec = read_liberty_ascii(tmp_path / "l.txt", items=",".join(LIBERTY_ITEMS), rate_hz=250.0)
    assert rec.n_frames == 30


# ----------------------------------------------------------------------- text readers


@FUZZ
@given(data=st.data(), rate=st.sampled_from([240.0, None]))
def test_fuzz_pose_csv(tmp_path, pose_csv, data, rate) -> None:
    path = tmp_path / "grasp.csv"
    path.write_bytes(mutate_text(data.draw, pose_csv.read_bytes()))
    rec = outcome(lambda: read_pose_csv(path, units="cm", rate_hz=rate), path)
    if rec is not None:
        check_recording(rec, rate)
        assert set(rec.poses) <= set(NAMES)


@FUZZ
@given(data=st.data(), rate=st.sampled_from([240.0, None]))
def test_fuzz_wide_csv(tmp_path, wide_csv, data, rate) -> None:
    path = tmp_path / "log.csv"
    path.write_bytes(mutate_text(data.draw, wide_csv.read_bytes()))
    sensors = dict(enumerate(NAMES, 1))
    rec = outcome(lambda: read_wide_csv(path, units="cm", rate_hz=rate, sensors=sensors), path)
    if rec is not None:
        check_recording(rec, rate)
        assert list(rec.poses) == NAMES


@FUZZ
@given(data=st.data(), items=st.sampled_from([LIBERTY_ITEMS, ("position", "euler")]))
def test_fuzz_liberty_ascii(tmp_path, data, items) -> None:
    base = format_liberty_ascii(liberty_records(items)).encode("ascii")
    path = tmp_path / "liberty.txt"
    path.write_bytes(mutate_text(data.draw, base, sep=b""))
    spec = ",".join(items)
    rec = outcome(lambda: read_liberty_ascii(path, items=spec, rate_hz=250.0), path)
    if rec is not None:
        check_recording(rec, 250.0)
        assert set(rec.poses) <= {"1", "2"} or len(rec.poses) <= 16


@FUZZ
@given(data=st.data(), items=st.sampled_from([LIBERTY_ITEMS, ("position", "euler")]))
def test_fuzz_liberty_binary(tmp_path, data, items) -> None:
    recs = liberty_records(items)
    base = liberty_binary_bytes(recs)
    path = tmp_path / "liberty.bin"
    path.write_bytes(mutate_binary(data.draw, base, len(base) // recs.n_records))
    spec = ",".join(items)
    rec = outcome(lambda: read_liberty_binary(path, items=spec, rate_hz=250.0), path)
    if rec is not None:
        check_recording(rec, 250.0)


@pytest.fixture(scope="module")
def real_wide_csv(tmp_path_factory) -> Path:
    """The first 300 rows of a real Liberty log (``../shared/data``)."""
    src = DATA / "polhemus-liberty" / "rotate-90deg-x.csv"
    if not src.is_file():
        pytest.skip(f"real Polhemus Liberty recordings not found in {src.parent}")
    p = tmp_path_factory.mktemp("real") / "rotate.csv"
    p.write_bytes(b"".join(src.read_bytes().splitlines(keepends=True)[:301]))
    return p


@settings(FUZZ, max_examples=60)
@given(data=st.data())
def test_fuzz_real_liberty_wide_csv(tmp_path, real_wide_csv, data) -> None:
    path = tmp_path / "rotate.csv"
    path.write_bytes(mutate_text(data.draw, real_wide_csv.read_bytes()))
    sensors = {1: "hand", 2: "index.proximal"}
    rec = outcome(lambda: read_wide_csv(path, units="cm", rate_hz=120.0, sensors=sensors), path)
    if rec is not None:
        check_recording(rec, 120.0)


# ---------------------------------------------------------------------------- C3D


@pytest.fixture(scope="module")
def small_c3d(tmp_path_factory) -> tuple[Path, int, int]:
    """A 40-frame C3D of two 3-marker clusters (mm), its data start and frame size."""
    pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    from ..test_io_c3d import ARM, FORE, moving, write_c3d

    _, _, arm = moving(40, ARM, 1)
    _, _, fore = moving(40, FORE[:3] + np.array([0.0, 60.0, 0.0]), 2)
    pts = np.concatenate([arm, fore], axis=1)
    labels = ["ArmR1", "ArmR2", "ArmR3", "ForeR1", "ForeR2", "ForeR3"]
    p = write_c3d(tmp_path_factory.mktemp("c3d") / "trial.c3d", labels, pts)
    start = 512 * (struct.unpack("<H", p.read_bytes()[16:18])[0] - 1)
    return p, start, 6 * 16


def _fuzz_c3d(tmp_path, raw, start, frame, data) -> None:
    path = tmp_path / "trial.c3d"
    path.write_bytes(mutate_binary(data.draw, raw, frame, start))
    seg = outcome(lambda: read_c3d_segments(path), path)
    if seg is not None:
        rec = seg.recording
        check_recording(rec)
        for fit in seg.fits.values():
            assert fit.residual.shape == (rec.n_frames,)


@settings(FUZZ, max_examples=100)
@given(data=st.data())
def test_fuzz_c3d(tmp_path, small_c3d, data) -> None:
    src, start, frame = small_c3d
    _fuzz_c3d(tmp_path, src.read_bytes(), start, frame, data)


@settings(FUZZ, max_examples=40)
@given(data=st.data())
def test_fuzz_real_c3d(tmp_path, data) -> None:
    pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    src = DATA / "optotrak-arm" / "kinematics_racing_static.c3d"
    if not src.is_file():
        pytest.skip(f"real Optotrak C3D trials not found in {src.parent}")
    raw = src.read_bytes()
    start = 512 * (struct.unpack("<H", raw[16:18])[0] - 1)
    n_points = struct.unpack("<H", raw[2:4])[0]
    _fuzz_c3d(tmp_path, raw, start, 16 * n_points, data)


# ------------------------------------------------------------- session, landmarks, events


@pytest.fixture(scope="module")
def small_session(tmp_path_factory) -> Path:
    """A session of 80-frame recordings with landmarks and events (index finger)."""
    sim = subject("exact", 11).session
    cut = slice(0, 80)
    s = Session(
        subject=sim.subject,
        hand=sim.hand,
        units=sim.units,
        rate_hz=sim.rate_hz,
        fingers=sim.fingers,
        reference=sim.reference.slice(cut),
        grasp=[r.slice(cut) for r in sim.grasp[:1]],
        landmarks=sim.landmarks,
        targets=[r.slice(cut) for r in sim.targets[:1]],
        events=[TargetEvent(sim.targets[0].name, "index", "a", 0.05, 0.2)],
    )
    s.landmarks = dict(sim.landmarks)
    s.landmarks.setdefault("target.a", np.array([1.0, 2.0, 3.0]))
    d = tmp_path_factory.mktemp("sess") / "S01"
    save_session(s, d)
    load_session(d)  # valid before mutation
    return d


TOML_EDITS = [
    'reference = "/etc/passwd"',
    'reference = "../outside.csv"',
    'reference = "sub/../../outside.csv"',
    'grasp = ["C:/x.csv"]',
    'grsp = ["grasp.csv"]',
    "extra = 1",
    'subject = "../../evil"',
    'subject = ""',
    "rate_hz = inf",
    "rate_hz = nan",
    "rate_hz = 1e308",
    "rate_hz = 123456789012345678901234567890",
    "fingers = [[1], 2]",
    'fingers = ["index", "index"]',
    'events = "."',
    'events = "reference.csv"',
    'test = ["landmarks.csv"]',
    '[recordings.more]\nx = "y"',
    "[other]",
    'hand = "left\\nright"',
    'grasp = "\\u0000"',
    "grasp = []",
]


@FUZZ
@given(data=st.data())
def test_fuzz_session_toml(tmp_path, small_session, data) -> None:
    tmp = Path(tempfile.mkdtemp(dir=tmp_path))
    d = tmp / "S"
    shutil.copytree(small_session, d)
    outside = tmp / "outside.csv"
    shutil.copyfile(d / "grasp.csv" if (d / "grasp.csv").exists() else d / "reference.csv", outside)
    toml = d / "session.toml"
    base = toml.read_bytes()
    how = data.draw(st.sampled_from(["as written", "edit", "mutate", "edit and mutate"]))
    event(how)
    if "edit" in how:
        lines = _lines(base)
        i = data.draw(st.integers(0, len(lines)))
        lines.insert(i, data.draw(st.sampled_from(TOML_EDITS)).encode() + b"\n")
        base = b"".join(lines)
    toml.write_bytes(mutate_text(data.draw, base, sep=b" ") if "mutate" in how else base)
    session = outcome(lambda: load_session(d), d)
    if session is not None:
        assert session.units in ("mm", "cm", "m", "in")
        assert math.isfinite(session.rate_hz) and session.rate_hz > 0
        for rec in session.recordings():
            check_recording(rec, session.rate_hz)
            assert (d / rec.name).resolve().is_relative_to(d.resolve())


@FUZZ
@given(data=st.data())
def test_fuzz_landmarks_and_events(tmp_path, small_session, data) -> None:
    for name, reader in (
        ("landmarks.csv", lambda p: read_landmarks(p, "cm")),
        ("events.csv", read_events),
    ):
        path = tmp_path / name
        path.write_bytes(mutate_text(data.draw, (small_session / name).read_bytes()))
        got = outcome(lambda p=path, r=reader: r(p), path)
        if isinstance(got, dict):
            for v in got.values():
                assert v.shape == (3,) and np.isfinite(v).all()
        elif got is not None:
            for ev in got:
                assert math.isfinite(ev.start) and ev.end > ev.start


# --------------------------------------------------------------------------- model JSON


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    model = fit_session(subject("exact", 11).session, FitOptions())
    return save_model(model, tmp_path_factory.mktemp("model") / "model.json")


def _paths(doc, prefix=()):
    yield prefix
    if isinstance(doc, dict):
        for k, v in doc.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            yield from _paths(v, (*prefix, i))


JSON_VALUES = [
    None, True, 0, -1, 1e308, -1e308, float("nan"), float("inf"), "x", "", [], {}, [1, 2],
    [0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], {"a": 1}, 10**400, "index",
]  # fmt: skip


@FUZZ
@given(data=st.data())
def test_fuzz_model_json(tmp_path, model_file, data) -> None:
    doc = json.loads(model_file.read_text())
    paths = list(_paths(doc))
    for _ in range(data.draw(st.integers(1, 3))):
        where = data.draw(st.sampled_from(paths))
        if not where:
            continue
        parent = doc
        try:
            for k in where[:-1]:
                parent = parent[k]
            if data.draw(st.booleans()) and isinstance(parent, dict):
                del parent[where[-1]]
            else:
                parent[where[-1]] = data.draw(st.sampled_from(JSON_VALUES))
        except (KeyError, IndexError, TypeError):
            continue
    text = json.dumps(doc, indent=1).encode()
    if data.draw(st.integers(0, 3)) == 0:
        text = mutate_text(data.draw, text, sep=b" ")
    path = tmp_path / "model.json"
    path.write_bytes(text)
    model = outcome(lambda: load_model(path), path)
    if model is not None:
        for f in model.fingers.values():
            for j in f.joints.values():
                assert np.isfinite(j.center).all() and abs(np.linalg.norm(j.axis) - 1) < 1e-6
            assert all(v > 0 for v in f.segment_lengths.values())
