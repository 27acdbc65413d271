"""The view of a live stream (``stream --view`` / ``--view-save``), logged to Rerun by a
process of its own.

The stream's data lane hands every block of frames to :class:`LiveView`, which only puts
the block's poses (and the robot's joints, when the view shows a robot) on a bounded
queue. A child process (:func:`fingerfit.processes.start_child`: ``spawn``, no script
of the caller's run again, Ctrl-C left to the stream; its priority lowered by
:data:`VIEW_NICE`) computes the kinematics and scene of the blocks and logs them to
Rerun with the functions ``fingerfit view`` uses. So neither the view's NumPy work nor
Rerun's Python side runs in the stream's interpreter, where it would take turns with the
robot lane.

Rerun stores every entity's rows of one logging call as a chunk, with about 1.2 kB of
its own beside the numbers (schema, metadata, framing; measured on a five-digit hand):
logged block by block as the data lane hands them over (about 20 blocks a second), the
chunks' own bytes were half the file. So the process joins consecutive blocks before it
logs them: for a viewer, the blocks waiting when it is free (the viewer is never further
behind); for a file, :data:`FILE_BATCH_FRAMES` frames at a time.

What reaches the view (:attr:`LiveView.policy`):

* ``every`` (``--view-save``): every frame; when the queue is full the data lane waits
  for the view's process (the robot lane does not: it never touches the view);
* ``drop`` (``--view``): a block that finds the queue full is dropped and its frames
  counted (:attr:`LiveView.dropped`), so a viewer that falls behind is at most
  :data:`VIEW_QUEUE_BLOCKS` blocks behind the stream.
"""

from __future__ import annotations

import collections
import contextlib
import os
import queue
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..kinematics import compute_kinematics
from ..model import HandModel
from ..processes import child_ignores_interrupt, context, end_child, start_child
from ..session import Recording, concat_recordings
from ..track.recording import last_frame, track_recording
from ..transforms import FloatArray
from .rerunlog import (
    blueprint,
    close_view,
    log_frames,
    log_robot_frames,
    log_robot_static,
    log_static,
    open_view,
)
from .scene import (
    RobotPlacement,
    hand_recording,
    hand_scene,
    marker_scene,
    require_rerun,
)

#: Blocks the view's queue holds (a block is one pass of the data lane: about
#: ``fingerfit.live.datalane.DATA_PERIOD`` s of frames).
VIEW_QUEUE_BLOCKS = 16
#: The ``os.nice`` increment of the view's process: the stream's own process comes first.
VIEW_NICE = 10
#: Frames the view's process joins before it logs them to a file (``--view-save``): a
#: few seconds of a stream, a few chunks per entity (module docstring).
FILE_BATCH_FRAMES = 1024
#: Seconds between checks that the view's process is alive while waiting on it (a check
#: of liveness only: nothing waits for this long when the process answers).
_POLL_S = 0.5
#: The kinematics the view shows: the fitted model and the orthogonal one's tips.
_VARIANTS = ("user_axis", "orthogonal")

#: What reaches the view: every frame (the data lane waits for room), or blocks dropped
#: and counted while the view's queue is full.
POLICIES = ("every", "drop")
#: The view's robot: ``(robot, map)`` as ``--retarget`` and ``--map`` give them.
RobotSpec = tuple[str, Path | None]


