"""The geometry of a model fitted from skin markers over a recording of its markers.

A hand sensor gives a 6-DOF model the hand's pose in each frame; a marker model has the
rigid fit of its hand markers instead (:func:`hand_poses`, as the marker fit carries
markers back: :mod:`fingerfit.estimate.markers.observe`). With it a marker block reads as
a 6-DOF block (:func:`with_hand`: the robot's retargeting, the fingertips in the hand's
frame, the view), and the model's markers can be placed where the model puts them
(:func:`model_marker_positions`). Lengths mm, tracker coordinates
(``docs/conventions.md``).
"""

from __future__ import annotations

import numpy as np

from ..digits import DIGITS, HAND_SENSOR
from ..model import HandModel
from ..session import PoseSeries, Recording
from ..transforms import FloatArray
from .direct import carry_by_hand, chain_points
from .results import FingerMotion, Kinematics


def hand_poses(model: HandModel, recording: Recording) -> PoseSeries:
    """The hand's pose in each frame, as the hand sensor of a 6-DOF model gives it.

    Parameters
    ----------
    model : HandModel
        Fitted from markers: its hand markers' places at the reference posture and the
        hand's reference pose (:attr:`HandModel.reference_poses`, the technical frame of
        those markers).
    recording : Recording
        Marker positions ``(n, 3)`` mm, tracker frame, NaN where unseen.

    Returns
    -------
    PoseSeries
        Position ``(n, 3)`` mm and rotation ``(n, 3, 3)`` (hand frame -> tracker): the
        reference pose carried by the rigid fit of the hand markers
        (:func:`fingerfit.io.rigid.fit_cluster`, as the marker fit carries markers back);
        NaN where fewer than three hand markers were seen (or on one line).
    """
    from ..io.rigid import fit_cluster

    labels = [k for k, (s, *_) in model.markers.items() if s == HAND_SENSOR]
    shape = np.array([model.markers[k][1] for k in labels])
    fit = fit_cluster(np.stack([recording.markers[k] for k in labels], axis=1), shape)
    p0, r0 = model.reference_poses[HAND_SENSOR]
    return PoseSeries(fit.rotation @ p0 + fit.translation, fit.rotation @ r0)


def with_hand(
    model: HandModel, recording: Recording, kin: Kinematics
) -> tuple[Recording, Kinematics]:
    """A marker block as a 6-DOF model's block reads: the hand's pose in every frame, and
    each digit's pad beside its tip.

    What the robot (``--retarget``), the fingertips in the hand's frame (``--tips-frame
    hand``) and the view take of a marker model's frames: they read the hand's pose from
    the recording's hand sensor (:func:`hand_poses`) and the tips (and pads) from the
    kinematics, as they do of a 6-DOF model's.

    Parameters
    ----------
    model : HandModel
        Fitted from markers.
    recording : Recording
        The block's marker positions ``(n, 3)`` mm, tracker frame.
    kin : Kinematics
        Its :func:`marker_kinematics` (``user_axis``).

    Returns
    -------
    recording : Recording
        ``recording`` with the pose series ``hand`` (:func:`hand_poses`).
    kinematics : Kinematics
        ``user_axis``: the same angles (rad) and tips (mm, tracker frame); for a digit
        with a pad point, its pad ``(n, 3)`` (mm, tracker frame): the tip plus the
        pad's offset from it as the model's chain turns it at the solved angles,
        carried by the hand's rotation. NaN where the angles or the hand's pose are.

    Notes
    -----
    The tips are those of ``fingerfit angles`` (each digit's adjustment corrects the
    hand's frame with its own markers), the hand's pose the plain rigid fit of its
    markers. The digits as the chain puts them in each digit's corrected frame (the
    chain's tips at the solved angles) lie farther from the truth: on simulated
    subjects (index finger, Todorov's layout, 0.3 mm noise, skin sliding; 1000 frames),
    the tip in the hand's frame is 2.2 mm (median) from the true tip in the true hand's
    frame this way, 3.6 mm as the chain's tip (MyoHand world); 8.9 and 9.0 mm in the
    realistic world, whose tip error is the fit's.
    """
    hand = hand_poses(model, recording)
    r0 = model.reference_poses[HAND_SENSOR][1]
    turn = hand.rotation @ r0.T  # reference posture -> tracker, each frame
    motions = {}
    for d, m in kin.motions["user_axis"].items():
        fm = model.fingers[d]
        pad = None
        if fm.pad is not None:
            offset = chain_points(fm, "user_axis", m.angles, fm.pad) - chain_points(
                fm, "user_axis", m.angles, fm.tip
            )
            pad = m.tip + np.einsum("nij,nj->ni", turn, offset)
        motions[d] = FingerMotion(m.angles, m.tip, pad)
    poses = {**recording.poses, HAND_SENSOR: hand}
    out = Recording(recording.name, recording.time, poses, recording.notes, recording.markers)
    return out, Kinematics(kin.time, {"user_axis": motions})


def model_marker_positions(
    model: HandModel, hand: PoseSeries, kin: Kinematics
) -> tuple[list[str], FloatArray]:
    """Where the model puts each of its markers in each frame.

    Parameters
    ----------
    model : HandModel
        Fitted from markers: each marker's segment, place at the reference posture and
        slide (:attr:`HandModel.markers`).
    hand : PoseSeries
        The hand's pose in each frame (:func:`hand_poses`; mm, tracker frame).
    kin : Kinematics
        The angles of the same ``n`` frames (``user_axis``, rad).

    Returns
    -------
    labels : list of str
        The model's markers, in its order.
    positions : ndarray, shape (n, M, 3)
        mm, tracker frame: each marker's place plus its slide times the angle of its
        segment's proximal flexion joint, moved by the digit's chain up to its segment
        and carried by the hand's pose (the hand's markers by the pose alone). NaN where
        the angles or the pose are.
    """
    n = hand.n_frames
    labels = list(model.markers)
    local = np.empty((n, len(labels), 3))
    motions = kin.motions["user_axis"]
    for i, (segment, place, slide) in enumerate(model.markers.values()):
        digit, _, name = segment.partition(".")
        if segment == HAND_SENSOR or digit not in motions:
            local[:, i] = place
            continue
        fm, angles = model.fingers[digit], motions[digit].angles
        depth = DIGITS[digit].segments.index(name) + 1
        theta = angles[DIGITS[digit].joints[depth - 1]]
        point = place + np.multiply.outer(theta, slide)
        local[:, i] = chain_points(fm, "user_axis", angles, point, depth)
    flat = local.reshape(n * len(labels), 3) if labels else np.zeros((0, 3))
    rot = np.repeat(hand.rotation, len(labels), axis=0)
    pos = np.repeat(hand.position, len(labels), axis=0)
    return labels, carry_by_hand(model, rot, pos, flat).reshape(n, len(labels), 3)
