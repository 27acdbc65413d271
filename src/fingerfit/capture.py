"""Guided capture: a protocol recording taken into a session folder, with the evidence
the fit needs shown per joint while it is recorded (``fingerfit capture``).

The evidence is the fit's own, computed by the fit's functions on everything the fit will
pool -- the folder's calibration (``grasp``) recordings so far and the one being recorded
(:func:`fingerfit.estimate.fit.digit_data`):

* grasp cycles and their median range of motion (:func:`fingerfit.estimate.cycles.
  extract_cycles`), against ``FitOptions.min_cycles`` and ``min_rom_deg``;
* the flexion axis's 95 % confidence half-angle from the spread over the cycles
  (:func:`fingerfit.estimate.fit.axis_ci_deg`), against ``FitOptions.max_axis_ci_deg``;
* for a joint with a second axis, whether the data identify it: a finger's MP and the
  thumb's MCP by the fit's held-out choice (:func:`fingerfit.estimate.methods.
  second_axis_choice`: two axes chosen, or one), the thumb's CMC by the saddle fit
  itself (:func:`fingerfit.estimate.fit.saddle_estimate`: both axes turned far enough,
  or the fit's refusal).

A joint is *enough* when it passes the rules by which ``fingerfit fit`` refuses a joint
(cycles, range of motion) and the axis confidence bound above which the fit warns; the
thumb's CMC, which the fit takes without the cycle rules, when its saddle fit succeeds and
its axis confidence passes (``docs/capture.md``).
"""

from __future__ import annotations

import functools
import math
import multiprocessing as mp
import queue
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .digits import DIGITS
from .errors import FingerfitError
from .estimate.choice import TWO_AXIS
from .estimate.fit import (
    FitOptions,
    axis_ci_deg,
    digit_data,
    digit_direction,
    reference_poses,
    saddle_estimate,
)
from .estimate.methods import JointData, second_axis_choice
from .session import PoseSeries, Recording, Session
from .transforms import FloatArray

#: The protocols ``fingerfit capture`` guides: the digits whose joints it shows (None:
#: every digit of the session) and the recordings it takes, in the order it proposes them
#: (``docs/formats.md``). Each is listed under ``grasp`` in ``session.toml``: the fit
#: pools every calibration recording.
PROTOCOLS: dict[str, tuple[tuple[str, ...] | None, tuple[str, ...]]] = {
    "grasp": (None, ("grasp.csv",)),
    "thumb": (("thumb",), ("thumb_circumduction.csv", "thumb_opposition.csv")),
}
#: The ``session.toml`` list every protocol's recording joins.
RECORDING_LIST = "grasp"
#: At least this many seconds between the starts of two evidence computations while
#: recording (:class:`EvidenceProcess`).
UPDATE_S = 0.5
#: Seconds between checks that the evidence process is alive while waiting on it (a
#: check of liveness only: nothing waits this long when it answers).
_POLL_S = 0.5


def thresholds(options: FitOptions | None = None) -> tuple[int, float, float]:
    """``(cycles, range of motion deg, axis confidence half-angle deg)`` a joint needs:
    the fit's own (``FitOptions``).

    The fit refuses a joint with fewer than ``max(min_cycles, 2)`` cycles or a median range
    of motion under ``min_rom_deg``, and warns (keeping the joint) when its axis
    confidence half-angle is over ``max_axis_ci_deg`` (``fingerfit.estimate.fit``).
    """
    options = options or FitOptions()
    return max(options.min_cycles, 2), float(options.min_rom_deg), float(options.max_axis_ci_deg)


@dataclass(frozen=True)
class JointEvidence:
    """What the fit needs of one joint, so far.

    Attributes
    ----------
    digit, joint : str
    cycles : int
        Movement cycles found over the pooled recordings.
    rom_deg : float
        Median range of motion of those cycles (deg; NaN without a cycle).
    axis_ci_deg : float
        95 % confidence half-angle of the flexion axis (deg; NaN below two cycles or
        when the saddle fit refuses).
    second : bool or None
        None for a joint with one axis (PIP, DIP, IP); else whether the data identify the
        second axis: a finger's MP or the thumb's MCP when the held-out choice takes two
        axes, the thumb's CMC when its saddle fit succeeds.
    second_note : str
        What decided ``second``, in a few words: the ab/adduction range (deg) and the
        choice, or the saddle fit's ranges (deg).
    enough : bool
        The joint passes the fit's rules (module docstring).
    advice : str
        The fit's own refusal of the second axis when it refuses it (one line), else "";
        a refused joint is not enough.
    """

    digit: str
    joint: str
    cycles: int
    rom_deg: float
    axis_ci_deg: float
    second: bool | None
    second_note: str
    enough: bool
    advice: str = ""


