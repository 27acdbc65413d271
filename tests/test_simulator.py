"""The simulator: deterministic, literature-plausible, and exactly kinematic when noise-free."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from fingerfit.io import load_session
from fingerfit.simulate import SimConfig, simulate_cohort, simulate_subject, write_subject
from fingerfit.transforms import angle_between_axes, rotate_about_line, unit

from .conftest import subject


def test_noise_free_sensors_obey_the_kinematic_chain(tmp_path) -> None:
    """Rebuild every phalanx sensor pose from the files alone: truth.json geometry, the
    per-frame truth angles and the hand sensor's motion. Agreement to 1e-9 mm."""
    sim = simulate_subject(SimConfig.exact(fingers=("index", "ring"), hand="right"), 7)
    d = write_subject(sim, tmp_path / "S")
    session = load_session(d)
    truth = json.loads((d / "truth.json").read_text())
    for rec in [*session.grasp, *session.test]:
        angles = pd.read_csv(d / "truth" / rec.name)
        hand = rec.poses["hand"]
        ref_p = np.array(truth["sensors"]["hand"]["position"])
        from fingerfit.transforms import matrix_from_quat_wxyz

        ref_r = matrix_from_quat_wxyz(np.array(truth["sensors"]["hand"]["quat_wxyz"]))
        motion_r = hand.rotation @ ref_r.T
        for f in session.fingers:
            geo = truth["fingers"][f]["joints"]
            th = {j: np.radians(angles[f"{f}.{j}"].to_numpy()) for j in ("mp", "pip", "dip")}
            for depth, seg in enumerate(("proximal", "middle", "distal"), start=1):
                name = f"{f}.{seg}"
                p = np.array(truth["sensors"][name]["position"])
                p = np.broadcast_to(p, (rec.n_frames, 3))
                for j in reversed(("mp", "pip", "dip")[:depth]):
                    p = rotate_about_line(
                        p, np.array(geo[j]["center"]), np.array(geo[j]["axis"]), th[j]
                    )
                p = np.einsum("nij,nj->ni", motion_r, p - ref_p) + hand.position
                err = np.abs(p - rec.poses[name].position).max()
                assert err < 1e-9, (rec.name, name, err)


def test_deterministic_for_a_seed(tmp_path) -> None:
    a = write_subject(simulate_subject(SimConfig(), 3), tmp_path / "a")
    b = write_subject(simulate_subject(SimConfig(), 3), tmp_path / "b")
    c = write_subject(simulate_subject(SimConfig(), 4), tmp_path / "c")
    for name in ("grasp.csv", "landmarks.csv", "truth.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes()
        assert (a / name).read_bytes() != (c / name).read_bytes()


def test_cohort_is_anatomically_plausible() -> None:
    cohort = simulate_cohort(
        SimConfig(fingers=("index", "little"), test=False, targets=False), 12, 1
    )
    lengths = np.array([s.truth.fingers["index"].lengths for s in cohort])
    # Index link lengths near the X-ray means (39.8, 22.4, 15.8 + 3.8 mm), with scatter.
    assert 33 < lengths[:, 0].mean() < 47 and 19 < lengths[:, 1].mean() < 26
    assert lengths[:, 0].std() > 1.0
    tilts = []
    for s in cohort:
        f = s.truth.fingers["index"]
        x = unit(f.centre[1] - f.centre[0])
        tilts.append(np.degrees(np.pi / 2 - angle_between_axes(f.axis, x)))
    tilts = np.abs(np.array(tilts))
    # Several degrees off perpendicular on average, individually different, never absurd.
    assert 2.0 < tilts.mean() < 10.0 and tilts.std() > 1.0 and tilts.max() < 25.0
    little = np.array([s.truth.fingers["little"].lengths[0] for s in cohort])
    assert little.mean() < lengths[:, 0].mean()


def test_protocol_shapes() -> None:
    sim = subject("realistic", 2)
    s = sim.session
    assert s.rate_hz == 240.0
    assert s.reference.n_frames >= 240
    # 10 grasp cycles of ~2 s.
    assert 18.0 < s.grasp[0].time[-1] < 24.0
    mp = np.degrees(sim.truth.frames["grasp.csv"]["angles"]["index"]["mp"])
    rising = np.flatnonzero(np.diff((mp > 30).astype(int)) == 1)
    assert rising.size == 10
    # Targets 0-120 mm by 20 mm along a straight edge.
    t = np.array([s.landmarks[f"target.t{d:03d}"] for d in range(0, 121, 20)])
    steps = np.linalg.norm(np.diff(t, axis=0), axis=1)
    np.testing.assert_allclose(steps, 20.0, atol=1.0)
    assert len(s.events) == 7


def test_true_fingertip_touches_targets() -> None:
    sim = subject("exact", 11)
    s = sim.session
    frames = sim.truth.frames["targets.csv"]
    for ev in s.events:
        k = (frames["time"] >= ev.start) & (frames["time"] <= ev.end)
        err = np.linalg.norm(frames["tip"]["index"][k] - s.landmarks[f"target.{ev.target}"], axis=1)
        assert err.max() < 1e-9


def test_each_error_source_switches() -> None:
    """Each source is off in SimConfig.exact() and on in the realistic default."""
    off = simulate_subject(SimConfig.exact(test=False, targets=False), 9)
    on = simulate_subject(SimConfig(test=False, targets=False), 9)
    for sim, active in ((off, False), (on, True)):
        f = sim.truth.fingers["index"]
        frames = sim.truth.frames["grasp.csv"]
        measured = sim.session.grasp[0].poses["index.middle"].position
        true = frames["sensors"]["index.middle"][0]
        mount = sim.truth.mounts["index.middle"]
        assert (np.abs(measured - true).max() > 0.05) == active  # tracker noise
        assert (np.abs(f.rolling).max() > 0) == active  # rolling contact
        assert (np.abs(frames["angles"]["index"]["mp_abduction"]).max() > 0) == active
        assert (np.abs(mount.sta_translation).max() > 0) == active  # soft-tissue artefact
