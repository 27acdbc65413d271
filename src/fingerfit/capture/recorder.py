"""The recorder every protocol of ``fingerfit capture`` shares: the frames of a source
kept as they arrive (:class:`Accumulator`), the evidence computed beside them in a child
process (:class:`EvidenceProcess`) and the loop that feeds both (:func:`record`); what a
Ctrl-C does meanwhile is :class:`fingerfit.processes.Interrupts`."""

from __future__ import annotations

import functools
import math
import queue
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..estimate.evidence import JointEvidence, evidence, thresholds
from ..estimate.fit import FitOptions
from ..processes import child_ignores_interrupt, context, end_child, start_child
from ..session import PoseSeries, Recording, Session
from ..transforms import FloatArray
from .table import markdown_table

#: At least this many seconds between the starts of two evidence computations while
#: recording (:class:`EvidenceProcess`).
UPDATE_S = 0.5
#: Seconds between checks that the evidence process is alive while waiting on it (a
#: check of liveness only: nothing waits this long when it answers).
_POLL_S = 0.5


class Accumulator:
    """Blocks of frames joined into one recording as they arrive.

    Each block is kept whole by one ``list.append`` (a Ctrl-C lands before or after it,
    never inside), so what was recorded is always one consistent recording.

    Parameters
    ----------
    name : str
        File name of the recording (``grasp.csv``).
    sensors : list of str
        Sensors kept (others a source sends are dropped); every one is in the result,
        NaN where a block lacks it.
    """

    def __init__(self, name: str, sensors: list[str]) -> None:
        self.name = name
        self.sensors = list(sensors)
        self._blocks: list[tuple[FloatArray, list[tuple[FloatArray, FloatArray]]]] = []

    @property
    def n_frames(self) -> int:
        """Frames so far."""
        return sum(t.size for t, _ in self._blocks)

    def add(self, block: Recording) -> None:
        """Keep a block (positions mm, rotations sensor -> tracker)."""
        n = block.n_frames
        if n == 0:
            return
        poses = [
            (block.poses[s].position, block.poses[s].rotation)
            if s in block.poses
            else (np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan))
            for s in self.sensors
        ]
        self._blocks.append((np.asarray(block.time, dtype=float), poses))

    def recording(self) -> Recording:
        """Everything so far as one :class:`~fingerfit.session.Recording`."""
        blocks = list(self._blocks)
        if not blocks:
            empty = {s: PoseSeries(np.zeros((0, 3)), np.zeros((0, 3, 3))) for s in self.sensors}
            return Recording(self.name, np.zeros(0), empty)
        poses = {
            s: PoseSeries(
                np.concatenate([b[1][k][0] for b in blocks]),
                np.concatenate([b[1][k][1] for b in blocks]),
            )
            for k, s in enumerate(self.sensors)
        }
        return Recording(self.name, np.concatenate([b[0] for b in blocks]), poses)


def _evidence_loop(
    base: Session,
    name: str,
    sensors: list[str],
    digits: list[str],
    options: FitOptions | None,
    view: tuple[Callable[..., Any] | None, Path | None],
    blocks: Any,
    results: Any,
) -> None:
    """The child process of :class:`EvidenceProcess`: joins the blocks it is sent and,
    whenever it is free, at most every :data:`UPDATE_S`, sends ``("evidence", rows,
    n_frames)`` of everything so far (and logs it to the view ``view[0]`` makes, if any); ends at
    ``("end", final)``, logging ``final`` (``(rows, n_frames)``, or None) to the view and
    closing it. Ctrl-C is the parent's to handle (it stops the child), so the child
    ignores it (:func:`fingerfit.processes.child_ignores_interrupt`)."""
    child_ignores_interrupt()
    shown = None
    if view[0] is not None:
        try:
            need = thresholds()
            shown = view[0](
                sensors,
                need,
                functools.partial(markdown_table, need=need, rate_hz=base.rate_hz),
                view[1],
            )
        except BaseException as exc:
            from ..view.live import _portable

            results.put(("error", _portable(exc)))
            return
        results.put(("ready", None))
    acc = Accumulator(name, sensors)
    done_frames, started = 0, -math.inf
    while True:
        try:  # wait for a block only when there is nothing new to evaluate
            wait = acc.n_frames == done_frames
            items = [
                blocks.get(
                    timeout=None if wait else max(0.0, started + UPDATE_S - time.monotonic())
                )
            ]
        except queue.Empty:
            items = []
        while True:
            try:
                items.append(blocks.get_nowait())
            except queue.Empty:
                break
        for item in items:
            if isinstance(item, tuple):  # ("end", final)
                if shown is not None:
                    final = item[1]
                    if final is not None:
                        shown.log(final[0], acc.recording(), final[1])
                    shown.close(final is not None)
                    results.put(("closed", shown.updates))
                return
            acc.add(item)
        if acc.n_frames > done_frames and time.monotonic() - started >= UPDATE_S:
            started = time.monotonic()
            rec = acc.recording()
            session = replace(base, grasp=[*base.grasp, rec])
            rows = evidence(session, digits, options)
            results.put(("evidence", rows, rec.n_frames))
            if shown is not None:
                shown.log(rows, rec, rec.n_frames)
            done_frames = rec.n_frames


