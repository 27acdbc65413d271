"""Data hygiene: repeats, grids, gaps (linear + slerp), jumps, unit plausibility, rigid fits."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.errors import FingerfitError
from fingerfit.io.hygiene import (
    centred_median,
    check_increasing,
    check_units,
    fill_gaps,
    find_jumps,
    jump_notes,
    place_on_grid,
    repeated_rows,
)
from fingerfit.io.rigid import cluster_shape, fit_cluster, technical_frame
from fingerfit.session import PoseSeries, Recording


def rotating(n: int, rate: float = 100.0, omega_deg_s: float = 90.0, speed: float = 50.0):
    """A sensor turning at constant angular velocity about a fixed axis, moving linearly."""
    t = np.arange(n) / rate
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    rot = Rotation.from_rotvec(np.radians(omega_deg_s) * t[:, None] * axis).as_matrix()
    pos = np.array([100.0, 20.0, -30.0]) + speed * t[:, None] * np.array([1.0, 0.0, 0.0])
    return t, PoseSeries(pos, rot)


def test_repeated_rows() -> None:
    v = np.array([[1, 2], [1, 2], [1, 3], [np.nan, 3], [np.nan, 3], [1, 3.0]])
    assert repeated_rows(v).tolist() == [False, True, False, False, True, False]
    assert repeated_rows(np.zeros((0, 3))).tolist() == []


def test_check_increasing_and_grid() -> None:
    lines = np.arange(5) + 10
    check_increasing(np.array([0, 1, 1, 2.0]), lines, "f.csv", strict=False)
    with pytest.raises(FingerfitError, match=r"f\.csv:12: field 'time': time does not increase"):
        check_increasing(np.array([0, 1, 1, 2.0]), lines, "f.csv")
    with pytest.raises(FingerfitError, match=r"f\.csv:13: field 'time': time goes backwards"):
        check_increasing(np.array([0, 1, 2, 1.5]), lines, "f.csv")
    t = np.array([0.0, 0.01, 0.0301, 0.05])
    grid, idx = place_on_grid(t, 100.0, lines, "f.csv")
    assert idx.tolist() == [0, 1, 3, 5]
    np.testing.assert_allclose(grid, [0, 0.01, 0.02, 0.0301, 0.04, 0.05])
    with pytest.raises(FingerfitError, match=r"f\.csv:12: .*not on the 100 Hz sampling grid"):
        place_on_grid(np.array([0.0, 0.01, 0.015]), 100.0, lines, "f.csv")


def test_fill_gaps_linear_and_slerp_exact_for_uniform_motion() -> None:
    t, truth = rotating(50)
    pos, rot = truth.position.copy(), truth.rotation.copy()
    gaps = [slice(5, 8), slice(20, 21), slice(30, 40), slice(0, 2), slice(48, 50)]
    for g in gaps:
        pos[g] = np.nan
        rot[g] = np.nan
    rec = Recording("r.csv", t, {"hand": PoseSeries(pos, rot)})
    out = fill_gaps(rec, 3)
    got = out.poses["hand"]
    filled = np.r_[5:8, 20]
    # Uniform motion: linear position and slerp orientation are exact.
    np.testing.assert_allclose(got.position[filled], truth.position[filled], atol=1e-9)
    np.testing.assert_allclose(got.rotation[filled], truth.rotation[filled], atol=1e-9)
    assert np.isnan(got.position[np.r_[0:2, 30:40, 48:50]]).all()
    assert out.notes == [
        "sensor 'hand': 2 gaps (4 frames) interpolated (at most 3 frames; positions linear, "
        "orientations slerp); 1 longer gaps kept as NaN"
    ]
    assert np.isnan(rec.poses["hand"].position[5]).all()  # input untouched
    assert fill_gaps(rec, 0).notes == ["sensor 'hand': 3 gaps longer than 0 frames kept as NaN"]


def test_find_jumps_hemisphere_flip_and_smooth_fast_motion() -> None:
    t, pose = rotating(200, rate=120.0, speed=2000.0)
    pos = pose.position.copy()
    pos[80:150] *= -1.0  # hemisphere flip: position mirrored through the source
    rot = pose.rotation.copy()
    rot[170] = Rotation.from_rotvec([0, 0, np.pi / 2]).as_matrix() @ rot[170]  # one bad sample
    rec = Recording("j.csv", t, {"hand": PoseSeries(pos, rot)})
    jumps = find_jumps(rec)
    pj = [j for j in jumps if j.kind == "position"]
    assert [(j.frame, j.hemisphere) for j in pj] == [(80, True), (150, True)]
    oj = [j for j in jumps if j.kind == "orientation"]
    assert [j.frame for j in oj] == [170]
    assert oj[0].end_frame == 171 and oj[0].peak > 90 * 120 * 0.9
    notes = jump_notes(jumps, max_speed_mm_s=3000, max_turn_deg_s=3600)
    assert notes[0].startswith("sensor 'hand': 2 position jumps (> 3000 mm/s) flagged at frames 80")
    # Smooth movement faster than the absolute limit is not a jump (the local median rule).
    _, fast = rotating(200, rate=120.0, speed=6000.0)
    assert find_jumps(Recording("f.csv", t, {"hand": fast})) == []
    # ... but it is with a lower relative factor and a window spanning the whole recording.
    assert len(find_jumps(Recording("f.csv", t, {"hand": fast}), relative=0.5, window=401)) > 0


@pytest.mark.parametrize("window", [1, 2, 3, 4, 21, 26])
def test_centred_median_is_pandas_centred_rolling_median_at_the_indices(window) -> None:
    """The jump rule's local median, taken at the fast steps only, is value for value
    pandas' centred rolling median (NaN ignored, windows cut at both ends)."""
    pd = pytest.importorskip("pandas")
    rng = np.random.default_rng(window)
    for n in (1, 2, 5, 40, 70_000):
        v = rng.gamma(1.0, 1.0, n)
        v[rng.random(n) < 0.1] = np.nan
        at = np.flatnonzero(np.isfinite(v))
        ref = pd.Series(v).rolling(window, center=True, min_periods=1).median().to_numpy()
        assert np.array_equal(centred_median(v, at, window), ref[at])
    assert centred_median(v, at[:0], window).shape == (0,)


