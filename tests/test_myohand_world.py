"""The MyoHand world (``fingerfit simulate --world myohand``) against MuJoCo itself.

MuJoCo is the reference: the subject's perturbations (scale, link lengths, axes) are
applied a second time, independently, by editing the MuJoCo model (body and site
positions, joint axes), and MuJoCo's own forward kinematics of that model must equal
the world's product of exponentials and its written truth.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.io import load_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.session import JOINTS, SEGMENTS
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.simulate import myohand as mh
from fingerfit.simulate.anatomy import compose, joint_transform, segment_motions
from fingerfit.simulate.study import relative_truth_in_parent, truth_document
from fingerfit.simulate.thumb import thumb_segment_motions
from fingerfit.simulate.truthmodel import truth_model
from fingerfit.transforms import (
    angle_between_axes,
    distance_point_to_line,
    matrix_from_quat_wxyz,
)

pytest.importorskip("myo_sim")
mujoco = pytest.importorskip("mujoco")

FINGERS = ("index", "middle", "ring", "little")
KEYS = ("mp", "mp_abduction", "pip", "dip")
THUMB_SEGMENTS = ("metacarpal", "proximal", "distal")


@pytest.fixture(scope="module")
def subject():
    """A whole-finger MyoHand subject with every error source (4 short grasp cycles)."""
    config = SimConfig(fingers=FINGERS, hand="right", world="myohand", cycles=4)
    return simulate_subject(config, 11)


@pytest.fixture(scope="module")
def thumb_subject():
    """MyoHand's thumb with the four fingers, every error source (2 grasp cycles)."""
    config = SimConfig(
        fingers=("thumb", *FINGERS), hand="right", world="myohand", cycles=2, targets=False
    )
    return simulate_subject(config, 7)


def edited_model(sim):
    """MyoHand with the subject's scale, link factors and axis rotations written into the
    MuJoCo model itself; returns (model, data at zero posture)."""
    model = mujoco.MjModel.from_xml_string(mh.model_xml())
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    p = sim.truth.myohand
    capitate = model.body("capitate_r").id
    for b in range(model.nbody):
        a = b
        while a not in (0, capitate):
            a = model.body_parentid[a]
        if a == capitate and b != capitate:
            model.body_pos[b] *= p.scale
    chains = {f: (mh.JOINT_NAMES[f], mh.SEGMENT_BODIES[f], mh.TIP_SITES[f]) for f in FINGERS}
    chains["thumb"] = (mh.THUMB_JOINT_NAMES, mh.THUMB_BODIES, mh.THUMB_TIP_SITE)
    for f, (joints, bodies, site) in chains.items():
        if f not in p.length_factor:
            continue
        k = p.length_factor[f]
        _, mid, dist = bodies
        model.body_pos[model.body(mid).id] *= k[0]
        model.body_pos[model.body(dist).id] *= k[1]
        model.site_pos[model.site(site).id] *= p.scale * k[2]
        for name, rv in zip(joints, p.axis_rotation[f], strict=True):
            j = mh.joint_id(model, name)
            r = data.xmat[model.jnt_bodyid[j]].reshape(3, 3)
            turn = _rotvec_matrix(rv)
            model.jnt_axis[j] = r.T @ turn @ r @ model.jnt_axis[j]
    mujoco.mj_kinematics(model, data)
    return model, data


def _rotvec_matrix(rv):
    th = np.linalg.norm(rv)
    k = np.array([[0, -rv[2], rv[1]], [rv[2], 0, -rv[0]], [-rv[1], rv[0], 0]]) / th
    return np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k


def to_tracker(sim, model, data0):
    """MuJoCo world (m) -> tracker (mm) of the subject: the placement rotation, the scaled
    middle MCP anchor at the hand origin."""
    origin = 1000.0 * data0.xanchor[mh.joint_id(model, "mcp3_flexion")].copy()
    place = sim.truth.myohand.placement
    hand_origin = sim.truth.fingers["middle"].centre[0]
    return lambda p: (1000.0 * np.asarray(p) - origin) @ place.T + hand_origin


