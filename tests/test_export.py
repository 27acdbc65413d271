"""Robot export: URDF and MJCF loaded by Pinocchio and MuJoCo reproduce fingerfit's FK.

Reference: :func:`fingerfit.kinematics.chain_points` (product of exponentials in
tracker coordinates at the reference posture, mm), expressed here in the hand
sensor frame in metres, ``R_h0^T (p - t_h0) / 1000``.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.estimate import fit_session
from fingerfit.export import mjcf_string, robot_hand, urdf_string
from fingerfit.export.geometry import SYMMETRIC, capsule_inertial
from fingerfit.kinematics import chain_points
from fingerfit.model import (
    DigitModel,
    HandModel,
    JointModel,
    JointQuality,
    SegmentFrame,
    load_model,
    save_model,
)
from fingerfit.session import JOINTS

from .conftest import subject

pin = pytest.importorskip("pinocchio")
mujoco = pytest.importorskip("mujoco")
pytest.importorskip("yourdfpy")

POS_TOL_M = 1e-6
DIR_TOL = 1e-9
MARGIN_DEG = 10.0


# --------------------------------------------------------------------------- models


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _quality(rom: list[float]) -> JointQuality:
    n = len(rom)
    return JointQuality(n, rom, [0.1] * n, [50.0] * n, 0.5, [0.1] * n)


def synthetic_model(
    seed: int, tilt_deg: float = 30.0, abduction: bool = False, fingers=("index", "middle")
) -> HandModel:
    """A hand with flexion axes tilted up to ``tilt_deg`` from the bone normal (mm, tracker)."""
    rng = np.random.default_rng(seed)
    r_h = Rotation.random(random_state=seed).as_matrix()
    t_h = rng.uniform(-300, 300, 3)
    poses = {"hand": (t_h, r_h)}
    out = {}
    for k, f in enumerate(fingers):
        # finger frame: x distal, y flexion-axis side, z dorsal (hand frame, then tracker)
        rf = r_h @ Rotation.from_euler("zyx", rng.uniform(-0.3, 0.3, 3)).as_matrix()
        x, y, z = rf.T
        lengths = rng.uniform([38, 22, 18], [50, 30, 24])
        mp = t_h + r_h @ np.array([70.0, -20.0 * k, -12.0])
        centres = [mp]
        for length in lengths[:2]:
            centres.append(centres[-1] + length * _unit(x + rng.normal(0, 0.05, 3)))
        tip = centres[-1] + lengths[2] * x + 3.0 * z
        tilts = rng.uniform(0.5, 1.0, 3) * tilt_deg
        tilts[k % 3] = tilt_deg  # at least one axis at the full tilt
        joints = {}
        segs = ("proximal", "middle", "distal")
        parents = ["hand", f"{f}.proximal", f"{f}.middle"]
        for i, j in enumerate(JOINTS):
            d = _unit(np.cross(y, rng.normal(size=3)))  # tilt direction, perpendicular to y
            axis = Rotation.from_rotvec(np.radians(tilts[i]) * d).apply(y)
            rom = list(rng.uniform(50, 95, 4))
            joints[j] = JointModel(
                j, parents[i], f"{f}.{segs[i]}", centres[i], axis, y.copy(), _quality(rom)
            )
        ab = None
        if abduction:
            ab_axis = Rotation.from_rotvec(np.radians(12.0) * x).apply(-z)
            ab = JointModel(
                "mp_abduction",
                "hand",
                f"{f}.proximal",
                mp - 4.0 * x + 1.0 * z,
                ab_axis,
                ab_axis.copy(),
                _quality([18.0, 22.0]),
            )
        ends = [*centres[1:], tip]
        frames = {}
        for i, s in enumerate(segs):
            poses[f"{f}.{s}"] = (
                (centres[i] + ends[i]) / 2 + 8 * z,
                Rotation.random(random_state=seed * 10 + i + k).as_matrix(),
            )
            frames[s] = SegmentFrame(ends[i], np.column_stack([x, y, z]))
        out[f] = DigitModel(
            f,
            joints,
            tip,
            {
                s: float(v)
                for s, v in zip(
                    segs,
                    [*np.linalg.norm(np.diff(centres, axis=0), axis=1), lengths[2]],
                    strict=True,
                )
            },
            frames,
            {"mp": ab} if ab is not None else {},
        )
    return HandModel("SYN", "right", "mm", "synthetic", poses, out)


@functools.cache
def fitted_model() -> HandModel:
    return fit_session(subject("realistic", 3, ("index", "middle", "ring", "little")).session)


@functools.cache
def whole_hand_model() -> HandModel:
    """A fitted thumb (saddle CMC, two lines apart) and index on exact simulated data."""
    return fit_session(subject("exact", 3, ("thumb", "index")).session)


CASES = {
    "fitted": lambda: fitted_model(),
    "whole_hand": lambda: whole_hand_model(),
    "tilt30": lambda: synthetic_model(1, 30.0),
    "tilt30_abduction": lambda: synthetic_model(2, 30.0, abduction=True, fingers=("index",)),
}


@functools.cache
def case_model(name: str, tmp: str) -> HandModel:
    """The case's model after a JSON round trip (what the CLI exports)."""
    return load_model(save_model(CASES[name](), Path(tmp) / f"{name}.json"))


