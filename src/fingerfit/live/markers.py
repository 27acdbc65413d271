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
fit of the model's hand markers (:func:`~fingerfit.kinematics.markers.hand_poses`): with
it (:func:`~fingerfit.kinematics.markers.with_hand`) the
robot (``--retarget``), the fingertips in the hand's frame (``--tips-frame hand``) and
the view take a marker block as they take a 6-DOF one.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..digits import HAND_SENSOR
from ..errors import FingerfitError
from ..kinematics import Kinematics, compute_kinematics
from ..kinematics.markers import hand_poses, with_hand
from ..kinematics.results import FingerMotion
from ..model import HandModel
from ..session import Recording


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


def marker_solver() -> Callable[[HandModel, Recording], dict]:
    """The marker solver, :func:`fingerfit.estimate.markers.angles.marker_angles`.

    Imported on first use (about a second: SciPy's optimisers among its imports). A
    stream of a marker model calls this before its first frame, so that the import does
    not hold up the first frames streamed nor the lane that records them."""
    from ..estimate.markers.angles import marker_angles

    return marker_angles


def marker_kinematics(model: HandModel, recording: Recording) -> tuple[Kinematics, int]:
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
    kinematics : Kinematics
        Variant ``user_axis`` only; per digit its angles (rad) in the model's
        :meth:`~fingerfit.model.DigitModel.angle_names` order (flexion joints, then
        ``<joint>_abduction``) and its tip ``(n, 3)`` (mm, tracker frame); NaN in a frame
        the model could not place the digit.
    unconverged : int
        Solves that stopped unconverged, a digit in a frame each, summed over the digits
        (their angles the last iterate's;
        :attr:`~fingerfit.estimate.markers.angles.DigitAngles.unconverged`).
    """
    n = recording.n_frames
    motions: dict[str, FingerMotion] = {}
    solved = marker_solver()(model, recording) if n else {}
    unconverged = sum(a.unconverged for a in solved.values())
    for d, fm in model.fingers.items():
        names = fm.angle_names()
        if d in solved:
            a = solved[d]
            col = {k: i for i, k in enumerate(a.names)}
            motions[d] = FingerMotion({k: a.angles[:, col[k]] for k in names}, a.tip)
        else:
            motions[d] = FingerMotion({k: np.zeros(0) for k in names}, np.zeros((0, 3)))
    return Kinematics(recording.time, {"user_axis": motions}), unconverged


def kinematics_of(
    model: HandModel, recording: Recording, variants: tuple[str, ...]
) -> tuple[Kinematics, int]:
    """A block's kinematics and its marker solves that stopped unconverged:
    :func:`marker_kinematics` for a model fitted from markers (``variants`` then
    ``user_axis`` only), else :func:`~fingerfit.kinematics.compute_kinematics` (0)."""
    if is_marker_model(model):
        return marker_kinematics(model, recording)
    return compute_kinematics(model, recording, variants), 0


def check_marker_source(
    model: HandModel, recording_markers: set[str], where: str, what: str = "source"
) -> None:
    """Refuse a marker source (``what``: ``source`` of a stream, ``recording`` of
    ``view``/``retarget``) that lacks a marker of the model, in one line naming the
    marker and ``where``."""
    missing = [k for k in model_markers(model) if k not in recording_markers]
    if missing:
        raise FingerfitError(
            f"no marker {', '.join(missing)} of the model in the {what} (a marker {what} "
            "needs every marker the model was fitted with)",
            path=where,
        )


__all__ = [
    "check_marker_source",
    "hand_poses",
    "is_marker_model",
    "kinematics_of",
    "marker_kinematics",
    "marker_presence",
    "markers_of",
    "model_markers",
    "with_hand",
]
