"""``fingerfit capture``: record a protocol into a session folder, guided by the fit's needs."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ..errors import FingerfitError
from .app import Quiet, app, console, notice, out, say, user_errors
from .capture_source import open_source, source_files

if TYPE_CHECKING:
    from collections.abc import Iterator

    from rich.table import Table

    from ..capture import CapturePlan, JointEvidence
    from ..session import Recording

# fingerfit.capture.PROTOCOLS (without importing NumPy), and the steps that are not
# calibration recordings (.capture_steps).
PROTOCOLS = ("grasp", "thumb", "pinch")
STEPS = ("reference", "landmarks")
HOLD_PROTOCOLS = ("thumb", "pinch")  # fingerfit.capture.protocols.HOLD_PROTOCOLS
TRIGGERS = ("still", "enter")


@app.command()
@user_errors
def capture(
    session_dir: Annotated[
        Path,
        typer.Argument(
            metavar="SESSION_DIR",
            help="Session folder: its session.toml (or the options below) and reference.csv.",
        ),
    ],
    source: Annotated[
        str,
        typer.Option(
            help="replay:FILE[@SPEED], liberty:PORT[@BAUD] or lsl:NAME (docs/streaming.md)."
        ),
    ],
    protocol: Annotated[
        str,
        typer.Option(
            help=f"The step to take: {', '.join(STEPS + PROTOCOLS)} (docs/lab.md: in the lab's "
            "order, reference, landmarks, grasp, thumb, pinch)."
        ),
    ] = "grasp",
    name: Annotated[
        str | None,
        typer.Option(
            help="File name of the recording in the folder (default: the protocol's first "
            "recording the folder lacks: grasp.csv; thumb_circumduction.csv, then "
            "thumb_opposition.csv)."
        ),
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option(
            min=0.0,
            help="Stop after this many seconds of recording (default: the "
            "end of a replay, Ctrl-C for a device).",
        ),
    ] = None,
    until_enough: Annotated[
        bool,
        typer.Option("--until-enough", help="Stop as soon as every joint has enough evidence."),
    ] = False,
    subject: Annotated[
        str | None,
        typer.Option(
            help="Subject id, for a folder without session.toml (with one, these options "
            "may only repeat what it says)."
        ),
    ] = None,
    hand: Annotated[
        str | None, typer.Option(help="left or right (without session.toml; default left).")
    ] = None,
    units: Annotated[
        str | None, typer.Option(help="Units of x,y,z (without session.toml; default mm).")
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(min=1e-6, help="Sampling rate, Hz (without session.toml; default 240)."),
    ] = None,
    fingers: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated digits (without session.toml; default: those the "
            "reference recording has sensors for)."
        ),
    ] = None,
    reference: Annotated[
        Path | None,
        typer.Option(
            help="Reference recording (pose CSV) to copy into the folder as its "
            "reference.csv (with the recording, once it is complete)."
        ),
    ] = None,
    landmarks: Annotated[
        Path | None,
        typer.Option(
            help="Landmarks CSV to copy into the folder as landmarks.csv (with the recording)."
        ),
    ] = None,
    stations: Annotated[
        str | None,
        typer.Option(help="liberty: station=sensor list, e.g. 1=hand,2=index.proximal,..."),
    ] = None,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="Replace the recording if it exists.")
    ] = False,
    view: Annotated[
        bool,
        typer.Option(
            "--view",
            help="Show the evidence live in the Rerun viewer too (series per joint, the "
            "table, the sensors; a display is needed).",
        ),
    ] = False,
    view_save: Annotated[
        Path | None,
        typer.Option(
            "--view-save",
            metavar="OUT.rrd",
            help="Write that view to this Rerun file instead of a window (complete when "
            "the capture ends).",
        ),
    ] = None,
    stylus: Annotated[
        Path | None,
        typer.Option(help="landmarks: the stylus file (fingerfit stylus).", show_default=False),
    ] = None,
    takes: Annotated[
        int, typer.Option(min=1, max=20, help="landmarks: placements averaged per landmark.")
    ] = 3,
    pads: Annotated[
        bool, typer.Option("--pads", help="landmarks: each digit's pad too (<digit>.pad).")
    ] = False,
    targets: Annotated[
        str | None,
        typer.Option(
            help="landmarks: target labels to digitise too (target.<label>), e.g. t000,t020."
        ),
    ] = None,
    only: Annotated[
        str | None,
        typer.Option(
            help="landmarks: take only these again (names as in landmarks.csv); the others "
            "in landmarks.csv are kept."
        ),
    ] = None,
    trigger: Annotated[
        str,
        typer.Option(
            help="landmarks: what takes a point: still (the stylus held still 0.5 s) or enter "
            "(the Enter key: the 0.5 s before it). thumb, pinch: still (holds found from the "
            "pads) or enter (a press at each hold's start and end)."
        ),
    ] = "still",
    quiet: Quiet = False,
) -> None:
    """Take a step of the lab's protocol into a session folder: the reference posture,
    the stylus landmarks, or a calibration recording (grasp, thumb, pinch) showing per
    joint the cycles, range of motion, axis confidence and second axis found so far and
    when each has enough for `fingerfit fit`."""
    from ..processes import Interrupts
    from .app import parse_list
    from .stream import check_view

    if protocol not in PROTOCOLS + STEPS:
        raise FingerfitError(f"must be one of {', '.join(STEPS + PROTOCOLS)}", field="--protocol")
    if trigger not in TRIGGERS:
        raise FingerfitError(f"must be one of {', '.join(TRIGGERS)}", field="--trigger")
    digits = parse_list(fingers, ("thumb", "index", "middle", "ring", "little"), "--fingers")
    if protocol in STEPS:
        from . import capture_steps as steps

        if protocol == "reference" and (view or view_save is not None):
            raise FingerfitError("the reference protocol has no view", field="--view")
        check_view(view, view_save, None)
        with Interrupts():
            try:
                if protocol == "reference":
                    steps.capture_reference(
                        session_dir, source, duration=duration, subject=subject, hand=hand,
                        units=units, rate=rate, digits=digits, stations=stations,
                        overwrite=overwrite,
                    )  # fmt: skip
                else:
                    steps.capture_landmarks(
                        session_dir, source, stylus=stylus, takes=takes, pads=pads,
                        targets=_names(targets), only=_names(only) or None, trigger=trigger,
                        stations=stations, overwrite=overwrite, view=view, view_save=view_save,
                    )  # fmt: skip
            except KeyboardInterrupt:
                raise FingerfitError(
                    "interrupted before recording began: nothing written"
                ) from None
        return
    with Interrupts() as interrupts:
        try:  # once recording, a Ctrl-C is handled inside (it never leaves half a result)
            check_view(view, view_save, None)
            _capture(
                session_dir, source, protocol, name, duration, until_enough, subject, hand,
                units, rate, digits, reference, landmarks, stations, overwrite, view,
                view_save, quiet, interrupts, trigger,
            )  # fmt: skip
        except KeyboardInterrupt:
            raise FingerfitError("interrupted before recording began: nothing written") from None


def _capture(
    folder, spec, protocol, name, duration, until_enough, subject, hand, units, rate, digits,
    reference, landmarks, stations, overwrite, view, view_save, quiet, interrupts, trigger,
) -> None:  # fmt: skip
    """Check everything, open the source, record, write, then the final evidence. Ctrl-C
    before the recording leaves nothing; during it, stops it and keeps what was recorded;
    after it, cuts the final evidence short (the files are written by then)."""
    from dataclasses import replace

    from ..capture import (
        Accumulator,
        EvidenceProcess,
        evidence,
        plan_capture,
        record,
        thresholds,
        write_capture,
    )

    plan = plan_capture(
        folder, protocol, name, subject=subject, hand=hand, units=units, rate=rate,
        fingers=digits, reference=reference, landmarks=landmarks, inputs=source_files(spec),
        overwrite=overwrite,
    )  # fmt: skip
    need = thresholds()
    acc = Accumulator(plan.name, plan.sensors)
    # --trigger enter: the holds of a thumb or pinch recording marked by the Enter key.
    presses: list[float] | None = [] if trigger == "enter" and protocol in HOLD_PROTOCOLS else None
    from ..capture import check_sensors

    the_source = open_source(
        spec,
        units=plan.units,
        rate_hz=plan.rate_hz,
        sensors=plan.sensors,
        stations=stations,
        check=lambda rec, path: check_sensors(rec, plan, path),
    )
    live = child = failure = None
    interrupted = False
    try:
        rows = evidence(plan.base, plan.shown, second=False)
        if not quiet and console.is_terminal:
            from rich.live import Live

            live = Live(_table(rows, need, 0, plan.rate_hz), console=console)
            live.start()
        viewer = None
        if view or view_save is not None:
            from ..view.evidence import EvidenceView

            viewer = EvidenceView
        # The evidence is computed beside the recording, in a child process: the loop
        # only collects frames, so it keeps up with the source whatever the evidence
        # costs (or the view, which the same child logs).
        interrupts.hold()  # the child is ours to end once it exists: not half-made
        child = EvidenceProcess(
            plan.base, plan.name, plan.sensors, plan.shown, viewer=viewer, view_save=view_save
        )
        interrupts.release()

        def show(rows: list[JointEvidence], frames: int) -> None:
            if live is not None:
                live.update(_table(rows, need, frames, plan.rate_hz))

        blocks = the_source.blocks()
        if presses is not None:
            blocks = _marking(blocks, presses)
        interrupted = record(
            blocks, acc, child, plan.rate_hz, duration=duration, until_enough=until_enough,
            show=show,
        )  # fmt: skip
    except KeyboardInterrupt:  # before the loop began: nothing recorded
        interrupted = True
    except FingerfitError as exc:  # the source or the evidence process failed
        failure = exc
    finally:
        interrupts.hold()  # from here on a Ctrl-C waits until the files are written
        the_source.close()
        if live is not None:
            live.stop()
    rec = _trimmed(acc.recording(), duration, plan.rate_hz)
    final, rows = None, None
    try:
        if rec.n_frames == 0:
            if failure is not None:
                raise failure
            why = (
                "interrupted before any frame was recorded"
                if interrupted
                else "nothing was recorded"
            )
            raise FingerfitError(f"{why}; no file written", field="--source")
        _check_recorded(rec, plan)
        extra = _pinch_events(plan, rec, presses) if protocol in HOLD_PROTOCOLS else None
        toml = write_capture(plan, rec, extra)
        if failure is not None:
            raise FingerfitError(
                f"{failure} -- the {rec.n_frames} frames recorded before it are kept in "
                f"{plan.target}"
            )
        if child is not None and not child.has_view:
            child.close()
        try:
            interrupts.release()  # Ctrl-C now cuts the final evidence short
            rows = evidence(replace(plan.base, grasp=[*plan.base.grasp, rec]), plan.shown)
            final = (rows, rec.n_frames)
        except KeyboardInterrupt:
            rows = None
        interrupts.hold()
    finally:
        if child is not None:
            child.close(final)  # a view logs the final evidence and keeps its file with it
    if rows is not None:
        out.print(_table(rows, need, rec.n_frames, plan.rate_hz))
    say(
        "{} frames ({} s){} -> [bold]{}[/]; {} lists it",
        rec.n_frames,
        f"{rec.n_frames / plan.rate_hz:.1f}",
        " (interrupted)" if interrupted else "",
        plan.target,
        toml,
    )
    if rows is None:
        say("interrupted: the recording is kept; its evidence was not computed")
        if view_save is not None:
            say("no view file: it ends with the final evidence")
        return
    short = [r for r in rows if not r.enough]
    if short:
        say("not enough for `fingerfit fit` yet: {}", "; ".join(_shortfall(r, need) for r in short))
    else:
        say(
            "enough for every joint ({} cycles, {} deg median ROM, axis within +/-{} deg each)",
            need[0],
            f"{need[1]:g}",
            f"{need[2]:g}",
        )
    if view_save is not None:
        say("view -> [bold]{}[/]", view_save)
    if not (plan.folder / "landmarks.csv").is_file():
        notice("note", f"{plan.folder / 'landmarks.csv'} is missing: the fit needs it")


def _names(text: str | None) -> list[str]:
    """A comma-separated list of names (empty for None)."""
    return [t.strip() for t in (text or "").split(",") if t.strip()]


def _marking(blocks: Iterator, presses: list[float]) -> Iterator:
    """The source's blocks, each Enter press noted in ``presses`` as the time (s) of the
    last frame received before it."""
    from .capture_steps import enter_presses

    pressed = enter_presses()
    last = None
    for block in blocks:
        if block is not None and block.recording.n_frames:
            last = float(block.recording.time[-1])
        if pressed.is_set() and last is not None:
            pressed.clear()
            presses.append(last)
            say("hold {} at {} s", "start" if len(presses) % 2 else "end", f"{last:.2f}")
        yield block


def _pinch_events(
    plan: CapturePlan, rec: Recording, presses: list[float] | None = None
) -> dict[Path, bytes] | None:
    """``events.csv`` with the pinch recording's holds -- found from the pads, or marked
    by ``presses`` (``--trigger enter``) -- (the folder's other events kept, this
    recording's earlier ones replaced), listed in ``session.toml``; None when the folder
    has no pad landmarks to find them with (said)."""
    from ..capture.pinch import find_holds, marked_holds, pad_points

    pads = pad_points(plan.base.landmarks, plan.base.reference, plan.digits)
    if presses is not None:
        points = (
            pads
            if "thumb" in pads and len(pads) > 1
            else pad_points(plan.base.landmarks, plan.base.reference, plan.digits, "tip")
        )
        found, unpaired = marked_holds(rec, presses, points)
        if unpaired:
            notice("warning", "the last Enter press had no end: that hold is left out")
        return _events_file(plan, rec, found, set(points) - {"thumb"})
    if "thumb" not in pads or len(pads) < 2:
        if plan.protocol != "pinch":
            return None
        notice(
            "warning",
            "no holds marked: the pads are found from the <digit>.pad landmarks, which "
            f"{plan.folder / 'landmarks.csv'} lacks (capture --protocol landmarks --pads)",
        )
        return None
    return _events_file(plan, rec, find_holds(rec, pads, plan.rate_hz), set(pads) - {"thumb"})


def _events_file(
    plan: CapturePlan, rec: Recording, found: list, fingers: set[str]
) -> dict[Path, bytes]:
    """``events.csv``'s new content with ``found`` for ``rec`` (said per finger)."""
    from ..capture.folder import rendered
    from ..io.sessiondir import EVENTS_FILE, read_events, write_events

    path = plan.folder / EVENTS_FILE
    kept = [e for e in read_events(path) if e.recording != rec.name] if path.is_file() else []
    plan.meta["recordings"]["events"] = EVENTS_FILE
    by_digit = {d: sum(e.target == d for e in found) for d in plan.digits if d in fingers}
    say(
        "pad-to-pad holds found: {}",
        ", ".join(f"thumb-{d} {n}" for d, n in by_digit.items()) or "none",
    )
    return {path: rendered(EVENTS_FILE, lambda p: write_events(p, [*kept, *found]))}


def _trimmed(rec, duration: float | None, rate_hz: float):
    """The recording cut at ``duration`` seconds (the source's last block may run over)."""
    if duration is None:
        return rec
    return rec.slice(slice(0, min(rec.n_frames, math.ceil(duration * rate_hz))))


def _check_recorded(rec, plan: CapturePlan) -> None:
    """A device's recording without samples of a sensor is refused (not written)."""
    from ..capture import check_sensors

    check_sensors(rec, plan, plan.target)


def _shortfall(r: JointEvidence, need: tuple[int, float, float]) -> str:
    """What one joint lacks, in a few words."""
    parts = [f"{r.cycles} cycle(s)"]
    parts.append("ROM " + ("n/a" if math.isnan(r.rom_deg) else f"{r.rom_deg:.0f} deg"))
    if not math.isnan(r.axis_ci_deg):
        parts.append(f"axis +/-{r.axis_ci_deg:.1f} deg")
    if r.advice:
        parts.append(f"second axis not identified: {r.advice}")
    return f"{r.digit} {r.joint} ({', '.join(parts)})"


def _table(
    rows: list[JointEvidence], need: tuple[int, float, float], frames: int, rate_hz: float
) -> Table:
    """The evidence table (rich), one row per joint."""
    from rich.table import Table

    from ..capture import NUMERIC_COLUMNS, TABLE_COLUMNS, table_cells, table_title

    t = Table(title=table_title(need, frames, rate_hz), title_justify="left")
    for col in TABLE_COLUMNS:
        t.add_column(col, justify="right" if col in NUMERIC_COLUMNS else "left")
    for r in rows:
        t.add_row(*table_cells(r))
    return t