class LiveView:
    """The view of ``fingerfit stream --view`` / ``--view-save``, fed block by block.

    :meth:`push` is called by the stream's data lane (every frame, in blocks) and hands
    the block to the view's process (module docstring): there the same
    :func:`hand_scene`, :func:`log_static` and :func:`log_frames` as ``fingerfit view``
    run, with frames numbered on from block to block (a dropped block leaves its frame
    numbers out). The robot (``robot``) is posed by the joints the data lane's own
    retargeter gives for every frame (:meth:`push`'s ``q``), or else by the joints the
    robot lane sent (:attr:`sent`, filled by the robot lane: one row per sent frame, at
    that frame).

    Parameters
    ----------
    model : HandModel
    save : Path, optional
        Write a Rerun file (atomically, when :meth:`close` is called with ``ok``; policy
        ``every``); otherwise the native viewer is spawned (its usage reporting off;
        policy ``drop``).
    robot : (str, Path or None), optional
        The robot beside the hand: ``--retarget`` and ``--map``, resolved by the view's
        process on a robot of its own (:func:`fingerfit.retarget.resolve`, the model's
        hand).
    policy : {"every", "drop"}, optional
        What reaches the view (module docstring); default ``every`` with ``save``, else
        ``drop``.

    Attributes
    ----------
    policy : {"every", "drop"}
    frames : int
        Frames pushed.
    dropped : int
        Frames dropped (policy ``drop``; 0 with ``every``).
    logged : int
        Frames the view's process logged (known once :meth:`close` returns).
    sent : collections.deque or None
        ``(frame, joints (nq,))`` of every frame the robot lane sent, when the view's robot
        follows it (appended by the robot lane, taken by :meth:`push`).

    Raises
    ------
    FingerfitError
        The view's process could not start its viewer or file, or resolve the robot.

    Notes
    -----
    A script may make a ``LiveView`` at its top level: the view's process runs none of
    the script (:mod:`fingerfit.processes`).
    """

    def __init__(
        self,
        model: HandModel,
        save: Path | None = None,
        robot: RobotSpec | None = None,
        policy: str | None = None,
    ) -> None:
        require_rerun()
        self.robot = robot
        self.policy = policy or ("every" if save is not None else "drop")
        if self.policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}, not {self.policy!r}")
        self.frames = self.dropped = self.logged = 0
        self.sent: collections.deque | None = None
        ctx = context()
        self._queue = ctx.Queue(VIEW_QUEUE_BLOCKS)
        self._reply, child_end = ctx.Pipe(duplex=False)
        batch = FILE_BATCH_FRAMES if save is not None else 0
        self._proc: Any = start_child(  # a daemon: never outlives the stream
            _serve,
            (self._queue, child_end, model, save, robot, os.getpid(), batch),
            "fingerfit-view",
        )
        child_end.close()
        try:
            self._answer("ready")
        except BaseException:
            self._end()
            raise

    def push(self, recording: Recording, q: FloatArray | None = None) -> None:
        """Hand a block of frames (the next ones of the stream) to the view's process.

        Parameters
        ----------
        recording : Recording
            The block's frames (mm, tracker frame).
        q : ndarray, shape (n, nq), optional
            The robot's joints at every frame of the block (else, with a robot, the
            robot lane's :attr:`sent` frames of the block).

        Raises
        ------
        FingerfitError
            The view's process has ended (its error, when it sent one).
        """
        n = recording.n_frames
        if n == 0:
            return
        self._alive()
        first = self.frames
        self.frames += n
        rows = None
        if self.robot is not None and q is None:
            rows, q = self._sent_until(first + n)
            rows = rows - first
        block = Recording("", recording.time, recording.poses, markers=recording.markers)
        item = ("frames", first, block, rows, q)
        if self.policy == "drop":
            try:
                self._queue.put_nowait(item)
            except queue.Full:
                self.dropped += n
        else:
            self._put(item)

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

    def _put(self, item: tuple) -> None:
        """Put ``item`` on the queue, waiting for room as long as the process lives."""
        while True:
            try:
                self._queue.put(item, timeout=_POLL_S)
                return
            except queue.Full:
                self._alive()

    def _alive(self) -> None:
        """Raise the view's error if its process has ended."""
        if self._proc is None:
            raise FingerfitError("the live view is closed")
        if self._proc.exitcode is not None:
            self._answer(None)  # raises: its error, or that it ended

    def _answer(self, kind: str | None) -> Any:
        """Wait for the view's process to answer ``kind`` (None: no answer but an error
        is expected); raise its error, or that it ended without the answer."""
        while True:
            if self._reply.poll(_POLL_S):
                got, value = self._reply.recv()
                if got == "error":
                    raise value
                if got == kind:
                    return value
            elif self._proc.exitcode is not None and not self._reply.poll(0):
                raise FingerfitError(
                    f"the live view's process ended (exit code {self._proc.exitcode})"
                )

    def close(self, ok: bool = True) -> None:
        """Log what is queued, flush, and end the view's process; the file (``save``) is
        kept when ``ok``, else removed. Sets :attr:`logged`."""
        if self._proc is None:
            return
        try:
            if self._proc.exitcode is None:
                self._put(("end", ok))
            self.logged = int(self._answer("done"))
        finally:
            self._end()

    def _end(self) -> None:
        """Join the view's process (ended after its answer) and release the queue."""
        proc, self._proc = self._proc, None
        end_child(proc, 30 * _POLL_S)  # terminated only after an error of this side
        self._queue.cancel_join_thread()  # the process has read up to "end", or is gone
        self._queue.close()
        self._reply.close()


