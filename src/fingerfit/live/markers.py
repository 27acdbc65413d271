"""Streaming with a model fitted from skin markers (``docs/markers.md``).

A source of marker positions (a TRC/TSV/C3D replayed, an LSL ``MoCap`` stream of
markers) hands over blocks whose :attr:`~fingerfit.session.Recording.markers` hold each
marker's positions (mm, tracker frame). Each block's angles and fingertips are those of
``fingerfit angles MODEL X.trc``: :func:`fingerfit.estimate.markers.angles.marker_angles`,
the bundle adjustment's inner step with the model held, solved for all the block's frames
at once (its frames are independent blocks of one sparse system: no loop over frames).
The result is a :class:`~fingerfit.kinematics.Kinematics` with the channel names of a
6-DOF model, so the outputs (LSL, ROS 2, rosbag2, ``--record``) take it unchanged.

What a hand sensor gives a 6-DOF model, the hand's pose in each frame, is here the rigid
fit of the model's hand markers (:func:`hand_poses`): with it (:func:`with_hand`) the
robot (``--retarget``), the fingertips in the hand's frame (``--tips-frame hand``) and
the view take a marker block as they take a 6-DOF one.
"""

from __future__ import annotations

import numpy as np

from ..digits import HAND_SENSOR
from ..errors import FingerfitError
from ..kinematics import Kinematics, chain_points, compute_kinematics
from ..kinematics.results import FingerMotion
from ..model import HandModel
from ..session import PoseSeries, Recording


def is_marker_model(model: HandModel) -> bool:
    """Whether ``model`` was fitted from markers (it then streams marker sources only)."""
    return bool(model.markers)


def model_markers(model: HandModel) -> list[str]:
    """The model's marker labels: the hand's first, then each digit's, in the model's
    order."""
    hand = markers_of(model, HAND_SENSOR)
    return hand + [k for k in model.markers if k not in hand]


def markers_of(model: HandModel, digit: str) -> list[str]:
    """The labels of ``digit``'s markers (on its segments ``<digit>.<segment>``; the
    hand's with ``digit`` ``hand``)."""
    return [k for k, (s, *_) in model.markers.items() if s.split(".")[0] == digit]


def marker_presence(recording: Recording, labels: list[str]) -> np.ndarray:
    """Whether each marker of ``labels`` was seen in each frame, ``(n, M)`` bool (a
    marker the recording lacks: in no frame)."""
    n = recording.n_frames
    out = np.zeros((n, len(labels)), dtype=bool)
    for i, k in enumerate(labels):
        x = recording.markers.get(k)
        if x is not None:
            out[:, i] = np.isfinite(x).all(axis=1)
    return out


def marker_kinematics(model: HandModel, recording: Recording) -> Kinematics:
    """Angles and fingertips of a block of marker frames, as ``fingerfit angles`` gives
    them for a marker recording.

    Parameters
    ----------
    model : HandModel
        Fitted from markers.
    recording : Recording
        Marker positions ``(n, 3)`` mm, tracker frame, NaN where unseen; every marker of
        the model present as a key.

    Returns
    -------
    Kinematics
        Variant ``user_axis`` only; per digit its angles (rad) in the model's
        :meth:`~fingerfit.model.DigitModel.angle_names` order (flexion joints, then
        ``<joint>_abduction``) and its tip ``(n, 3)`` (mm, tracker frame); NaN in a frame
        the model could not place the digit.
    """
    from ..estimate.markers.angles import marker_angles

    n = recording.n_frames
    motions: dict[str, FingerMotion] = {}
    solved = marker_angles(model, recording) if n else {}
    for d, fm in model.fingers.items():
        names = fm.angle_names()
        if d in solved:
            a = solved[d]
            col = {k: i for i, k in enumerate(a.names)}
            motions[d] = FingerMotion({k: a.angles[:, col[k]] for k in names}, a.tip)
        else:
            motions[d] = FingerMotion({k: np.zeros(0) for k in names}, np.zeros((0, 3)))
    return Kinematics(recording.time, {"user_axis": motions})


def kinematics_of(model: HandModel, recording: Recording, variants: tuple[str, ...]) -> Kinematics:
    """A block's kinematics: :func:`marker_kinematics` for a model fitted from markers
    (``variants`` then ``user_axis`` only), else
    :func:`~fingerfit.kinematics.compute_kinematics`."""
    if is_marker_model(model):
        return marker_kinematics(model, recording)
    return compute_kinematics(model, recording, variants)


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

    labels = markers_of(model, HAND_SENSOR)
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


def check_marker_source(model: HandModel, recording_markers: set[str], where: str) -> None:
    """Refuse a marker source that lacks a marker of the model (one line naming it and
    the source)."""
    missing = [k for k in model_markers(model) if k not in recording_markers]
    if missing:
        raise FingerfitError(
            f"no marker {', '.join(missing)} of the model in the source (a marker stream "
            "needs every marker the model was fitted with)",
            path=where,
        )