def hand_recording(scale: float) -> Recording:
    t = np.arange(10) / 100.0
    eye = np.broadcast_to(np.eye(3), (10, 3, 3)).copy()
    poses = {}
    # hand at x = 200 mm; proximal, middle, distal 60, 30 and 20 mm further along x.
    for x, name in zip(
        (200.0, 260.0, 290.0, 310.0),
        ("hand", "index.proximal", "index.middle", "index.distal"),
        strict=True,
    ):
        pos = np.broadcast_to(np.array([x, 0.0, 0.0]) * scale, (10, 3)).copy()
        poses[name] = PoseSeries(pos, eye)
    return Recording("u.csv", t, poses)


def test_check_units() -> None:
    check_units(hand_recording(1.0))
    with pytest.raises(
        FingerfitError,
        match=r"u\.csv: field 'units': implausible distance 600 mm between sensors 'hand' "
        r"and 'index\.proximal'",
    ):
        check_units(hand_recording(10.0), "u.csv")
    with pytest.raises(FingerfitError, match=r"implausible distance 2\.362 mm"):
        check_units(hand_recording(1 / 25.4), "u.csv")
    with pytest.raises(FingerfitError, match=r"sensor 'hand' is 200 m from the tracker origin"):
        check_units(hand_recording(1000.0), "u.csv")


# ------------------------------------------------------------------------- rigid fits


def test_fit_cluster_matches_scipy_and_truth() -> None:
    rng = np.random.default_rng(3)
    shape = rng.normal(scale=40.0, size=(5, 3))
    n = 300
    rot = Rotation.random(n, random_state=4)
    trans = rng.normal(scale=500.0, size=(n, 3))
    markers = np.einsum("nij,mj->nmi", rot.as_matrix(), shape) + trans[:, None, :]
    noisy = markers + rng.normal(scale=0.2, size=markers.shape)
    noisy[10, 0] = np.nan  # 4 visible: still fitted
    noisy[11, :3] = np.nan  # 2 visible: not fitted
    fit = fit_cluster(noisy, shape)
    assert fit.n_markers[10] == 4 and fit.n_markers[11] == 2
    assert np.isnan(fit.rotation[11]).all() and np.isnan(fit.residual[11])
    ok = np.isfinite(fit.residual)
    err = (Rotation.from_matrix(fit.rotation[ok]) * rot[ok].inv()).magnitude()
    assert np.degrees(err).max() < 1.0 and np.degrees(np.median(err)) < 0.3
    assert 0.1 < np.median(fit.residual[ok]) < 0.3
    # Same answer as scipy's align_vectors (the reference least-squares solution).
    k = 42
    c = noisy[k].mean(axis=0)
    ref, _ = Rotation.align_vectors(noisy[k] - c, shape - shape.mean(axis=0))
    assert np.degrees((ref * Rotation.from_matrix(fit.rotation[k]).inv()).magnitude()) < 1e-6
    exact = fit_cluster(markers, shape)
    np.testing.assert_allclose(exact.translation, trans, atol=1e-8)
    assert np.nanmax(exact.residual) < 1e-9


def test_cluster_shape_defines_a_reproducible_frame() -> None:
    rng = np.random.default_rng(5)
    local = np.array([[0.0, 0, 0], [60, 0, 0], [20, 40, 0], [30, 10, 25]])
    n = 100
    rot = Rotation.random(n, random_state=6)
    markers = np.einsum("nij,mj->nmi", rot.as_matrix(), local)
    markers += rng.normal(scale=300, size=(n, 1, 3))
    markers[3, 2] = np.nan
    shape = cluster_shape(markers)
    # The shape's own technical frame is the identity at the origin.
    r, o = technical_frame(shape)
    np.testing.assert_allclose(r, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(o, 0.0, atol=1e-12)
    # Same inter-marker distances as the true cluster.
    d = np.linalg.norm(shape[:, None] - shape[None], axis=2)
    np.testing.assert_allclose(d, np.linalg.norm(local[:, None] - local[None], axis=2), atol=1e-9)
    with pytest.raises(ValueError, match="collinear"):
        cluster_shape(np.tile([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]], (5, 1, 1)))
    with pytest.raises(ValueError, match="no frame"):
        cluster_shape(np.full((3, 3, 3), np.nan))