def _rotation_angle(r):
    """Rotation angle (rad) of ``r`` from ``|R - I|_F = 2 sqrt(2) sin(angle / 2)``: accurate
    near 0, unlike arccos of the trace (which cannot resolve below ~1e-8 rad)."""
    return 2 * np.arcsin(np.linalg.norm(r - np.eye(3)) / (2 * np.sqrt(2)))


def test_product_of_exponentials_equals_mujoco(subject) -> None:
    """(a) Body poses of every phalanx at random postures within MyoHand's joint ranges:
    the world's PoE (zero-posture anchors and axes, flexion before ab/adduction) vs
    MuJoCo's mj_kinematics on the independently edited model."""
    model, data = edited_model(subject)
    point = to_tracker(subject, model, data)
    place = subject.truth.myohand.placement
    ref = mh.reference_geometry(model)
    body0 = {
        f: [(point(data.body(b).xpos), place @ data.body(b).xmat.reshape(3, 3)) for b in bodies]
        for f, bodies in mh.SEGMENT_BODIES.items()
    }
    rng = np.random.default_rng(5)
    n = 40
    angles = {}
    for f in FINGERS:
        ids = [mh.joint_id(model, j) for j in mh.JOINT_NAMES[f]]
        lo, hi = model.jnt_range[ids].T
        q = rng.uniform(lo, hi, (n, 4))
        angles[f] = {k: ref.fingers[f].sign[i] * q[:, i] for i, k in enumerate(KEYS)}
    eye = (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))
    worst_mm = worst_rad = 0.0
    poe = {f: segment_motions(subject.truth.fingers[f], angles[f], eye) for f in FINGERS}
    for k in range(n):
        data.qpos[:] = mh.mujoco_qpos(
            model, ref, {f: {j: angles[f][j][k] for j in KEYS} for f in FINGERS}
        )
        mujoco.mj_kinematics(model, data)
        for f in FINGERS:
            for s, b in enumerate(mh.SEGMENT_BODIES[f]):
                r, t = poe[f][SEGMENTS[s]]
                p0, r0 = body0[f][s]
                pos = point(data.body(b).xpos)
                rot = place @ data.body(b).xmat.reshape(3, 3)
                worst_mm = max(worst_mm, np.linalg.norm(r[k] @ p0 + t[k] - pos))
                # Rotation angle from |R - I|_F = 2 sqrt(2) sin(angle / 2): accurate near 0,
                # unlike arccos of the trace (which cannot resolve below ~1e-8 rad).
                d = np.linalg.norm((r[k] @ r0).T @ rot - np.eye(3))
                worst_rad = max(worst_rad, 2 * np.arcsin(d / (2 * np.sqrt(2))))
    assert worst_mm < 1e-9 and worst_rad < 1e-9, (worst_mm, worst_rad)
    # The MP order matters: ab/adduction first would not reproduce MuJoCo.
    f, k = "index", int(np.argmax(np.abs(angles["index"]["mp_abduction"])))
    anat = subject.truth.fingers[f]
    a = {j: angles[f][j][k : k + 1] for j in KEYS}
    wrong = compose(
        joint_transform(anat.abduction_point, anat.abduction_axis, a["mp_abduction"]),
        joint_transform(anat.centre[0], anat.axis[0], a["mp"]),
    )
    right = poe[f]["proximal"]
    assert (
        np.linalg.norm(wrong[1][0] - right[1][k]) + np.linalg.norm(wrong[0][0] - right[0][k]) > 1e-3
    )


def _off_in_parent(doc: dict, jd: dict, anchor: np.ndarray, axis: np.ndarray) -> float:
    """How far a truth.json joint (``center_in_parent``, ``axis_in_parent``) is from
    MuJoCo's anchor (mm) and axis, both carried into its parent sensor's frame."""
    s = doc["sensors"][jd["parent_sensor"]]
    pr = matrix_from_quat_wxyz(np.array(s["quat_wxyz"])[None])[0]
    pp = np.array(s["position"])
    return max(
        float(np.linalg.norm(pr.T @ (anchor - pp) - jd["center_in_parent"])),
        float(np.linalg.norm(pr.T @ axis - jd["axis_in_parent"])),
    )


