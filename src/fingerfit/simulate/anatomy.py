"""Simulated finger anatomy and its exact forward kinematics (the ground truth).

Each finger is a chain hand -> proximal -> middle -> distal phalanx. At the
reference (stretched) posture every point is given in tracker coordinates; a
posture moves each segment by a product of exponentials: the MP
ab/adduction about ``b`` (fixed in the hand), then flexion about the tilted
axes ``a_mp``, ``a_pip``, ``a_dip``, each through a centre that migrates with
flexion (rolling contact: ``c(theta) = c + rho * theta * w``).

Hand anatomical frame: x distal, z dorsal, y = z x x (radial for a right
hand, ulnar for a left one). Positive flexion curls the finger palmar,
positive ab/adduction is radial deviation. Lengths mm, angles rad.

Literature defaults (``docs/simulator.md``): index bone lengths from X-ray
(proximal 39.8 +/- 4.9, middle 22.4 +/- 2.5, distal 15.8 +/- 2.3 mm, tip soft
tissue 3.8 mm), other fingers scaled by Buchholz 1992 ratios; mean axis
obliquity per finger and joint from the MyoHand model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..session import JOINTS
from ..transforms import FloatArray, axis_angle_matrix, unit

# Link lengths of the index finger (mm): X-ray bone lengths; the distal link
# runs from the DIP centre to the nail edge (bone + soft tissue).
INDEX_LENGTHS = np.array([39.8, 22.4, 15.8 + 3.8])
INDEX_LENGTH_SD = np.array([4.9, 2.5, 2.3])
# Buchholz 1992 link ratios (fraction of hand length) P1, P2, P3.
BUCHHOLZ = {
    "index": np.array([0.245, 0.143, 0.097]),
    "middle": np.array([0.266, 0.170, 0.108]),
    "ring": np.array([0.244, 0.165, 0.107]),
    "little": np.array([0.204, 0.117, 0.094]),
}
# Mean flexion-axis obliquity off perpendicular-to-the-bone (deg), MyoHand: MP, PIP, DIP.
MYOHAND_TILT_DEG = {
    "index": np.array([4.5, 1.2, 0.6]),
    "middle": np.array([3.7, 2.7, 6.0]),
    "ring": np.array([3.7, 4.4, 0.8]),
    "little": np.array([9.5, 10.0, 3.4]),
}
# MP centres in the hand frame (mm; y given for a right hand) and splay (deg about z).
MP_POSITION = {
    "index": np.array([-3.0, 22.0, 0.0]),
    "middle": np.array([0.0, 0.0, 0.0]),
    "ring": np.array([-5.0, -19.0, 0.0]),
    "little": np.array([-16.0, -36.0, -2.0]),
}
SPLAY_DEG = {"index": 5.0, "middle": 0.0, "ring": -4.0, "little": -10.0}
# Dorsal distance of the joint-midpoint landmark from the joint centre (mm): MP, PIP, DIP.
DORSAL_DEPTH = np.array([9.0, 6.5, 4.5])
NAIL_HEIGHT = 2.5  # nail edge above the distal link axis (mm)


@dataclass(frozen=True)
class FingerAnatomy:
    """True geometry of one finger at the reference posture (tracker coordinates, mm).

    Attributes
    ----------
    centre : ndarray, shape (3, 3)
        Joint centres MP, PIP, DIP (on the finger's sagittal plane).
    axis : ndarray, shape (3, 3)
        Unit flexion axes MP, PIP, DIP.
    abduction_point, abduction_axis : ndarray, shape (3,)
        A point on, and the unit direction of, the MP ab/adduction axis.
    rolling : ndarray, shape (3, 3)
        Centre migration per radian of flexion (mm/rad), per joint.
    tip : ndarray, shape (3,)
        Nail-edge fingertip point.
    landmarks : dict[str, ndarray]
        True dorsal joint midpoints ``mp``, ``pip``, ``dip`` and ``tip``.
    frame : ndarray, shape (3, 3)
        Columns x (distal), y, z (dorsal) of the finger's anatomical frame.
    order : tuple of str
        The two MP axes, proximal first: ``("mp_abduction", "mp")`` (this world: the
        ab/adduction is fixed in the hand and carries the flexion axis) or
        ``("mp", "mp_abduction")`` (flexion proximal, the ab/adduction axis turning with
        the flexion, as in MyoHand: :mod:`.myohand`).
    """

    name: str
    centre: FloatArray
    axis: FloatArray
    abduction_point: FloatArray
    abduction_axis: FloatArray
    rolling: FloatArray
    tip: FloatArray
    landmarks: dict[str, FloatArray]
    frame: FloatArray
    order: tuple[str, str] = ("mp_abduction", "mp")

    @property
    def lengths(self) -> FloatArray:
        """Link lengths MP-PIP, PIP-DIP, DIP-tip (mm)."""
        pts = np.vstack([self.centre, self.tip])
        return np.linalg.norm(np.diff(pts, axis=0), axis=1)


def _rot_z(deg: float) -> FloatArray:
    return axis_angle_matrix(np.array([0.0, 0.0, 1.0]), np.array([np.radians(deg)]))[0]


def sample_finger(
    rng: np.random.Generator,
    name: str,
    *,
    hand: str,
    hand_scale: float,
    hand_rotation: FloatArray,
    hand_origin: FloatArray,
    tilt_scale: float = 1.0,
    tilt_sd_deg: float = 4.0,
    rolling: bool = True,
    abduction: bool = True,
    mp_tilt_deg: float | None = None,
) -> FingerAnatomy:
    """Draw one finger's anatomy for one subject.

    Parameters
    ----------
    rng : numpy Generator
    name : str
        ``index``, ``middle``, ``ring`` or ``little``.
    hand : {"left", "right"}
    hand_scale : float
        Subject size factor (1 = average hand).
    hand_rotation : ndarray, shape (3, 3)
        Hand anatomical frame in tracker coordinates at the reference posture.
    hand_origin : ndarray, shape (3,)
        Middle-finger MP centre in tracker coordinates (mm).
    tilt_scale : float
        Multiplies the axis obliquities (0 gives axes perpendicular to the bones).
    tilt_sd_deg : float
        Between-subject SD of each axis obliquity (deg).
    rolling, abduction : bool
        Centre migration with flexion; a distinct MP ab/adduction axis.
    mp_tilt_deg : float, optional
        The MP axis obliquity about ``z`` (deg, positive: the axis's +y end turned
        distally) in place of the drawn one (drawn all the same, so the random stream and
        every other draw are unchanged).
    """
    side = 1.0 if hand == "right" else -1.0
    ratio = BUCHHOLZ[name] / BUCHHOLZ["index"]
    lengths = (
        INDEX_LENGTHS
        * ratio
        * hand_scale
        * (1 + rng.normal(0, INDEX_LENGTH_SD / INDEX_LENGTHS / 2))
    )
    mp_local = MP_POSITION[name] * np.array([1.0, side, 1.0]) * hand_scale + rng.normal(0, 1.0, 3)
    splay = _rot_z(side * SPLAY_DEG[name] + rng.normal(0, 2.0))
    frame_local = splay  # columns x, y, z of the finger in the hand frame
    frame = hand_rotation @ frame_local
    x, y, z = frame[:, 0], frame[:, 1], frame[:, 2]
    mp = hand_origin + hand_rotation @ mp_local
    centre = np.array([mp, mp + lengths[0] * x, mp + (lengths[0] + lengths[1]) * x])
    tip = centre[2] + lengths[2] * x + NAIL_HEIGHT * z

    # Flexion axes: y tilted off perpendicular (about z: gains a bone component)
    # and slightly dorsally (about x).
    alpha = np.radians(
        tilt_scale
        * (rng.choice([-1.0, 1.0]) * MYOHAND_TILT_DEG[name] + rng.normal(0, tilt_sd_deg, 3))
    )
    if mp_tilt_deg is not None:
        alpha[0] = np.radians(mp_tilt_deg)
    beta = np.radians(tilt_scale * rng.normal(0, 2.0, 3))
    axis = unit(
        np.cos(alpha)[:, None] * (np.cos(beta)[:, None] * y + np.sin(beta)[:, None] * z)
        + np.sin(alpha)[:, None] * x
    )
    # MP ab/adduction: roughly dorsal, oblique, 1-3 mm proximal to the flexion axis,
    # so the two MP axes neither intersect nor stand at right angles.
    if abduction:
        tilt = rng.normal(0, np.radians(8.0), 2)
        b = unit(z + tilt[0] * x + tilt[1] * y) * side
        b_point = mp - rng.uniform(1.0, 3.0) * x + rng.normal(0, 0.7) * y
    else:
        b, b_point = side * z, mp.copy()
    # Rolling contact: the centre moves distally and palmar as the joint flexes.
    if rolling:
        speed = rng.uniform(0.1, 1.0, 3)
        direction = unit(x[None, :] - rng.uniform(0.0, 0.6, (3, 1)) * z[None, :])
        roll = speed[:, None] * direction
    else:
        roll = np.zeros((3, 3))
    depth = DORSAL_DEPTH * hand_scale + rng.normal(0, 0.7, 3)
    landmarks = {j: centre[i] + depth[i] * z for i, j in enumerate(JOINTS)}
    landmarks["tip"] = tip.copy()
    return FingerAnatomy(name, centre, axis, b_point, b, roll, tip, landmarks, frame)


def joint_transform(
    centre: FloatArray, axis: FloatArray, angle: FloatArray, rolling: FloatArray | None = None
) -> tuple[FloatArray, FloatArray]:
    """Rigid motion of rotating by ``angle`` about a (possibly migrating) centre.

    Parameters
    ----------
    centre, axis : ndarray, shape (3,)
        Centre (mm) and unit axis at zero angle.
    angle : ndarray, shape (n,)
        Joint angle (rad).
    rolling : ndarray, shape (3,), optional
        Centre migration per radian (mm/rad).

    Returns
    -------
    R : ndarray, shape (n, 3, 3)
    t : ndarray, shape (n, 3)
        ``p' = R p + t`` in the reference-posture tracker frame.
    """
    r = axis_angle_matrix(axis, angle)
    c = np.broadcast_to(centre, (angle.shape[0], 3))
    if rolling is not None:
        c = c + angle[:, None] * rolling
    return r, c - np.einsum("nij,nj->ni", r, c)


def compose(
    a: tuple[FloatArray, FloatArray], b: tuple[FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """Per-frame composition ``a * b`` of rigid motions given as ``(R, t)``."""
    ra, ta = a
    rb, tb = b
    return ra @ rb, np.einsum("nij,nj->ni", ra, tb) + ta


def segment_motions(
    finger: FingerAnatomy,
    angles: dict[str, FloatArray],
    hand_motion: tuple[FloatArray, FloatArray],
) -> dict[str, tuple[FloatArray, FloatArray]]:
    """Motion of each segment relative to the reference posture, per frame.

    A product of exponentials about the reference-posture axes, the two MP axes in
    ``finger.order`` (proximal first), then PIP and DIP.

    Parameters
    ----------
    finger : FingerAnatomy
    angles : dict
        ``mp``, ``mp_abduction``, ``pip``, ``dip`` joint angles, each ``(n,)`` rad.
    hand_motion : (R (n, 3, 3), t (n, 3))
        Hand motion relative to its reference pose (tracker frame).

    Returns
    -------
    dict
        ``hand``, ``proximal``, ``middle``, ``distal`` -> ``(R, t)``, mapping a
        point at the reference posture to its position in each frame (mm).
    """
    ab = joint_transform(finger.abduction_point, finger.abduction_axis, angles["mp_abduction"])
    abduction_first = finger.order[0] == "mp_abduction"
    prox = compose(hand_motion, ab) if abduction_first else hand_motion
    out = {"hand": hand_motion}
    for i, (seg, j) in enumerate(zip(("proximal", "middle", "distal"), JOINTS, strict=True)):
        prox = compose(
            prox, joint_transform(finger.centre[i], finger.axis[i], angles[j], finger.rolling[i])
        )
        if i == 0 and not abduction_first:
            prox = compose(prox, ab)
        out[seg] = prox
    return out