# --------------------------------------------------------------------------- reference FK


def _to_hand(model: HandModel, p: np.ndarray) -> np.ndarray:
    t0, r0 = model.reference_poses["hand"]
    return (p - t0) @ r0 / 1000.0


def reference_frames(model: HandModel, finger: str, variant: str, q: dict[str, float]) -> dict:
    """fingerfit FK of every joint frame and the tip, hand frame (m).

    Returns ``{joint kind: (origin (3,), axis (3,), child link rotation (3, 3))}`` and
    ``"tip": (3,)``. A joint's own rotation leaves its centre and axis fixed, so the
    chain through that joint (``depth = i + 1``) moves them correctly.
    """
    fm = model.fingers[finger]
    r0 = model.reference_poses["hand"][1]
    ang = {k: np.array([v]) for k, v in q.items()}
    out = {}
    for depth, j in enumerate(fm.joints, start=1):
        axes = fm.axes(j)
        for k, jm in enumerate(axes):
            # The frame after axis k of joint j: the joint's more distal axis held at 0.
            a_ang = {**ang, **{x.name: np.zeros(1) for x in axes[k + 1 :]}}
            c, axis = jm.center, jm.axis_for(variant)
            pts = np.stack([c, c + axis, *(c + r0[:, i] for i in range(3))])
            moved = np.stack([chain_points(fm, variant, a_ang, p, depth)[0] for p in pts])
            moved_h = _to_hand(model, moved) * 1000.0  # mm, hand frame
            out[jm.name] = (
                moved_h[0] / 1000.0,
                moved_h[1] - moved_h[0],
                (moved_h[2:] - moved_h[0]).T,
            )
    out["tip"] = _to_hand(model, chain_points(fm, variant, ang, fm.tip)[0])
    return out


def random_angles(model: HandModel, variant: str, rng: np.random.Generator, n: int) -> list[dict]:
    """``n`` joint-angle sets inside the exported limits, the first two at the limits."""
    joints = robot_hand(model, variant, MARGIN_DEG).joints
    lo = np.array([j.lower for j in joints])
    hi = np.array([j.upper for j in joints])
    samples = [lo, hi, *rng.uniform(lo, hi, (n - 2, lo.size))]
    return [{j.name: float(v) for j, v in zip(joints, s, strict=True)} for s in samples]


def _per_finger(q: dict[str, float], finger: str) -> dict[str, float]:
    return {k.split("_", 1)[1]: v for k, v in q.items() if k.split("_", 1)[0] == finger}


# --------------------------------------------------------------------------- loaders