def test_written_truth_equals_mujoco(subject, tmp_path) -> None:
    """(b) truth.json (centres and axes in the true parent sensor frames, the MP
    ab/adduction line, tips) equals MuJoCo's anchors/axes of the edited model."""
    write_subject(subject, tmp_path / "S")
    doc = json.loads((tmp_path / "S" / "truth.json").read_text())
    model, data = edited_model(subject)
    point = to_tracker(subject, model, data)
    place = subject.truth.myohand.placement
    ref = mh.reference_geometry()
    assert doc["config"]["world"] == "myohand"
    worst = 0.0
    for f in FINGERS:
        fd = doc["fingers"][f]
        assert fd["axis_order"] == {"mp": ["mp", "mp_abduction"]}
        ids = [mh.joint_id(model, j) for j in mh.JOINT_NAMES[f]]
        anchor = point(data.xanchor[ids])
        axis = ref.fingers[f].sign[:, None] * data.xaxis[ids] @ place.T
        for i, j in zip((0, 2, 3), JOINTS, strict=True):
            worst = max(worst, _off_in_parent(doc, fd["joints"][j], anchor[i], axis[i]))
        ab = fd["mp_abduction"]
        worst = max(
            worst,
            np.linalg.norm(anchor[1] - ab["point"]),
            np.linalg.norm(axis[1] - ab["axis"]),
            np.linalg.norm(point(data.site(mh.TIP_SITES[f]).xpos) - fd["tip"]),
        )
    assert worst < 1e-9, worst


def test_exact_myohand_session_fits(tmp_path) -> None:
    """(c) A written exact MyoHand session loads and fits: the PIP/DIP (and the hinge MP)
    axes and centres against the truth, in the parent sensor frames."""
    config = SimConfig.exact(fingers=("index",), hand="right", world="myohand", cycles=6)
    sim = simulate_subject(config, 3)
    session = load_session(write_subject(sim, tmp_path / "S"))
    model = fit_session(session, FitOptions())
    for j in JOINTS:
        c, a = model.in_parent("index", j)
        ct, at = relative_truth_in_parent(sim, "index", j)
        deg = np.degrees(angle_between_axes(a, at))
        mm = distance_point_to_line(c, ct, at)
        assert deg < 1e-3 and mm < 1e-3, (j, deg, mm)
    # The fitted chain carries MyoHand's tip site through the free-motion recording.
    rec = session.test[0]
    kin = compute_kinematics(model, rec, variants=("user_axis",), fingers=["index"])
    err = np.linalg.norm(
        kin.motions["user_axis"]["index"].tip - sim.truth.frames[rec.name]["tip"]["index"], axis=1
    )
    assert err.max() < 1e-3, err.max()


