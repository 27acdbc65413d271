"""The view of a live stream, fed block by block from the data lane (``stream --view``)."""

from __future__ import annotations

import collections
import contextlib
from pathlib import Path

import numpy as np

from ..kinematics import Kinematics
from ..model import HandModel
from ..session import Recording
from ..transforms import FloatArray
from .rerunlog import (
    blueprint,
    log_frames,
    log_robot_frames,
    log_robot_static,
    log_static,
    new_stream,
)
from .scene import (
    RobotPlacement,
    hand_scene,
    no_usage_reporting,
    require_rerun,
)


class LiveView:
    """The view of ``fingerfit stream --view`` / ``--view-save``, fed block by block.

    :meth:`push` is called by the stream's data lane (its own thread, every frame, in
    blocks) with the kinematics it computed: the same :func:`hand_scene`,
    :func:`log_static` and :func:`log_frames` as ``fingerfit view``, with frames counted
    on from block to block. The robot (``placement``) is posed by the joints the data
    lane's own retargeter gives for every frame (:meth:`push`'s ``q``), or else by the
    joints the robot lane sent (:attr:`sent`, filled by the robot lane: one row per sent
    frame, at that frame).

    Parameters
    ----------
    model : HandModel
    save : Path, optional
        Write a Rerun file (atomically, when :meth:`close` is called with ``ok``);
        otherwise the native viewer is spawned (its usage reporting off).
    placement : RobotPlacement, optional
        The robot beside the hand, on a robot of its own (used on the data lane's thread).
    """

    def __init__(
        self, model: HandModel, save: Path | None = None, placement: RobotPlacement | None = None
    ) -> None:
        from ..io.atomic import atomic_path

        require_rerun()
        self.model, self.placement = model, placement
        self.frames = 0
        #: (frame, joints (nq,)) of every frame the robot lane sent, when the view's robot
        #: follows it (appended by the robot lane, taken by :meth:`push`).
        self.sent: collections.deque | None = None
        self._stack = contextlib.ExitStack()
        self.stream = new_stream()
        layout = blueprint(placement is not None)
        if save is not None:
            tmp = self._stack.enter_context(atomic_path(save, suffix=".part.rrd"))
            self.stream.save(tmp, default_blueprint=layout)
        else:
            with no_usage_reporting():
                self.stream.spawn(default_blueprint=layout)
        self._started = False

    def push(self, recording: Recording, kin: Kinematics, q: FloatArray | None = None) -> None:
        """Log a block of frames (the next ones of the stream).

        Parameters
        ----------
        recording : Recording
            The block's frames (mm, tracker frame).
        kin : Kinematics
            Their :func:`~fingerfit.kinematics.compute_kinematics` (``user_axis``, and
            ``orthogonal`` for its tips).
        q : ndarray, shape (n, nq), optional
            The robot's joints at every frame of the block.
        """
        n = recording.n_frames
        if n == 0:
            return
        scene = hand_scene(self.model, recording, kin)
        if not self._started:
            log_static(scene, self.stream)
            if self.placement is not None:
                log_robot_static(self.placement.digits, self.stream)
            self._started = True
        first = self.frames
        log_frames(scene, self.stream, first)
        if self.placement is not None:
            rows = np.arange(n)
            if q is None:
                rows, q = self._sent_until(first + n)
                rows = rows - first
            if rows.size:
                robot = self.placement.scene(q, recording.slice(rows))
                log_robot_frames(robot, self.stream, first + rows, recording.time[rows])
        self.frames += n

    def _sent_until(self, end: int) -> tuple[np.ndarray, FloatArray]:
        """The robot lane's sent frames before frame ``end``: their frames and joints."""
        rows, qs = [], []
        sent = self.sent
        while sent and sent[0][0] < end:
            frame, joints = sent.popleft()
            rows.append(frame)
            qs.append(joints)
        if not rows:
            return np.zeros(0, dtype=int), np.zeros((0, 0))
        return np.array(rows), np.stack(qs)

    def close(self, ok: bool = True) -> None:
        """Flush the stream; the file (``save``) is kept when ``ok``, else removed."""
        try:
            self.stream.flush()
            self.stream.disconnect()
        finally:
            if ok:
                self._stack.close()
            else:
                with contextlib.suppress(BaseException):
                    self._stack.__exit__(RuntimeError, RuntimeError("stream failed"), None)