class PinocchioLoader:
    def __init__(self, urdf: Path) -> None:
        self.model = pin.buildModelFromUrdf(str(urdf))
        self.data = self.model.createData()

    def names(self) -> list[str]:
        return list(self.model.names)[1:]

    def limits(self, name: str) -> tuple[float, float]:
        iq = self.model.joints[self.model.getJointId(name)].idx_q
        return self.model.lowerPositionLimit[iq], self.model.upperPositionLimit[iq]

    def set(self, q: dict[str, float]) -> None:
        qv = pin.neutral(self.model)
        for name, v in q.items():
            qv[self.model.joints[self.model.getJointId(name)].idx_q] = v
        pin.forwardKinematics(self.model, self.data, qv)
        pin.updateFramePlacements(self.model, self.data)
        pin.computeJointJacobians(self.model, self.data, qv)

    def joint(self, name: str):
        jid = self.model.getJointId(name)
        m = self.data.oMi[jid]
        jac = pin.getJointJacobian(
            self.model, self.data, jid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        )[:, self.model.joints[jid].idx_v]
        assert np.abs(jac[:3]).max() < 1e-12  # the axis passes through the joint origin
        return m.translation.copy(), jac[3:].copy(), m.rotation.copy()

    def tip(self, finger: str) -> np.ndarray:
        return self.data.oMf[self.model.getFrameId(f"{finger}_tip")].translation.copy()


class MujocoLoader:
    def __init__(self, path: Path, tip_is_site: bool) -> None:
        self.model = mujoco.MjModel.from_xml_path(str(path))
        self.data = mujoco.MjData(self.model)
        self.tip_is_site = tip_is_site

    def names(self) -> list[str]:
        return [self.model.joint(i).name for i in range(self.model.njnt)]

    def limits(self, name: str) -> tuple[float, float]:
        j = self.model.joint(name)
        assert j.limited[0] == 1
        return tuple(j.range)

    def set(self, q: dict[str, float]) -> None:
        self.data.qpos[:] = 0
        for name, v in q.items():
            self.data.qpos[self.model.joint(name).qposadr[0]] = v
        mujoco.mj_kinematics(self.model, self.data)

    def joint(self, name: str):
        j = self.model.joint(name)
        body = self.data.body(int(j.bodyid[0]))
        anchor = self.data.xanchor[j.id].copy()
        assert np.abs(anchor - body.xpos).max() < 1e-15  # joint at the body origin
        return anchor, self.data.xaxis[j.id].copy(), body.xmat.reshape(3, 3).copy()

    def tip(self, finger: str) -> np.ndarray:
        name = f"{finger}_tip"
        return (self.data.site(name) if self.tip_is_site else self.data.body(name)).xpos.copy()


@functools.cache
def exported(name: str, variant: str, tmp: str) -> dict[str, object]:
    """Write URDF and MJCF to disk and load them back (the XML round trip)."""
    model = case_model(name, tmp)
    d = Path(tmp)
    urdf = d / f"{name}_{variant}.urdf"
    mjcf = d / f"{name}_{variant}.xml"
    urdf.write_text(urdf_string(model, variant, MARGIN_DEG))
    mjcf.write_text(mjcf_string(model, variant, MARGIN_DEG))
    return {
        "pinocchio(urdf)": PinocchioLoader(urdf),
        "mujoco(urdf)": MujocoLoader(urdf, tip_is_site=False),
        "mujoco(mjcf)": MujocoLoader(mjcf, tip_is_site=True),
    }


@pytest.fixture(scope="module")
def tmp(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("robot"))


# --------------------------------------------------------------------------- tests


@pytest.mark.parametrize("variant", ["user_axis", "orthogonal"])
@pytest.mark.parametrize("case", list(CASES))
def test_loaders_match_fingerfit_fk(case: str, variant: str, tmp: str) -> None:
    model = case_model(case, tmp)
    loaders = exported(case, variant, tmp)
    rng = np.random.default_rng(7)
    worst = dict.fromkeys(loaders, 0.0)
    for q in random_angles(model, variant, rng, 25):
        for label, ld in loaders.items():
            ld.set(q)
            for f in model.fingers:
                ref = reference_frames(model, f, variant, _per_finger(q, f))
                err = np.linalg.norm(ld.tip(f) - ref.pop("tip"))
                assert err < POS_TOL_M, (label, f, "tip", err)
                worst[label] = max(worst[label], err)
                for kind, (origin, axis, rot) in ref.items():
                    p, a, r = ld.joint(f"{f}_{kind}")
                    err = np.linalg.norm(p - origin)
                    assert err < POS_TOL_M, (label, f, kind, err)
                    assert np.abs(a - axis).max() < DIR_TOL, (label, f, kind)
                    assert np.abs(r - rot).max() < DIR_TOL, (label, f, kind)
                    worst[label] = max(worst[label], err)
    print(
        f"\n{case}/{variant} max FK discrepancy (m): "
        + ", ".join(f"{k} {v:.2e}" for k, v in worst.items())
    )