def test_thumb_product_of_exponentials_equals_mujoco(thumb_subject) -> None:
    """(a) The thumb's metacarpal, proximal and distal bodies and its tip site at random
    postures within MyoHand's thumb joint ranges: the world's PoE (ThumbAnatomy, CMC
    flexion before ab/adduction, hinge MCP) vs MuJoCo's mj_kinematics on the edited model;
    the fingers of the same subject too."""
    sim = thumb_subject
    model, data = edited_model(sim)
    point = to_tracker(sim, model, data)
    place = sim.truth.myohand.placement
    ref = mh.reference_geometry(model)
    th = sim.truth.thumb
    assert not th.mcp_abduction
    body0 = [
        (point(data.body(b).xpos), place @ data.body(b).xmat.reshape(3, 3)) for b in mh.THUMB_BODIES
    ]
    n = 40
    rng = np.random.default_rng(8)
    ids = [mh.joint_id(model, j) for j in mh.THUMB_JOINT_NAMES]
    lo, hi = model.jnt_range[ids].T
    q = rng.uniform(lo, hi, (n, 4))
    angles = {k: ref.thumb.sign[i] * q[:, i] for i, k in enumerate(mh.THUMB_KEYS)}
    angles["mcp_abduction"] = np.zeros(n)
    eye = (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))
    poe = thumb_segment_motions(th, angles, eye)
    f_ang = {f: {k: rng.uniform(0.0, 0.5, n) for k in KEYS} for f in FINGERS}
    f_poe = {f: segment_motions(sim.truth.fingers[f], f_ang[f], eye) for f in FINGERS}
    worst_mm = worst_rad = worst_tip = worst_finger = 0.0
    for k in range(n):
        posture = {f: {j: f_ang[f][j][k] for j in KEYS} for f in FINGERS}
        posture["thumb"] = {j: angles[j][k] for j in angles}
        data.qpos[:] = mh.mujoco_qpos(model, ref, posture)
        mujoco.mj_kinematics(model, data)
        for s, b in enumerate(mh.THUMB_BODIES):
            r, t = poe[THUMB_SEGMENTS[s]]
            p0, r0 = body0[s]
            rot = place @ data.body(b).xmat.reshape(3, 3)
            worst_mm = max(worst_mm, np.linalg.norm(r[k] @ p0 + t[k] - point(data.body(b).xpos)))
            worst_rad = max(worst_rad, _rotation_angle((r[k] @ r0).T @ rot))
        r, t = poe["distal"]
        tip = point(data.site(mh.THUMB_TIP_SITE).xpos)
        worst_tip = max(worst_tip, np.linalg.norm(r[k] @ th.tip + t[k] - tip))
        for f in FINGERS:
            r, t = f_poe[f]["distal"]
            tip = point(data.site(mh.TIP_SITES[f]).xpos)
            worst_finger = max(
                worst_finger, np.linalg.norm(r[k] @ sim.truth.fingers[f].tip + t[k] - tip)
            )
    assert max(worst_mm, worst_tip, worst_finger) < 1e-9 and worst_rad < 1e-9, (
        worst_mm,
        worst_rad,
        worst_tip,
        worst_finger,
    )
    # The CMC order matters: ab/adduction first would not reproduce MuJoCo.
    k = int(np.argmax(np.abs(angles["cmc"] * angles["cmc_abduction"])))
    wrong = compose(
        joint_transform(
            th.axis_point["cmc_abduction"],
            th.axis["cmc_abduction"],
            angles["cmc_abduction"][k : k + 1],
        ),
        joint_transform(th.axis_point["cmc"], th.axis["cmc"], angles["cmc"][k : k + 1]),
    )
    right = poe["metacarpal"]
    assert np.linalg.norm(wrong[0][0] - right[0][k]) > 1e-3


def test_thumb_truth_equals_mujoco(thumb_subject, tmp_path) -> None:
    """(b) truth.json's thumb (centres and axes in the true parent sensor frames, tip, no
    MCP ab/adduction line) equals MuJoCo's anchors and axes of the edited model; the pad
    events touch exactly."""
    sim = thumb_subject
    write_subject(sim, tmp_path / "S")
    doc = json.loads((tmp_path / "S" / "truth.json").read_text())
    model, data = edited_model(sim)
    point = to_tracker(sim, model, data)
    place = sim.truth.myohand.placement
    ref = mh.reference_geometry()
    td = doc["fingers"]["thumb"]
    assert set(td["joints"]) == {"cmc", "cmc_abduction", "mcp", "ip"}
    assert td["axis_order"] == {"cmc": ["cmc", "cmc_abduction"]}
    assert td["axis_offset_mm"]["cmc"] < 1e-9  # MyoHand's CMC lines meet
    ids = [mh.joint_id(model, j) for j in mh.THUMB_JOINT_NAMES]
    anchor = point(data.xanchor[ids])
    axis = ref.thumb.sign[:, None] * data.xaxis[ids] @ place.T
    worst = np.linalg.norm(point(data.site(mh.THUMB_TIP_SITE).xpos) - td["tip"])
    for i, j in enumerate(mh.THUMB_KEYS):
        worst = max(worst, _off_in_parent(doc, td["joints"][j], anchor[i], axis[i]))
    assert worst < 1e-9, worst
    assert set(doc["myohand"]["length_factor"]) == {"thumb", *FINGERS}
    # Every pad-to-pad touch (opposition to each finger, tip pinches) holds its gap.
    pads = [c for c in doc["contacts"] if c["in_events_csv"]]
    assert len(pads) == 7
    for c in pads:
        assert abs(c["distance_min_mm"] - c["gap_mm"]) < 1e-9
        assert abs(c["distance_max_mm"] - c["gap_mm"]) < 1e-9
    # The thumb's MCP never ab/adducts.
    for frames in sim.truth.frames.values():
        assert not np.any(frames["angles"]["thumb"]["mcp_abduction"])


