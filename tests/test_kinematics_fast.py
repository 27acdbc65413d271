"""The block kernel of ``compute_kinematics`` (swing-twist models) against the plain path.

The reference is the straightforward computation from the public pieces: ``finger_angles``
(relative rotation, then traces and atan2), ``chain_points`` (cos/sin of each angle) and
``carry_by_hand``. Random sensor rotations and positions, NaN frames, several blocks, a
two-axis MP joint, hinge-only fingers and a migrating (rolling-contact) centre; the whole
hand (thumb with its two-axis CMC and MCP beside four fingers, all digits at once) one
frame at a time, as the live stream runs it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit import kinematics as kin
from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.model import VARIANTS, HandModel
from fingerfit.session import HAND_SENSOR, PoseSeries, Recording
from fingerfit.simulate.truthmodel import truth_model

from .conftest import subject

HAND = ("thumb", "index", "middle", "ring", "little")


def reference(
    model: HandModel, rec: Recording, variants: tuple[str, ...], point: str = "tip"
) -> dict:
    """variant, digit -> (angles, the ``point`` (``tip`` or ``pad``)) by the plain path."""
    hand = rec.pose(HAND_SENSOR)
    out = {}
    for f, fm in model.fingers.items():
        angles = kin.finger_angles(model, f, rec, variants, method="swing_twist")
        for v in variants:
            local = kin.chain_points(fm, v, angles[v], getattr(fm, point))
            out[v, f] = angles[v], kin.carry_by_hand(model, hand.rotation, hand.position, local)
    return out


def random_recording(model: HandModel, n: int, seed: int) -> Recording:
    """Sensor poses near the reference ones (tens of degrees away) plus a few NaN frames."""
    rng = np.random.default_rng(seed)
    poses = {}
    for sensor, (p, r) in model.reference_poses.items():
        turn = Rotation.from_rotvec(rng.normal(scale=0.6, size=(n, 3))).as_matrix()
        position = p + rng.normal(scale=20.0, size=(n, 3))
        rotation = turn @ r
        rotation[rng.integers(0, n, 3)] = np.nan
        poses[sensor] = PoseSeries(position, rotation)
    # Exactly the reference posture (zero angles, a twist atan2(0, 2)) on the first frame.
    for sensor, (p, r) in model.reference_poses.items():
        poses[sensor].position[0], poses[sensor].rotation[0] = p, r
    return Recording("random", np.arange(n) / 240.0, poses)


@pytest.fixture(scope="module")
def models() -> dict[str, HandModel]:
    session = subject("realistic", 2).session
    two_axis = fit_session(session, FitOptions())  # the default: swing-twist, two-axis MP
    hinge = fit_session(session, FitOptions(method="pooled", angle_method="swing_twist"))
    rng = np.random.default_rng(5)
    fm = hinge.fingers["index"]
    rolling = replace(
        hinge,
        fingers={
            "index": replace(
                fm,
                joints={
                    j: replace(jm, migration=rng.normal(scale=2.0, size=3))
                    for j, jm in fm.joints.items()
                },
            )
        },
    )
    return {"two_axis": two_axis, "hinge": hinge, "rolling": rolling}


@pytest.mark.parametrize("kind", ["two_axis", "hinge", "rolling"])
def test_block_kernel_equals_reference(
    models: dict[str, HandModel], kind: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    model = models[kind]
    assert model.angle_method == "swing_twist"
    assert (model.fingers["index"].second_axes.get("mp") is not None) == (kind == "two_axis")
    rec = random_recording(model, 2500, seed=len(kind))
    monkeypatch.setattr(kin, "BLOCK_FRAMES", 1000)  # three blocks, the last one short
    got = kin.compute_kinematics(model, rec)
    want = reference(model, rec, VARIANTS)
    for (v, f), (angles, tip) in want.items():
        motion = got.motions[v][f]
        assert list(motion.angles) == list(angles)
        for j, a in angles.items():
            np.testing.assert_array_equal(np.isnan(motion.angles[j]), np.isnan(a))
            np.testing.assert_allclose(motion.angles[j], a, rtol=0, atol=1e-10)
            assert np.nanmax(np.abs(a)) > 0.3  # the random poses really move the joints
        assert np.isnan(tip).any(axis=1).sum() > 0
        np.testing.assert_array_equal(np.isnan(motion.tip), np.isnan(tip))
        np.testing.assert_allclose(motion.tip, tip, rtol=0, atol=1e-10)
        assert np.all(np.abs(motion.angles["mp"][0]) < 1e-12)  # reference posture


def test_block_kernel_single_variant_and_missing_sensor(models: dict[str, HandModel]) -> None:
    model = models["two_axis"]
    rec = random_recording(model, 300, seed=1)
    got = kin.compute_kinematics(model, rec, variants=("orthogonal",))
    angles, tip = reference(model, rec, ("orthogonal",))["orthogonal", "index"]
    np.testing.assert_allclose(
        got.motions["orthogonal"]["index"].angles["mp_abduction"],
        angles["mp_abduction"],
        atol=1e-10,
    )
    np.testing.assert_allclose(got.motions["orthogonal"]["index"].tip, tip, atol=1e-10)
    assert list(got.motions) == ["orthogonal"]
    poses = {k: v for k, v in rec.poses.items() if k != "index.middle"}
    with pytest.raises(FingerfitError, match=r"index\.middle"):
        kin.compute_kinematics(model, Recording("r", rec.time, poses))


@pytest.mark.parametrize("migration", [False, True])
def test_one_frame_whole_hand(migration: bool) -> None:
    """The live stream's call: one-frame blocks of a whole hand, both variants, against the
    plain path (1e-12 relative or deg and mm) and the same frames run as one block; a frame that lacks
    one sensor gives NaN for that digit only, a frame that lacks the hand sensor for all."""
    model = truth_model(subject("realistic", 2, HAND), migration=migration)
    assert list(model.fingers) == list(HAND)
    assert len(model.fingers["thumb"].chain()) == 5  # two-axis CMC and MCP
    assert any(jm.migration is not None for jm in model.fingers["index"].chain()) == migration
    rec = random_recording(model, 40, seed=3)
    missing = {5: "index.middle", 6: "thumb.metacarpal", 7: HAND_SENSOR}
    for i, sensor in missing.items():  # that sensor alone: the random NaN frames elsewhere
        for name, (_, r) in model.reference_poses.items():
            rec.poses[name].rotation[i] = r
        rec.poses[sensor].rotation[i] = np.nan
    sensors = {f: model_sensors(model, f) for f in HAND}
    plan = kin.KinematicsPlan(model, VARIANTS)
    block = plan.run(rec)
    tips, pads = reference(model, rec, VARIANTS), reference(model, rec, VARIANTS, "pad")
    for i in range(rec.n_frames):
        one = plan.run(rec.slice(slice(i, i + 1)))
        assert list(one.motions) == list(VARIANTS)
        for v in VARIANTS:
            assert list(one.motions[v]) == list(HAND)
            for f in HAND:
                motion, whole = one.motions[v][f], block.motions[v][f]
                angles, tip = tips[v, f]
                got = [
                    (motion.tip, tip[i : i + 1], 1.0),
                    (motion.pad, pads[v, f][1][i : i + 1], 1.0),
                ]
                got += [
                    (motion.angles[j], a[i : i + 1], np.degrees(1.0)) for j, a in angles.items()
                ]
                assert list(motion.angles) == list(angles)
                for x, want, scale in got:
                    np.testing.assert_allclose(x * scale, want * scale, rtol=1e-12, atol=1e-12)
                for x, y in zip(
                    [motion.tip, motion.pad, *motion.angles.values()],
                    [whole.tip, whole.pad, *whole.angles.values()],
                    strict=True,
                ):
                    np.testing.assert_allclose(x, y[i : i + 1], rtol=1e-12, atol=1e-12)
                lacks = any(np.isnan(rec.poses[s].rotation[i]).any() for s in sensors[f])
                for x in (motion.tip, motion.pad):  # (an angle: its own two sensors)
                    assert np.isnan(x).all() if lacks else np.isfinite(x).all()
    # The frame without index.middle: the index is NaN, the other digits are not.
    one = plan.run(rec.slice(slice(5, 6))).motions["user_axis"]
    assert np.isnan(one["index"].tip).all()
    assert all(np.isfinite(one[f].tip).all() for f in HAND if f != "index")
    assert all(
        np.isnan(m.tip).all()
        for m in plan.run(rec.slice(slice(7, 8))).motions["orthogonal"].values()
    )


def model_sensors(model: HandModel, digit: str) -> set[str]:
    """The sensors of a digit's joints (the hand sensor included)."""
    return {s for jm in model.fingers[digit].joints.values() for s in (jm.parent, jm.child)}


def test_plan_on_no_frames(models: dict[str, HandModel]) -> None:
    """A recording without frames (a stream's empty block): empty angles and points."""
    model = models["two_axis"]
    empty = random_recording(model, 5, seed=2).slice(slice(0, 0))
    got = kin.KinematicsPlan(model, VARIANTS).run(empty)
    for v in VARIANTS:
        for motion in got.motions[v].values():
            assert motion.tip.shape == (0, 3)
            assert all(a.shape == (0,) for a in motion.angles.values())