@pytest.mark.parametrize("case", list(CASES))
def test_names_order_limits_axes(case: str, tmp: str) -> None:
    model = case_model(case, tmp)
    r0 = model.reference_poses["hand"][1]
    expected = []
    for f, fm in model.fingers.items():
        for jm in fm.chain():
            top = max(jm.quality.rom_deg) + MARGIN_DEG
            lim = (-top, top) if jm.name in SYMMETRIC else (-MARGIN_DEG, top)
            expected.append((f"{f}_{jm.name}", np.radians(lim), r0.T @ jm.axis))
    for label, ld in exported(case, "user_axis", tmp).items():
        names = [e[0] for e in expected]
        if label.startswith("pinocchio"):
            # Pinocchio visits the hand's branches in its own order (child link names):
            # same joints, each finger proximal to distal; map by name, never by index.
            assert sorted(ld.names()) == sorted(names), label
            for f in model.fingers:
                assert [n for n in ld.names() if n.startswith(f + "_")] == [
                    n for n in names if n.startswith(f + "_")
                ]
        else:
            assert ld.names() == names, label
        for name, lim, _ in expected:
            assert np.abs(np.array(ld.limits(name)) - lim).max() < 1e-12, (label, name)
        ld.set({})
        for name, _, axis in expected:  # at q = 0 the world axis is the fitted axis
            assert np.abs(ld.joint(name)[1] - axis).max() < 1e-12, (label, name)


def test_tilted_axes_are_really_exported(tmp: str) -> None:
    """The two variants differ by the fitted tilt: up to 30° in the synthetic model."""
    model = case_model("tilt30", tmp)
    lu = exported("tilt30", "user_axis", tmp)["mujoco(mjcf)"].model
    lo = exported("tilt30", "orthogonal", tmp)["mujoco(mjcf)"].model
    tilt = np.degrees(np.arccos(np.clip(np.sum(lu.jnt_axis * lo.jnt_axis, axis=1), -1, 1)))
    assert tilt.max() == pytest.approx(30.0, abs=1e-6)
    assert (tilt > 10).all()
    _, r0 = model.reference_poses["hand"]
    assert (
        np.abs(
            lo.joint("index_pip").axis - r0.T @ model.fingers["index"].joints["pip"].orthogonal_axis
        ).max()
        < 1e-12
    )


def test_mjcf_keeps_full_precision_and_radians(tmp: str) -> None:
    """MjSpec.to_xml rounds to 6 digits; the exported numbers must be exact."""
    model = case_model("fitted", tmp)
    hand = robot_hand(model, "user_axis", MARGIN_DEG)
    m = exported("fitted", "user_axis", tmp)["mujoco(mjcf)"].model
    for f in hand.fingers:
        for j, link in zip(f.joints, f.links, strict=True):
            assert np.array_equal(m.body(link.name).pos, j.origin)
            assert np.array_equal(m.joint(j.name).range, [j.lower, j.upper])
            assert m.body(link.name).mass[0] == pytest.approx(link.mass, rel=1e-12)
        assert np.array_equal(m.site(f.tip_name).pos, f.tip)
    xml = (Path(tmp) / "fitted_user_axis.xml").read_text()
    assert 'angle="radian"' in xml


def test_mujoco_keeps_static_frames_from_urdf(tmp: str) -> None:
    """Without the <mujoco> extension MuJoCo would fuse 'hand' and '<finger>_tip' away."""
    m = exported("fitted", "user_axis", tmp)["mujoco(urdf)"].model
    bodies = {m.body(i).name for i in range(m.nbody)}
    assert {"hand", "index_tip", "little_tip"} <= bodies
    text = (Path(tmp) / "fitted_user_axis.urdf").read_text()
    stripped = text[: text.index("<mujoco>")] + "</robot>\n"
    fused = mujoco.MjModel.from_xml_string(stripped)
    assert "index_tip" not in {fused.body(i).name for i in range(fused.nbody)}


