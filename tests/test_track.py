"""Tracking with the model (fingerfit.track): joint angles and fingertips from fewer sensors.

Against known truth: noise-free simulated frames give the true angles back for every
layout that determines them; a realistic simulated subject under reduced layouts stays
within bounds looser than the targets of docs/tracking.md; dropouts leave no frame without
a fingertip; the live filter agrees with the offline solution; the solver's gradient is
the derivative of its cost.
"""

from __future__ import annotations

import functools
import warnings
from dataclasses import replace

import numpy as np
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.kinematics import KinematicsPlan, compute_kinematics
from fingerfit.model import load_model, save_model
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate.truthmodel import truth_model
from fingerfit.track import TrackOptions, check_layout, track_recording, tracking_statistics
from fingerfit.track.chains import Chains
from fingerfit.track.live import FROM_MODEL, FROM_SENSORS, HELD, LiveTracker
from fingerfit.track.recording import with_every_sensor
from fingerfit.track.solver import data_terms, observe
from fingerfit.track.weights import chain_weights

from .conftest import subject

DIGITS = ("thumb", "index")
#: Every layout of the thumb and index that determines every joint: the sensors kept.
LAYOUTS = {
    "no middle": ["hand", "thumb.metacarpal", "thumb.distal", "index.proximal", "index.distal"],
    "no proximal": ["hand", "thumb.proximal", "thumb.distal", "index.middle", "index.distal"],
    "distal only": ["hand", "thumb.distal", "index.distal"],
}
#: The IK alone: no bounds, no temporal prior (exactness).
PLAIN = TrackOptions(bounds=False, temporal=False)


def keep(rec: Recording, sensors: list[str]) -> Recording:
    return Recording(rec.name, rec.time, {s: rec.poses[s] for s in sensors})


@functools.cache
def exact_model():
    """The true model of a noise-free thumb + index subject, with its calibration
    statistics, and the subject."""
    sim = subject("exact", 5, DIGITS)
    model = truth_model(sim)
    return replace(model, tracking=tracking_statistics(model, sim.session.grasp)), sim


@functools.cache
def realistic():
    """A realistic thumb + index subject fitted by the default method."""
    sim = subject("realistic", 4, DIGITS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sim.session, FitOptions(force=True))
    return model, sim


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_noise_free_frames_give_the_true_angles_back(layout: str) -> None:
    model, sim = exact_model()
    rec = sim.session.test[0].slice(slice(0, 600))
    truth = sim.truth.frames[rec.name]
    tracked = track_recording(model, rec, ("user_axis",), sensors=LAYOUTS[layout], options=PLAIN)
    for d in DIGITS:
        m = tracked.kinematics.motions["user_axis"][d]
        for k, a in m.angles.items():
            err = np.degrees(np.abs(a - truth["angles"][d][k][:600]))
            assert err.max() < 1e-6, (d, k, err.max())
        assert np.abs(m.tip - truth["tip"][d][:600]).max() < 1e-6  # mm
        assert tracked.digits[d].model.all()  # every frame solved by the model
    # With the bounds and the temporal prior (the defaults): still the truth, their pull
    # on noise-free sensors being tiny.
    tracked = track_recording(model, rec, ("user_axis",), sensors=LAYOUTS[layout])
    for d in DIGITS:
        for k, a in tracked.kinematics.motions["user_axis"][d].angles.items():
            assert np.degrees(np.abs(a - truth["angles"][d][k][:600])).max() < 1e-3


def test_a_full_layout_is_the_direct_computation_to_the_bit() -> None:
    model, sim = realistic()
    rec = sim.session.test[0]
    tracked = track_recording(model, rec)
    direct = compute_kinematics(model, rec)
    assert not tracked.digits  # nothing solved by the model
    for v, ms in direct.motions.items():
        for d, m in ms.items():
            got = tracked.kinematics.motions[v][d]
            for k, a in m.angles.items():
                np.testing.assert_array_equal(got.angles[k], a)
            np.testing.assert_array_equal(got.tip, m.tip)
            np.testing.assert_array_equal(got.pad, m.pad)


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(a**2)))