#: The evidence table's columns (``fingerfit capture``'s table, the view's panel); the
#: numeric ones are right-aligned.
TABLE_COLUMNS = ("digit", "joint", "cycles", "ROM (deg)", "axis +/- (deg)", "2nd axis", "")
NUMERIC_COLUMNS = ("cycles", "ROM (deg)", "axis +/- (deg)")


def table_title(need: tuple[int, float, float], frames: int, rate_hz: float) -> str:
    """The evidence table's title: the frames (and seconds at ``rate_hz`` Hz) it covers
    and what the fit needs (:func:`thresholds`)."""
    return (
        f"{frames} frames ({frames / rate_hz:.1f} s); the fit needs {need[0]} cycles, "
        f"{need[1]:g} deg median range of motion and the axis within +/-{need[2]:g} deg "
        "(95 %) per joint"
    )


def table_cells(r: JointEvidence) -> list[str]:
    """One joint's row of the evidence table (:data:`TABLE_COLUMNS`), as printed: the ROM
    to the degree, the axis confidence to a tenth of a degree (``<0.1`` below), ``-``
    for what is not known, ``enough`` or ``more``."""
    rom = "-" if math.isnan(r.rom_deg) else f"{r.rom_deg:.0f}"
    ci = "-" if math.isnan(r.axis_ci_deg) else f"{max(r.axis_ci_deg, 0.1):.1f}"
    ci = "<" + ci if r.axis_ci_deg < 0.05 else ci
    second = "-" if r.second is None else ("yes: " if r.second else "no: ") + r.second_note
    return [r.digit, r.joint, str(r.cycles), rom, ci, second, "enough" if r.enough else "more"]


def markdown_table(
    rows: list[JointEvidence], frames: int, need: tuple[int, float, float], rate_hz: float
) -> str:
    """The evidence table as Markdown (the view's panel): :func:`table_title`, then one
    row per joint with the cells the terminal shows (:func:`table_cells`)."""
    head = [c or "fit" for c in TABLE_COLUMNS]
    align = ["---:" if c in NUMERIC_COLUMNS else "---" for c in TABLE_COLUMNS]
    lines = [f"**{table_title(need, frames, rate_hz)}**", ""]
    for cells in (head, align, *(table_cells(r) for r in rows)):
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def _second(data: JointData, required: bool) -> tuple[bool, str, str, float]:
    """``(identified, note, advice, axis CI deg)`` of a joint with a second axis (module
    docstring)."""
    if required:
        try:
            est = saddle_estimate(data, None, None)
        except FingerfitError as exc:
            return False, "refused by the saddle fit", exc.reason, math.nan
        sf = est.abduction
        note = f"flexion {sf.flexion_range_deg:.0f}, ab/ad {sf.abduction_range_deg:.0f} deg"
        return True, note, "", axis_ci_deg(data, sf)
    if len(data.periods) < 2:
        return False, "needs 2 cycles", "", math.nan
    try:
        tf, choice = second_axis_choice(data)
    except FingerfitError as exc:
        return False, "refused by the two-axis fit", exc.reason, math.nan
    two = choice.chosen == TWO_AXIS
    note = f"ab/ad {tf.abduction_range_deg:.1f} deg, {'two axes' if two else 'one axis'}"
    return two, note, "", axis_ci_deg(data, None, choice)