class EvidenceProcess:
    """The evidence of a recording in progress, computed in a child process beside the
    recording loop.

    The loop only hands each block over (:meth:`add`: a few frames pickled onto a
    queue) and picks up the newest result (:meth:`latest`); the child joins the blocks
    and evaluates everything so far whenever it is free, at most every :data:`UPDATE_S`.
    In its own process the evaluation (the thumb's saddle fit takes seconds) shares neither
    the loop's interpreter lock nor its BLAS threads, so the loop keeps up with the source.
    With a view (``capture --view`` / ``--view-save``) the child also logs each result to
    Rerun (``viewer``, :class:`fingerfit.view.evidence.EvidenceView`), and at :meth:`close`
    the final evidence.

    Parameters
    ----------
    base : Session
        The session without the recording in progress: reference, the calibration
        recordings so far in ``grasp``, landmarks (mm), rate.
    name : str
        File name of the recording in progress.
    sensors : list of str
        Its sensors (:class:`Accumulator`).
    digits : list of str
        Digits to report (:func:`evidence`).
    options : FitOptions, optional
    viewer : callable, optional
        ``viewer(sensors, thresholds, table, save)`` makes the child's view of the evidence
        (:class:`fingerfit.view.evidence.EvidenceView`, passed in by the command so that
        this module does not import the viewer); None: no view.
    view_save : Path, optional
        With ``viewer``: write the view to this Rerun file instead of the native viewer
        (complete once :meth:`close` returns with a final result).

    Raises
    ------
    FingerfitError, ModuleNotFoundError
        The child could not open its viewer or file.
    """

    def __init__(
        self,
        base: Session,
        name: str,
        sensors: list[str],
        digits: list[str],
        options: FitOptions | None = None,
        viewer: Callable[..., Any] | None = None,
        view_save: Path | None = None,
    ) -> None:
        ctx = context()
        self.has_view = viewer is not None
        self._closed = False
        self._blocks = ctx.Queue()
        self._results = ctx.Queue()
        self._proc = start_child(
            _evidence_loop,
            (
                base,
                name,
                sensors,
                digits,
                options,
                (viewer, view_save),
                self._blocks,
                self._results,
            ),
            "fingerfit-evidence",
        )
        if self.has_view:
            try:
                self._wait("ready")
            except BaseException:
                end_child(self._proc)
                raise

    def _wait(self, kind: str) -> Any:
        """The child's next answer ``kind`` (evidence in between is dropped); its error
        raised, or that it ended without the answer."""
        while True:
            try:
                got = self._results.get(timeout=_POLL_S)
            except queue.Empty:
                if self._proc.exitcode is not None and self._results.empty():
                    raise FingerfitError(
                        f"the evidence process ended (exit code {self._proc.exitcode})"
                    ) from None
                continue
            if got[0] == "error":
                raise got[1]
            if got[0] == kind:
                return got[1]

    def add(self, block: Recording) -> None:
        """Hand a block of frames over (as :meth:`Accumulator.add` takes it)."""
        if block.n_frames:
            self._blocks.put(block)

    def latest(self) -> tuple[list[JointEvidence], int] | None:
        """The newest result not yet taken, ``(rows, frames it covers)``, or None."""
        out = None
        while True:
            try:
                got = self._results.get_nowait()
            except queue.Empty:
                return out
            if got[0] == "error":
                raise got[1]
            out = (got[1], got[2])

    def close(
        self, final: tuple[list[JointEvidence], int] | None = None, timeout_s: float = 1.0
    ) -> int:
        """Stop the child. Without a view: at once after ``timeout_s`` if it is still
        evaluating. With one: once it has logged ``final`` (the evidence the capture
        prints and the frames it covers; None: the file is not kept) and closed the view.
        Once closed, a call does nothing.

        Returns
        -------
        int
            Updates the view logged (0 without a view).
        """
        if self._closed:
            return 0
        self._closed = True
        self._blocks.put(("end", final))
        updates = 0
        try:
            if self.has_view:
                updates = int(self._wait("closed"))
        finally:
            end_child(self._proc, None if self.has_view else timeout_s)
            self._blocks.cancel_join_thread()
            self._results.cancel_join_thread()
        return updates


def record(
    blocks: Iterable[Any],
    kept: Accumulator,
    child: EvidenceProcess,
    rate_hz: float,
    *,
    duration: float | None = None,
    until_enough: bool = False,
    show: Callable[[list[JointEvidence], int], None] | None = None,
) -> bool:
    """Record a source's blocks into ``kept`` and hand each to ``child`` until the source
    ends, ``duration`` seconds are recorded, every joint has enough (``until_enough``) or
    Ctrl-C.

    Parameters
    ----------
    blocks : iterable
        The source's blocks (:class:`fingerfit.live.sources.Block`, or None while it
        waits).
    kept : Accumulator
    child : EvidenceProcess
    rate_hz : float
        The session's rate (the seconds of ``duration``).
    duration : float, optional
    until_enough : bool
    show : callable, optional
        Called with each new evidence ``(rows, frames)``.

    Returns
    -------
    bool
        Whether Ctrl-C stopped it (what was recorded is in ``kept`` either way).
    """
    try:
        for block in blocks:
            if block is not None:
                kept.add(block.recording)
                child.add(block.recording)
            result = child.latest()
            if result is not None:
                if show is not None:
                    show(*result)
                if until_enough and all(r.enough for r in result[0]):
                    return False
            if duration is not None and kept.n_frames >= duration * rate_hz:
                return False
    except KeyboardInterrupt:
        return True
    return False
