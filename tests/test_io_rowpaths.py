"""The readers' shared row helpers against the plain NumPy they replace, bit for bit.

``row_norms`` must give the bits of ``np.linalg.norm(q, axis=1)`` (the quaternion check
and its message use it); ``put_rows``/``gap_rows`` must fill a pose array exactly as
``np.full(nan)`` followed by ``out[at] = values`` did; the wide reader's ``_repeats`` must
flag the rows ``repeated_rows(...) & isfinite(...).any(...)`` flagged, and its held values
(computed once, before repeated rows are dropped) must equal those computed after.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from fingerfit.io.fastcsv import (
    gap_rows,
    put_quat_rows,
    put_rows,
    put_scaled_rows,
    row_blocks,
    rows_where,
)
from fingerfit.io.hygiene import repeated_rows
from fingerfit.io.widecsv import _repeats
from fingerfit.session import PoseSeries
from fingerfit.transforms import matrix_from_quat_wxyz, row_norms

SETTINGS = settings(max_examples=60, deadline=None)


def test_row_norms_is_linalg_norm_bit_for_bit():
    rng = np.random.default_rng(3)
    q = rng.normal(size=(20000, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[:5000] *= rng.uniform(0.99, 1.01, size=(5000, 1))
    q[5000:5010] = [1e200, 1e200, 0, 0]  # overflows to inf in both
    q[5010:5020] = [1e-200, 0, 0, 0]  # underflows alike
    q[5020] = np.nan
    wide = np.concatenate([rng.normal(size=(q.shape[0], 3)), q], axis=1)  # strided view
    with np.errstate(over="ignore", under="ignore"):
        for arr in (q, wide[:, 3:], wide[:, :3], wide[:, 2:5], q[:, :1]):
            assert np.array_equal(row_norms(arr), np.linalg.norm(arr, axis=1), equal_nan=True)
        assert np.isinf(row_norms(q[5000:5010])).all()


def test_valid_frames_are_the_finite_ones():
    """PoseSeries.valid, column by column, flags a frame with any one non-finite entry."""
    rng = np.random.default_rng(4)
    n = 3000
    pos, rot = rng.normal(size=(n, 3)), rng.normal(size=(n, 3, 3))
    hit = rng.choice(n, 400, replace=False)
    for k, i in enumerate(hit):
        bad = (np.nan, np.inf, -np.inf)[k % 3]
        if k % 2:
            pos[i, k % 3] = bad
        else:
            rot[i, k % 3, (k // 3) % 3] = bad
    want = np.isfinite(pos).all(axis=1) & np.isfinite(rot).all(axis=(1, 2))
    assert np.array_equal(PoseSeries(pos, rot).valid, want) and want.sum() == n - 400


@SETTINGS
@given(
    n=st.integers(1, 40),
    rows=st.lists(st.integers(0, 39), max_size=40, unique=True),
    sort=st.booleans(),
)
def test_put_rows_and_gap_rows_fill_like_full_and_fancy_index(n, rows, sort):
    at = np.array([r for r in rows if r < n], dtype=np.int64)
    if sort:
        at = np.sort(at)
    values = np.arange(at.size * 9, dtype=float).reshape(-1, 3, 3) + 0.5
    expected = np.full((n, 3, 3), np.nan)
    expected[at] = values
    got = np.empty((n, 3, 3))
    got[:] = 7.0  # whatever np.empty holds must not survive
    put_rows(got, at, values)
    gap = gap_rows(n, [at])
    if gap is not None:
        got[gap] = np.nan
    assert np.array_equal(got, expected, equal_nan=True)
    assert (gap is None) == (np.unique(at).size == n)


def test_put_rows_contiguous_run_is_a_slice_and_blocks_tile():
    out = np.full((10, 3), np.nan)
    put_rows(out, np.arange(2, 6), np.ones((4, 3)))
    put_rows(out, np.array([6, 8]), 2 * np.ones((2, 3)))
    assert np.isnan(out[[0, 1, 7, 9]]).all() and (out[2:6] == 1).all() and (out[[6, 8]] == 2).all()
    gap = gap_rows(10, [np.arange(2, 6), np.array([6, 8])])
    assert gap.tolist() == [0, 1, 7, 9]
    assert gap_rows(5, [np.arange(0, 2), np.arange(2, 5)]) is None


def _matrix_reference(quat: np.ndarray) -> np.ndarray:
    """The plain formula, whole arrays: the bits the block kernel must give."""
    q = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=1,
    ).reshape(-1, 3, 3)  # fmt: skip


def test_matrix_from_quat_blocks_and_out_give_the_formulas_bits():
    rng = np.random.default_rng(5)
    n = 3 * 4096 + 17  # several blocks and a short last one
    q = rng.normal(size=(n, 4)) * rng.uniform(0.5, 2.0, size=(n, 1))
    q[[3, 5000]] = np.nan
    expected = _matrix_reference(q)
    wide = np.concatenate([q, rng.normal(size=(n, 3))], axis=1)[:, :4]  # strided input
    with np.errstate(invalid="ignore"):
        assert np.array_equal(matrix_from_quat_wxyz(q), expected, equal_nan=True)
        host = np.full((2 * n, 3, 3), 7.0)
        got = matrix_from_quat_wxyz(wide, out=host[::2])  # strided output, in place
        assert np.shares_memory(got, host)
        assert np.array_equal(host[::2], expected, equal_nan=True)
        assert (host[1::2] == 7.0).all()  # nothing written between the rows
        assert np.array_equal(matrix_from_quat_wxyz(q[7]), expected[7])
    assert matrix_from_quat_wxyz(np.empty((0, 4))).shape == (0, 3, 3)


@pytest.mark.parametrize("at", [np.arange(3, 9), np.array([0, 2, 3, 9, 1, 4])])
def test_put_quat_and_scaled_rows_are_fancy_index_assignments(at):
    rng = np.random.default_rng(6)
    q = rng.normal(size=(at.size, 4))
    xyz = rng.normal(size=(at.size, 3))
    rot = np.full((10, 3, 3), np.nan)
    pos = np.full((10, 3), np.nan)
    put_quat_rows(rot, at, q)
    put_scaled_rows(pos, at, xyz, 25.4)
    expected_rot = np.full((10, 3, 3), np.nan)
    expected_rot[at] = _matrix_reference(q)
    expected_pos = np.full((10, 3), np.nan)
    expected_pos[at] = xyz * 25.4
    assert np.array_equal(rot, expected_rot, equal_nan=True)
    assert np.array_equal(pos, expected_pos, equal_nan=True)


# values from a small set, so that repeats, held values, NaN, -0.0 and empty rows occur
_VALUES = st.sampled_from([0.0, -0.0, 1.0, 2.5, np.nan])


@SETTINGS
@given(
    vals=hnp.arrays(
        float,
        st.tuples(st.integers(0, 30), st.integers(1, 3), st.integers(1, 3)),
        elements=_VALUES,
    )
)
def test_repeats_matches_the_reference_definitions(vals):
    n = vals.shape[0]
    rep, same_all = _repeats(vals)
    if n:
        ref = repeated_rows(vals.reshape(n, -1)) & np.isfinite(vals).any(axis=(1, 2))
    else:
        ref = np.zeros(0, dtype=bool)
    assert np.array_equal(rep, ref)
    # held values after dropping the repeats, as the reader computed them before
    v = vals[~ref]
    held = np.zeros(v.shape[:2], dtype=bool)
    held[1:] = (v[1:] == v[:-1]).all(axis=2)
    assert np.array_equal(same_all[~rep], held)


@SETTINGS
@given(
    codes=hnp.arrays(np.int32, st.integers(0, 30), elements=st.integers(0, 3)), k=st.integers(0, 3)
)
def test_rows_where_selects_the_rows_of_one_code(codes, k):
    expected = np.flatnonzero(codes == k)
    got = np.arange(codes.size)[rows_where(codes, k)]
    assert np.array_equal(got, expected)


def test_rows_where_is_a_slice_for_sensors_taking_turns():
    codes = np.tile(np.array([2, 0, 1], dtype=np.int32), 5)
    assert rows_where(codes, 0) == slice(1, 14, 3)
    codes[4] = 2
    assert isinstance(rows_where(codes, 0), np.ndarray)


@SETTINGS
@given(
    start=st.integers(0, 5),
    count=st.integers(0, 30),
    step=st.integers(1, 4),
    size=st.integers(1, 7),
    as_slice=st.booleans(),
)
def test_row_blocks_cover_the_rows_in_order(start, count, step, size, as_slice):
    idx = start + step * np.arange(count)
    rows = slice(start, int(idx[-1]) + 1 if count else start, step) if as_slice else idx
    pieces = [np.arange(200)[b] for b in row_blocks(rows, size)]
    assert all(0 < p.size <= size for p in pieces)
    got = np.concatenate(pieces) if pieces else np.zeros(0, dtype=int)
    assert np.array_equal(got, idx)


def test_wide_reader_returns_arrays_of_their_own(tmp_path):
    """No returned array may be a view into the parsed rows (that would keep them all)."""
    from fingerfit.io.widecsv import read_wide_csv, write_wide_csv
    from fingerfit.session import PoseSeries, Recording
    from fingerfit.transforms import matrix_from_quat_wxyz

    rng = np.random.default_rng(5)
    n = 50
    poses = {
        s: PoseSeries(rng.normal(size=(n, 3)) * 100, matrix_from_quat_wxyz(rng.normal(size=(n, 4))))
        for s in ("1", "2")
    }
    path = write_wide_csv(tmp_path / "w.csv", Recording("w", np.arange(n) / 240.0, poses))
    for rate in (None, 240.0):
        rec = read_wide_csv(path, units="mm", rate_hz=rate, check=False)
        assert np.array_equal(rec.time, np.arange(n) / 240.0)
        for a in [rec.time] + [x for p in rec.poses.values() for x in (p.position, p.rotation)]:
            assert a.base is None and a.flags.c_contiguous
        for s, p in poses.items():
            assert np.array_equal(rec.poses[s].position, p.position)
            assert np.allclose(rec.poses[s].rotation, p.rotation, atol=1e-15)


_TOKENS = st.sampled_from(["01", "02A", "1.5", "-0.25", "+3", "1e-3", "x", ","])
_BLANKS = st.sampled_from([" ", "  ", "\t", " \t ", "\r"])


@SETTINGS
@given(
    lines=st.lists(
        st.tuples(
            st.lists(st.tuples(_BLANKS, _TOKENS), max_size=5),  # (blanks before, token)
            st.sampled_from(["", " ", "\r", "  \r"]),  # the line's end before its newline
        ),
        min_size=1,
        max_size=8,
    ),
    newline_at_end=st.booleans(),
)
def test_ascii_quick_conversion_is_the_token_conversion(lines, newline_at_end):
    """The quick blank-to-comma conversion gives the located-token conversion's text
    (plus one empty last field per line when every line ends in blanks), or declines."""
    from fingerfit.io.liberty import _ascii_to_csv, _ascii_to_csv_quick

    text = "\n".join("".join(blank + tok for blank, tok in toks) + end for toks, end in lines)
    text += "\n" if newline_at_end else ""
    b = np.frombuffer(text.encode(), dtype=np.uint8)
    n_lines = text.count("\n") + (0 if text.endswith("\n") else 1)
    reference, _ = _ascii_to_csv(b)
    quick = _ascii_to_csv_quick(b, n_lines)
    if len(lines) > 1 and not newline_at_end and lines[-1] == ([], ""):
        lines = lines[:-1]  # an empty last line without its newline is not in the text
    with_tokens = [end != "" for toks, end in lines if toks]  # ends in blanks?
    if all(with_tokens):
        assert quick is not None and quick[1] is True
        # one empty last field on every line that holds a token
        ref = "\n".join(ln + "," if ln else ln for ln in reference.tobytes().decode().split("\n"))
    elif len(with_tokens) == len(lines) and not any(with_tokens):
        assert quick is not None and quick[1] is False
        ref = reference.tobytes().decode()
    else:
        assert quick is None
        return
    assert quick[0].tobytes().decode() == ref