def evidence(
    session: Session,
    digits: list[str],
    options: FitOptions | None = None,
    *,
    second: bool = True,
) -> list[JointEvidence]:
    """The evidence of every joint of ``digits`` over the session's ``grasp`` recordings.

    Parameters
    ----------
    session : Session
        The reference recording, every calibration recording so far in ``grasp`` (mm,
        tracker frame) and the landmarks when there are any (they start the MP's second
        axis as in the fit; without them the fit's landmark-free starts are used).
    digits : list of str
        Digits whose joints to report.
    options : FitOptions, optional
        The thresholds (default: the fit's defaults).
    second : bool
        Evaluate the second axes (the held-out choice, the saddle fit: tenths of a
        second to seconds); without it ``second`` is None and a joint's axis confidence is
        that of its SARA hinge axis.

    Returns
    -------
    list of JointEvidence
        Proximal to distal per digit.
    """
    options = options or FitOptions()
    need_cycles, need_rom, max_ci = thresholds(options)
    reference = reference_poses(session)
    out = []
    for d in digits:
        digit = DIGITS[d]
        if any(s not in reference for s in digit.sensors()) or not session.grasp:
            out += [
                JointEvidence(d, j, 0, math.nan, math.nan, None, "", False) for j in digit.joints
            ]
            continue
        try:
            along = digit_direction(session, d)
        except FingerfitError:  # no landmarks yet
            along = None
        for j, data in digit_data(session, d, reference, along).items():
            n = len(data.periods)
            rom = float(np.degrees(np.median(data.rom))) if n else math.nan
            required = j in digit.required_second
            ident, note, advice = None, "", ""
            if second and j in digit.second_axes:
                ident, note, advice, ci = _second(data, required)
            else:
                ci = axis_ci_deg(data)
            ci_ok = not ci > max_ci  # NaN: the cycle rule decides
            if required:
                ok = bool(ident) and ci_ok if second else False
            else:
                ok = n >= need_cycles and rom >= need_rom and ci_ok and not math.isnan(ci)
                ok = ok and not advice
            out.append(JointEvidence(d, j, n, rom, ci, ident, note, bool(ok), advice))
    return out


class Accumulator:
    """Blocks of frames joined into one recording as they arrive.

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
        self._time: list[FloatArray] = []
        self._pos: dict[str, list[FloatArray]] = {s: [] for s in self.sensors}
        self._rot: dict[str, list[FloatArray]] = {s: [] for s in self.sensors}
        self.n_frames = 0

    def add(self, block: Recording) -> None:
        n = block.n_frames
        if n == 0:
            return
        self._time.append(np.asarray(block.time, dtype=float))
        for s in self.sensors:
            if s in block.poses:
                self._pos[s].append(block.poses[s].position)
                self._rot[s].append(block.poses[s].rotation)
            else:
                self._pos[s].append(np.full((n, 3), np.nan))
                self._rot[s].append(np.full((n, 3, 3), np.nan))
        self.n_frames += n

    def recording(self) -> Recording:
        """Everything so far as one :class:`~fingerfit.session.Recording`."""
        if not self._time:
            empty = {s: PoseSeries(np.zeros((0, 3)), np.zeros((0, 3, 3))) for s in self.sensors}
            return Recording(self.name, np.zeros(0), empty)
        poses = {
            s: PoseSeries(np.concatenate(self._pos[s]), np.concatenate(self._rot[s]))
            for s in self.sensors
        }
        return Recording(self.name, np.concatenate(self._time), poses)


def _evidence_loop(
    base: Session,
    name: str,
    sensors: list[str],
    digits: list[str],
    options: FitOptions | None,
    view: tuple[Callable[..., Any] | None, Path | None],
    blocks: mp.Queue,
    results: mp.Queue,
) -> None:
    """The child process of :class:`EvidenceProcess`: joins the blocks it is sent and,
    whenever it is free, at most every :data:`UPDATE_S`, sends ``("evidence", rows,
    n_frames)`` of everything so far (and logs it to the view ``view[0]`` makes, if any); ends at
    ``("end", final)``, logging ``final`` (``(rows, n_frames)``, or None) to the view and
    closing it. Ctrl-C is the parent's to handle (it stops the child), so the child
    ignores it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
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
            from .view.live import _portable

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
        ctx = mp.get_context("spawn")
        self.has_view = viewer is not None
        self._blocks = ctx.Queue()
        self._results = ctx.Queue()
        self._proc = ctx.Process(
            target=_evidence_loop,
            args=(
                base,
                name,
                sensors,
                digits,
                options,
                (viewer, view_save),
                self._blocks,
                self._results,
            ),
            daemon=True,
        )
        self._proc.start()
        if self.has_view:
            try:
                self._wait("ready")
            except BaseException:
                self._proc.join()
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

        Returns
        -------
        int
            Updates the view logged (0 without a view).
        """
        self._blocks.put(("end", final))
        updates = 0
        try:
            if self.has_view:
                updates = int(self._wait("closed"))
        finally:
            self._proc.join(None if self.has_view else timeout_s)
            if self._proc.is_alive():
                self._proc.terminate()
                self._proc.join()
            self._blocks.cancel_join_thread()
            self._results.cancel_join_thread()
        return updates