class _Logger:
    """The view's process side: the Rerun stream, the robot's placement, frames logged."""

    def __init__(self, model: HandModel, save: Path | None, robot: RobotSpec | None) -> None:
        require_rerun()
        self.model = model
        self.placement = None
        if robot is not None:
            from ..retarget import resolve, setup

            bot, rmap = resolve(robot[0], robot[1], model.hand)
            self.placement = RobotPlacement(model, bot, rmap, setup(model, bot, rmap))
        self.frames = 0
        self.stream, self.stack = open_view(save, blueprint(robot is not None))
        self._started = False
        self._anchor = None

    def log(
        self, first: int, recording: Recording, rows: np.ndarray | None, q: FloatArray | None
    ) -> None:
        """Log the block whose first frame is the stream's frame ``first``; the robot at
        the block's ``rows`` (all when None) with joints ``q`` (rows, nq)."""
        n = recording.n_frames
        if self.model.markers:  # a model fitted from markers: its markers' kinematics
            scene = marker_scene(self.model, recording)
            recording = hand_recording(scene, recording)  # the robot is placed by it
        else:
            if self.model.tracking is not None and n:
                # Frames with a missing sensor: solved by the model as the stream's files
                # are, joined to the previous block by the temporal prior.
                track = track_recording(self.model, recording, _VARIANTS, anchor=self._anchor)
                kin = track.kinematics
                self._anchor = last_frame(kin)
            else:
                kin = compute_kinematics(self.model, recording, _VARIANTS)
            scene = hand_scene(self.model, recording, kin)
        if not self._started:
            log_static(scene, self.stream)
            if self.placement is not None:
                log_robot_static(self.placement.digits, self.stream, self.placement.geometry)
            self._started = True
        log_frames(scene, self.stream, first)
        if self.placement is not None and q is not None:
            at = np.arange(n) if rows is None else rows
            if at.size:
                robot = self.placement.scene(q, recording.slice(at))
                log_robot_frames(robot, self.stream, first + at, recording.time[at])
        self.frames += n

    def close(self, ok: bool) -> None:
        """Flush the stream; the file is kept when ``ok``, else removed."""
        close_view(self.stream, self.stack, ok)


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it pickles (to cross to the stream's process), else its text."""
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:
        return FingerfitError(f"live view: {type(exc).__name__}: {exc}")
    return exc


class _Joined:
    """Consecutive blocks of the stream joined into one before they are logged: the
    frames, and the robot's rows and joints of each (``LiveView.push``'s items)."""

    def __init__(self) -> None:
        self.items: list[tuple[int, Recording, np.ndarray | None, FloatArray | None]] = []
        self.frames = 0

    def follows(self, first: int, recording: Recording) -> bool:
        """Whether a block starting at frame ``first`` continues the joined ones (no
        dropped block between, the same sensors)."""
        if not self.items:
            return True
        last_first, last, _, _ = self.items[-1]
        return first == last_first + last.n_frames and recording.sensors == last.sensors

    def add(
        self, first: int, recording: Recording, rows: np.ndarray | None, q: FloatArray | None
    ) -> None:
        self.items.append((first, recording, rows, q))
        self.frames += recording.n_frames

    def take(self) -> tuple[int, Recording, np.ndarray | None, FloatArray | None]:
        """The joined block as :meth:`_Logger.log` takes it, and empty again."""
        items, self.items, self.frames = self.items, [], 0
        first = items[0][0]
        recording = concat_recordings([it[1] for it in items])
        if all(rows is None for _, _, rows, _ in items):
            qs = [q for *_, q in items if q is not None]
            return first, recording, None, np.concatenate(qs) if qs else None
        at, qs = [], []
        for start, rec, rows, q in items:
            if rows is None:
                rows = np.arange(rec.n_frames)
            if rows.size and q is not None:
                at.append(rows + (start - first))
                qs.append(q)
        if not at:
            return first, recording, np.zeros(0, dtype=int), np.zeros((0, 0))
        return first, recording, np.concatenate(at), np.concatenate(qs)


def _serve(
    blocks: Any,
    reply: Any,
    model: HandModel,
    save: Path | None,
    robot: RobotSpec | None,
    parent: int,
    batch: int,
) -> None:
    """The view's process: log every block taken from ``blocks`` until ``("end", ok)``,
    consecutive blocks joined (:class:`_Joined`): ``batch`` frames at a time, or with
    ``batch`` 0 those waiting whenever the queue is empty.

    Answers on ``reply``: ``("ready", None)`` once the viewer or file is open, then
    ``("done", frames logged)``; or ``("error", exception)``. Ctrl-C is left to the
    stream, which ends the view through the queue; if the stream's process (``parent``,
    its pid) is gone, the view ends too (its file not kept).
    """
    child_ignores_interrupt()
    with contextlib.suppress(OSError):
        os.nice(VIEW_NICE)
    try:
        logger = _Logger(model, save, robot)
    except BaseException as exc:
        reply.send(("error", _portable(exc)))
        return
    reply.send(("ready", None))
    joined = _Joined()
    try:
        while True:
            try:
                item = blocks.get(timeout=_POLL_S)
            except queue.Empty:
                if os.getppid() != parent:
                    item = ("end", False)
                else:
                    continue
            if item[0] == "end":
                if joined.items and item[1]:
                    logger.log(*joined.take())
                logger.close(bool(item[1]))
                break
            first, recording = item[1], item[2]
            if not joined.follows(first, recording):
                logger.log(*joined.take())
            joined.add(*item[1:])
            if joined.frames >= (batch or FILE_BATCH_FRAMES) or (not batch and blocks.empty()):
                logger.log(*joined.take())
    except BaseException as exc:
        with contextlib.suppress(BaseException):
            logger.close(False)
        reply.send(("error", _portable(exc)))
        return
    reply.send(("done", logger.frames))