def test_reduced_layouts_stay_within_bounds_on_a_realistic_subject() -> None:
    """Looser than the benchmark's targets (bench/tracking.py, docs/tracking.md), on one
    subject the fit never saw moving this way (its free-motion test recording)."""
    model, sim = realistic()
    rec = sim.session.test[0]
    truth = sim.truth.frames[rec.name]
    full = track_recording(model, rec, ("user_axis",)).kinematics.motions["user_axis"]

    def tip(kin) -> float:
        return float(
            np.mean([np.linalg.norm(kin[d].tip - truth["tip"][d], axis=1).mean() for d in DIGITS])
        )

    base = tip(full)
    got = {
        name: track_recording(model, rec, ("user_axis",), sensors=s).kinematics.motions["user_axis"]
        for name, s in LAYOUTS.items()
    }
    # Each finger's middle phalanx (the thumb's proximal) absent: the tip as good as with
    # every sensor; PIP and DIP a few degrees from the full layout's.
    assert tip(got["no middle"]) <= 1.25 * base
    for k in ("pip", "dip"):
        assert _rms(np.degrees(got["no middle"]["index"].angles[k] - full["index"].angles[k])) < 4.0
    # The hand and each digit's distal sensor: the split of the flexion between the joints
    # is poorly determined, the tip is not.
    assert tip(got["distal only"]) <= 1.4 * base
    limits = {"mp": 6.0, "pip": 15.0, "dip": 12.0}
    for k, lim in limits.items():
        assert (
            _rms(np.degrees(got["distal only"]["index"].angles[k] - full["index"].angles[k])) < lim
        )
    for name, kin in got.items():
        for d in DIGITS:
            assert np.isfinite(kin[d].tip).all(), name


def _dropout(rec: Recording, sensor: str, rng: np.random.Generator) -> Recording:
    """``sensor`` missing for about 20 % of the frames, in bursts of 0.1-2 s."""
    n = rec.n_frames
    mask = np.zeros(n, dtype=bool)
    while mask.mean() < 0.2:
        length = int(rng.uniform(0.1, 2.0) * 240)
        start = int(rng.integers(0, n - length))
        mask[start : start + length] = True
    poses = dict(rec.poses)
    p = poses[sensor]
    pos, r = p.position.copy(), p.rotation.copy()
    pos[mask], r[mask] = np.nan, np.nan
    poses[sensor] = PoseSeries(pos, r)
    return Recording(rec.name, rec.time, poses)


@pytest.mark.parametrize("sensor", ["index.proximal", "index.middle", "index.distal"])
def test_dropouts_leave_every_frame_with_a_fingertip(sensor: str) -> None:
    model, sim = realistic()
    rec = sim.session.test[0]
    truth = sim.truth.frames[rec.name]
    dropped = _dropout(rec, sensor, np.random.default_rng(7))
    tracked = track_recording(model, dropped)
    t = tracked.digits["index"]
    missing = ~dropped.poses[sensor].valid
    np.testing.assert_array_equal(t.model, missing)  # the model solved exactly those frames
    for v in ("user_axis", "orthogonal"):
        m = tracked.kinematics.motions[v]["index"]
        assert np.isfinite(m.tip).all() and all(np.isfinite(a).all() for a in m.angles.values())
    assert np.isfinite(t.rms_mm[missing]).all() and np.isnan(t.rms_mm[~missing]).all()
    # A joint the frame's own sensors leave open (the distal sensor out: DIP) is carried
    # from the frames around it and says so, with an infinite standard deviation.
    carried = t.carried
    if sensor == "index.distal":
        np.testing.assert_array_equal(carried, missing)
        assert np.isinf(t.sd["dip"][missing]).all()
    else:
        assert not carried.any() and np.isfinite(t.sd["pip"][missing]).all()
    # Where the sensors determine every joint, the tip stays as good as with every sensor.
    kin = tracked.kinematics.motions["user_axis"]["index"]
    full = compute_kinematics(model, rec).motions["user_axis"]["index"]
    err = np.linalg.norm(kin.tip - truth["tip"]["index"], axis=1)
    base = np.linalg.norm(full.tip - truth["tip"]["index"], axis=1)
    if sensor != "index.distal":
        assert err[missing].mean() <= 1.25 * base[missing].mean()


def test_the_live_filter_agrees_with_the_offline_solution() -> None:
    """index.middle vanishes for 2 s: the filter, one frame at a time, stays close to the
    offline solution of the whole recording (which also looks ahead)."""
    model, sim = realistic()
    rec = with_every_sensor(sim.session.test[0].slice(slice(0, 960)), list(model.reference_poses))
    poses = dict(rec.poses)
    p = poses["index.middle"]
    pos, r = p.position.copy(), p.rotation.copy()
    pos[240:720], r[240:720] = np.nan, np.nan
    poses["index.middle"] = PoseSeries(pos, r)
    rec = Recording(rec.name, rec.time, poses)
    offline = track_recording(model, rec, ("user_axis",)).kinematics.motions["user_axis"]
    plan = KinematicsPlan(model, ("user_axis",))
    tracker = LiveTracker(model)
    got = {k: np.empty(rec.n_frames) for k in ("pip", "dip")}
    sources = []
    for t in range(rec.n_frames):
        one = rec.slice(slice(t, t + 1))
        kin = plan.run(one)
        if t < 240 or t >= 720:
            tracker.remember(kin, float(one.time[0]))
            sources.append(FROM_SENSORS)
        else:
            sources.append(tracker.step(one, kin)["index"])
        for k in got:
            got[k][t] = kin.motions["user_axis"]["index"].angles[k][0]
    assert sources[240:720] == [FROM_MODEL] * 480
    for k in got:
        diff = np.degrees(got[k] - offline["index"].angles[k])
        assert np.isfinite(got[k]).all()
        assert _rms(diff[240:720]) < 0.6 and np.abs(diff).max() < 2.5, k
        np.testing.assert_allclose(diff[:240], 0.0, atol=1e-12)  # direct: every sensor there