def test_exact_thumb_session_fits_and_truth_model_is_exact(tmp_path) -> None:
    """(c) An exact MyoHand thumb + index session: the true model drives the thumb exactly
    (angles and tip), and the written session fits: the thumb's axes (a hinge MCP) and
    centres equal the truth in the parent sensor frames."""
    config = SimConfig.exact(
        fingers=("thumb", "index"), hand="right", world="myohand", cycles=4, targets=False
    )
    sim = simulate_subject(config, 5)
    model = truth_model(sim)
    assert set(model.fingers["thumb"].second_axes) == {"cmc"}
    for name in ("thumb_circumduction.csv", "pinch.csv", "test.csv"):
        kin = compute_kinematics(model, sim.session.recording(name))
        fr = sim.truth.frames[name]
        motion = kin.motions["user_axis"]["thumb"]
        for k, v in motion.angles.items():
            assert np.max(np.abs(np.degrees(v - fr["angles"]["thumb"][k]))) < 1e-6, (name, k)
        assert np.max(np.linalg.norm(motion.tip - fr["tip"]["thumb"], axis=1)) < 1e-6
    session = load_session(write_subject(sim, tmp_path / "S"))
    fitted = fit_session(session, FitOptions())
    assert [a.name for a in fitted.fingers["thumb"].chain()] == [
        "cmc",
        "cmc_abduction",
        "mcp",
        "ip",
    ]
    for j in ("cmc", "cmc_abduction", "mcp", "ip"):
        c, a = fitted.in_parent("thumb", j)
        ct, at = relative_truth_in_parent(sim, "thumb", j)
        deg, mm = np.degrees(angle_between_axes(a, at)), distance_point_to_line(c, ct, at)
        assert deg < 1e-6 and mm < 1e-6, (j, deg, mm)


def test_default_world_unchanged() -> None:
    """(d) The default world: same streams and truth with the new field, default order,
    no MyoHand keys in truth.json, segment motions as ab/adduction-first composition."""
    a = simulate_subject(SimConfig(cycles=2), 4)
    b = simulate_subject(SimConfig(cycles=2, world="default"), 4)
    assert truth_document(a) == truth_document(b)
    doc = truth_document(a)
    assert "world" not in doc["config"] and "myohand" not in doc
    assert "axis_order" not in doc["fingers"]["index"]
    anat = a.truth.fingers["index"]
    assert anat.order == ("mp_abduction", "mp")
    frames = a.truth.frames["grasp.csv"]
    ang = frames["angles"]["index"]
    n = ang["mp"].size
    eye = (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))
    seg = segment_motions(anat, ang, eye)
    prox = compose(
        joint_transform(anat.abduction_point, anat.abduction_axis, ang["mp_abduction"]),
        joint_transform(anat.centre[0], anat.axis[0], ang["mp"], anat.rolling[0]),
    )
    assert np.array_equal(seg["proximal"][0], prox[0])
    assert np.array_equal(seg["proximal"][1], prox[1])


def test_refusals(monkeypatch) -> None:
    """A left hand, an unknown world and a missing myo-sim: one line each."""
    with pytest.raises(FingerfitError, match=r"--hand.*right hand"):
        simulate_subject(SimConfig(world="myohand"), 0)
    with pytest.raises(FingerfitError, match=r"--world.*default, myohand"):
        SimConfig(world="mano")
    monkeypatch.setitem(__import__("sys").modules, "myo_sim", None)
    with pytest.raises(FingerfitError, match=r"pip install fingerfit\[myohand\]"):
        simulate_subject(SimConfig(world="myohand", hand="right"), 0)
