"""Synthetic thumb CMC recordings with known saddle-joint truth (tests and bench/saddle.py).

A hand sensor and a thumb-metacarpal sensor are placed in tracker coordinates; the
metacarpal turns about the distal axis line and then about the proximal axis line
(``order``), through circumduction loops and opposition strokes with thumb-like ranges
(flexion about -20..+40 deg, ab/adduction about -10..+40 deg); the whole hand drifts
slowly through the tracker's field. Errors are the simulator's own
(:class:`fingerfit.simulate.sensors.TrackerErrors`: white noise and the smooth distortion
field at ``noise``; :func:`~fingerfit.simulate.sensors.mount` skin sliding at ``sta``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from fingerfit.kinematics import two_axis_angles
from fingerfit.simulate.sensors import TrackerErrors, mount, sensor_poses
from fingerfit.transforms import FloatArray, axis_angle_matrix, relative_pose, unit


@dataclass(frozen=True)
class SaddleCase:
    """One synthetic recording (parent = hand sensor frame at the reference posture).

    ``rotation``/``translation`` are the measured child-in-parent poses (n frames),
    ``reference_rotation`` the measured one at the reference posture; the rest is truth.
    """

    rotation: FloatArray
    translation: FloatArray
    reference_rotation: FloatArray
    groups: FloatArray
    order: str
    flexion_axis: FloatArray
    abduction_axis: FloatArray
    flexion_point: FloatArray  # nearest the other line
    abduction_point: FloatArray
    offset_mm: float  # signed along unit(flexion x abduction)
    flexion_angle: FloatArray  # (n,) rad, true
    abduction_angle: FloatArray
    bone: FloatArray  # metacarpal direction


def thumb_motion(
    rng: np.random.Generator, cycles: int = 10, per_cycle: int = 240
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Flexion and ab/adduction (rad, ``(n,)``) and the cycle of each frame.

    Each cycle: one circumduction loop (flexion 10 +- 30 deg, ab/adduction 15 +- 25 deg,
    radii varying by +-10 %) then opposition strokes to four fingertips and back.
    """
    flex, abd, grp = [], [], []
    half = per_cycle // 2
    for c in range(cycles):
        phi = np.linspace(0, 2 * np.pi, half, endpoint=False) + rng.uniform(0, 2 * np.pi)
        r1, r2 = rng.uniform(0.9, 1.1, 2)
        f1 = 10 + 30 * r1 * np.cos(phi)
        a1 = 15 + 25 * r2 * np.sin(phi)
        strokes = per_cycle - half
        u = np.linspace(0, 1, strokes // 4, endpoint=False)
        f2, a2 = [], []
        for _ in range(4):
            tf, ta = rng.uniform(15, 40), rng.uniform(15, 40)
            prof = np.sin(np.pi * u) ** 2
            f2.append(tf * prof + rng.normal(0, 2))
            a2.append(ta * prof ** rng.uniform(0.7, 1.4))
        f = np.concatenate([f1, *f2])
        a = np.concatenate([a1, *a2])
        flex.append(f)
        abd.append(a)
        grp.append(np.full(f.size, c))
    return np.radians(np.concatenate(flex)), np.radians(np.concatenate(abd)), np.concatenate(grp)


def _geometry(rng: np.random.Generator) -> dict:
    """Random thumb CMC geometry (tracker frame): bone, axes 60-80 deg apart, each 5-15 deg
    off perpendicular to the bone, lines 3-8 mm apart."""
    frame = Rotation.random(random_state=rng).as_matrix()
    bone, dorsal = frame[:, 0], frame[:, 2]
    u1 = frame[:, 1]
    t1, t2 = np.radians(rng.uniform(5, 15, 2)) * rng.choice([-1, 1], 2)
    turn = np.radians(rng.uniform(60, 80))
    u2 = np.cos(turn) * u1 + np.sin(turn) * dorsal
    flex = unit(np.cos(t1) * u1 + np.sin(t1) * bone)
    abd = unit(np.cos(t2) * u2 + np.sin(t2) * bone)
    origin = rng.uniform(-200, 200, 3) + np.array([0.0, 0.0, 300.0])
    c_flex = origin
    n = unit(np.cross(flex, abd))
    offset = rng.uniform(3, 8) * rng.choice([-1, 1])
    c_abd = c_flex + offset * n
    return dict(
        frame=frame, bone=bone, flex=flex, abd=abd, c_flex=c_flex, c_abd=c_abd, offset=offset
    )


def make_case(
    seed: int,
    *,
    order: str = "flexion_first",
    noise: float = 1.0,
    distortion: bool = True,
    sta: float = 0.0,
    flexion_deg: FloatArray | None = None,
    abduction_deg: FloatArray | None = None,
    groups: FloatArray | None = None,
) -> SaddleCase:
    """A synthetic recording: ``noise`` as the simulator's (1 = Liberty-like), ``sta`` the
    skin-sliding scale (0 rigid). Optional explicit angle series (deg) replace the motion."""
    rng = np.random.default_rng(seed)
    g = _geometry(rng)
    if flexion_deg is None:
        th_f, th_a, grp = thumb_motion(rng)
    else:
        th_f, th_a = np.radians(flexion_deg), np.radians(abduction_deg)
        grp = np.arange(th_f.size) * 10 // th_f.size if groups is None else groups
    n = th_f.size
    if order == "flexion_first":
        p, cp, alpha, d, cd, delta = g["flex"], g["c_flex"], th_f, g["abd"], g["c_abd"], th_a
    else:
        p, cp, alpha, d, cd, delta = g["abd"], g["c_abd"], th_a, g["flex"], g["c_flex"], th_f
    rp, rd = axis_angle_matrix(p, alpha), axis_angle_matrix(d, delta)
    r_seg = rp @ rd
    # x -> Rot_p (Rot_d (x - cd) + cd - cp) + cp
    t_seg = np.einsum("nij,j->ni", rp, cd - cp) - np.einsum("nij,j->ni", r_seg, cd) + cp
    # The whole hand drifts slowly (+-8 deg, +-30 mm) about a point near the wrist.
    s = np.linspace(0, 1, n)
    rv = np.radians(8) * np.stack(
        [np.sin(2 * np.pi * (s * k + rng.uniform())) for k in (1, 2, 3)], 1
    )
    r_hand = Rotation.from_rotvec(rv).as_matrix()
    pivot = g["c_flex"] - 40 * g["bone"]
    t_hand = 30 * np.stack([np.sin(2 * np.pi * (s * k + rng.uniform())) for k in (2, 1, 3)], 1)
    t_hand = t_hand + pivot - np.einsum("nij,j->ni", r_hand, pivot)
    frame = g["frame"]
    hand_m = mount(
        rng,
        "hand",
        pivot + 30 * frame[:, 1] + 15 * frame[:, 2],
        frame,
        offset_sd=np.zeros(3),
        sta=0.4 * sta,
    )
    meta_m = mount(
        rng,
        "thumb.metacarpal",
        g["c_flex"] + 20 * g["bone"] + 8 * frame[:, 2],
        frame,
        offset_sd=np.zeros(3),
        sta=sta,
    )
    zero = np.zeros(n)
    hp, hr = sensor_poses(hand_m, (r_hand, t_hand), (zero, zero))
    mp, mr = sensor_poses(
        meta_m,
        (r_hand @ r_seg, np.einsum("nij,nj->ni", r_hand, t_seg) + t_hand),
        (th_f, th_a),
    )
    tracker = TrackerErrors.sample(rng, noise, distortion)
    hp, hr = tracker.apply(rng, hp, hr)
    mp, mr = tracker.apply(rng, mp, mr)
    rot, trans = relative_pose(hr, hp, mr, mp)
    # Reference posture: a 1 s static recording at 60 Hz, averaged.
    k = 60
    rest = (np.broadcast_to(np.eye(3), (k, 3, 3)), np.zeros((k, 3)))
    sh = tracker.apply(rng, *sensor_poses(hand_m, rest, (np.zeros(k), np.zeros(k))))
    sm = tracker.apply(rng, *sensor_poses(meta_m, rest, (np.zeros(k), np.zeros(k))))
    r_ref_all, _ = relative_pose(sh[1], sh[0], sm[1], sm[0])
    r_ref = Rotation.from_matrix(r_ref_all).mean().as_matrix()
    # Truth in the hand sensor frame at the reference posture.
    h_rot, h_pos = hand_m.rotation, hand_m.position
    f, a = h_rot.T @ g["flex"], h_rot.T @ g["abd"]
    cf, ca = h_rot.T @ (g["c_flex"] - h_pos), h_rot.T @ (g["c_abd"] - h_pos)
    q_true = axis_angle_matrix(h_rot.T @ p, alpha) @ axis_angle_matrix(h_rot.T @ d, delta)
    if order == "flexion_first":
        b_, t_ = two_axis_angles(q_true, a, f)
        ta_f, ta_a = b_, t_
    else:
        b_, t_ = two_axis_angles(q_true, f, a)
        ta_f, ta_a = t_, b_
    return SaddleCase(
        rot,
        trans,
        r_ref,
        grp,
        order,
        f,
        a,
        cf,
        ca,
        float(g["offset"]),
        ta_f,
        ta_a,
        h_rot.T @ g["bone"],
    )