def test_a_frame_without_the_hand_is_held_by_the_live_filter() -> None:
    model, sim = realistic()
    rec = with_every_sensor(sim.session.test[0].slice(slice(0, 2)), list(model.reference_poses))
    poses = dict(rec.poses)
    poses["hand"] = PoseSeries(np.full((2, 3), np.nan), np.full((2, 3, 3), np.nan))
    one = Recording(rec.name, rec.time, poses).slice(slice(1, 2))
    kin = KinematicsPlan(model, ("user_axis",)).run(one)
    status = LiveTracker(model).step(one, kin)
    assert status == dict.fromkeys(model.fingers, HELD)


@pytest.mark.parametrize(
    ("sensors", "text"),
    [
        (["index.proximal", "index.middle", "index.distal"], "no 'hand' sensor"),
        (["hand", "index.distal"], "thumb: no sensor on the digit (thumb.distal would"),
        (["hand", "thumb.distal", "index.proximal", "index.middle"], "index dip: not determined"),
        (["hand", "thumb.metacarpal", "index.distal"], "thumb mcp: not determined"),
    ],
)
def test_a_layout_that_cannot_determine_a_joint_is_refused_naming_it(sensors, text) -> None:
    model, _ = realistic()
    with pytest.raises(FingerfitError) as err:
        check_layout(model, set(sensors), list(model.fingers), "rec.csv", skip="--fingers")
    assert text in str(err.value) and "\n" not in str(err.value)
    if "not determined" in text:  # names the sensor that would determine it
        assert text.split()[0] + ".distal would determine it" in str(err.value)


def test_tracking_statistics_survive_the_model_file_and_old_files_say_fit_again(tmp_path) -> None:
    model, sim = realistic()
    back = load_model(save_model(model, tmp_path / "m.json"))
    assert back.tracking == model.tracking
    s = model.tracking.sensors["user_axis"]["index.distal"]
    assert 0.05 < s.position_mm < 5.0 and 0.01 < s.orientation_deg < 5.0
    a = model.tracking.angles["user_axis"]["index"]["pip"]
    assert a.low_deg <= 0.0 < 45.0 < a.high_deg < 130.0 and 50.0 < a.speed_deg_s < 2000.0
    old = replace(model, tracking=None)
    rec = keep(sim.session.test[0], LAYOUTS["no middle"])
    with pytest.raises(FingerfitError, match="fit it again"):
        track_recording(old, rec)
    track_recording(old, sim.session.test[0])  # every sensor: no statistics needed


def test_the_step_is_the_cost_s_derivative() -> None:
    """data_terms' right-hand side is minus half the gradient of its cost (central
    differences, 1e-6 relative), migrating centres and two-axis joints included."""
    model, sim = realistic()
    chains = Chains(model, ("user_axis",), list(DIGITS))
    w = chain_weights(model, chains, TrackOptions())
    rec = sim.session.test[0].slice(slice(100, 104))
    h = rec.poses["hand"]
    obs = observe(
        chains,
        h.position,
        h.rotation,
        {s: p.position for s, p in rec.poses.items()},
        {s: p.rotation for s, p in rec.poses.items()},
    )
    rng = np.random.default_rng(3)
    q = rng.normal(0, 0.4, (chains.size, chains.L, 4)) * chains.active[..., None]
    t = data_terms(chains, w, obs, q)
    eps = 1e-6
    num = np.zeros_like(q)
    for d in range(chains.size):
        for k in range(chains.levels[d]):
            dq = np.zeros_like(q)
            dq[d, k] = eps
            up, down = (
                data_terms(chains, w, obs, q + dq).cost,
                data_terms(chains, w, obs, q - dq).cost,
            )
            num[d, k] = -(up[d] - down[d]) / (4 * eps)
    assert np.abs(num - t.gradient).max() < 1e-6 * np.abs(t.gradient).max()