def test_inertials_and_geometry(tmp: str) -> None:
    model = case_model("fitted", tmp)
    hand = robot_hand(model, "user_axis", MARGIN_DEG)
    # capsule inertial against MuJoCo's own computation from the geom (density 1100)
    link = next(lk for lk in hand.fingers[0].links if lk.capsule is not None)
    spec = mujoco.MjSpec()
    b = spec.worldbody.add_body(pos=[0, 0, 0])
    b.add_joint(type=mujoco.mjtJoint.mjJNT_FREE)
    b.add_geom(
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=np.concatenate(link.capsule).tolist(),
        size=[link.radius, 0, 0],
        density=1100.0,
    )
    mm = spec.compile()
    mass, com, inertia = capsule_inertial(*link.capsule, link.radius)
    assert mm.body_mass[1] == pytest.approx(mass, rel=1e-9)
    assert mm.body_ipos[1] == pytest.approx(com, abs=1e-12)
    assert np.sort(mm.body_inertia[1]) == pytest.approx(
        np.sort(np.linalg.eigvalsh(inertia)), rel=1e-9
    )
    # plausible finger masses (g) and URDF cylinders aligned with the bones in MuJoCo
    for f in hand.fingers:
        grams = 1000 * sum(lk.mass for lk in f.links)
        assert 5 < grams < 60, (f.name, grams)
    mu = exported("fitted", "user_axis", tmp)["mujoco(urdf)"]
    mu.set({})
    for g in range(mu.model.ngeom):
        if mu.model.geom_type[g] != mujoco.mjtGeom.mjGEOM_CYLINDER:
            continue
        body = mu.model.body(int(mu.model.geom_bodyid[g])).name
        link = next(lk for f in hand.fingers for lk in f.links if lk.name == body)
        bone = link.capsule[1] - link.capsule[0]
        z = mu.data.geom_xmat[g].reshape(3, 3)[:, 2]
        assert abs(abs(z @ bone) / np.linalg.norm(bone) - 1) < 1e-9, body
        assert mu.data.geom_xpos[g] == pytest.approx(mu.data.body(body).xpos + bone / 2, abs=1e-12)


@pytest.mark.parametrize("fmt", ["mjcf", "urdf"])
def test_mujoco_simulates_under_gravity(fmt: str, tmp: str) -> None:
    """Released at the reference posture, the fingers fall, stay in their limits and settle."""
    ld = exported("tilt30_abduction", "user_axis", tmp)[f"mujoco({fmt})"]
    m, d = ld.model, mujoco.MjData(ld.model)
    m.opt.gravity[:] = [0.0, 0.0, -9.81]
    qpos = []
    for _ in range(int(4.0 / m.opt.timestep)):
        mujoco.mj_step(m, d)
        qpos.append(d.qpos.copy())
    qpos = np.array(qpos)
    assert np.isfinite(qpos).all()
    lo, hi = m.jnt_range[:, 0], m.jnt_range[:, 1]
    assert (qpos > lo - 0.05).all() and (qpos < hi + 0.05).all()
    assert np.abs(qpos[-1]).max() > 0.05  # gravity moved something
    assert np.abs(d.qvel).max() < 0.05  # and it came to rest
    print(
        f"\n{fmt}: max |q| after 4 s {np.abs(qpos[-1]).max():.3f} rad, max |qdot| {np.abs(d.qvel).max():.2e} rad/s"
    )


def test_limits_without_recorded_range(tmp: str) -> None:
    """No recorded range of motion: anatomical defaults widened by the margin."""
    import dataclasses

    model = case_model("tilt30_abduction", tmp)
    fm = model.fingers["index"]
    empty = _quality([])
    fm = dataclasses.replace(
        fm,
        joints={k: dataclasses.replace(j, quality=empty) for k, j in fm.joints.items()},
        second_axes={"mp": dataclasses.replace(fm.second_axes["mp"], quality=empty)},
    )
    model = dataclasses.replace(model, fingers={"index": fm})
    got = {j.kind: (j.lower, j.upper) for j in robot_hand(model, margin_deg=5.0).joints}
    want = {"mp_abduction": (-35, 35), "mp": (-35, 95), "pip": (-15, 115), "dip": (-25, 95)}
    for k, lim in want.items():
        assert got[k] == pytest.approx(np.radians(lim), abs=1e-15), k
