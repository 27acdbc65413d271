"""``fingerfit capture``: record a protocol into a session folder, guided by the fit's needs."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from ..errors import FingerfitError, shown
from .app import Quiet, app, console, notice, out, say, user_errors

if TYPE_CHECKING:
    from rich.table import Table

    from ..capture import JointEvidence

PROTOCOLS = ("grasp", "thumb")  # fingerfit.capture.PROTOCOLS (without importing NumPy)


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
        str, typer.Option(help=f"The recording to take: {', '.join(PROTOCOLS)}.")
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
        str | None, typer.Option(help="Subject id, for a folder without session.toml.")
    ] = None,
    hand: Annotated[str, typer.Option(help="left or right (without session.toml).")] = "left",
    units: Annotated[str, typer.Option(help="Units of x,y,z (without session.toml).")] = "mm",
    rate: Annotated[
        float, typer.Option(min=1e-6, help="Sampling rate, Hz (without session.toml).")
    ] = 240.0,
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
            "reference.csv (a new folder)."
        ),
    ] = None,
    landmarks: Annotated[
        Path | None,
        typer.Option(help="Landmarks CSV to copy into the folder as landmarks.csv."),
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
    quiet: Quiet = False,
) -> None:
    """Record a protocol (grasp, thumb) into a session folder, showing per joint the
    cycles, range of motion, axis confidence and second axis found so far (over every
    calibration recording of the folder) and when each has enough for `fingerfit fit`."""
    from dataclasses import replace

    from ..capture import PROTOCOLS as PLAN
    from ..capture import RECORDING_LIST, Accumulator, EvidenceProcess, evidence, thresholds
    from ..io import read_pose_csv
    from ..io.atomic import check_target
    from ..io.posewrite import write_pose_csv
    from ..io.sessiondir import read_landmarks
    from ..live import sources as src
    from ..session import Session, digit_sensors

    if protocol not in PROTOCOLS:
        raise FingerfitError(f"must be one of {', '.join(PROTOCOLS)}", field="--protocol")
    from .stream import check_view

    check_view(view, view_save, None)
    meta = _meta(session_dir, subject, hand, units, rate, fingers)
    listed = meta["recordings"].get(RECORDING_LIST, [])
    listed = [listed] if isinstance(listed, str) else list(listed)
    if name is None:
        todo = [f for f in PLAN[protocol][1] if f not in listed and not (session_dir / f).exists()]
        if not todo:
            raise FingerfitError(
                f"the folder has {' and '.join(PLAN[protocol][1])}: give --name", field="--name"
            )
        name = todo[0]
    if "/" in name or "\\" in name or not name.endswith(".csv") or name.startswith("."):
        raise FingerfitError("must be a file name ending in .csv", field="--name")
    target = session_dir / name
    copies = {}
    for given, file in ((reference, meta["recordings"]["reference"]), (landmarks, "landmarks.csv")):
        if given is not None:
            if not given.is_file():
                raise FingerfitError("no such file", path=given)
            check_target(session_dir / file, overwrite=overwrite)
            copies[session_dir / file] = given.read_bytes()
    if copies:
        from ..io.atomic import write_files

        write_files(copies, overwrite=overwrite)
    if name == meta["recordings"]["reference"]:
        raise FingerfitError("names the reference recording", field="--name")
    check_target(target, overwrite=overwrite)
    reference = read_pose_csv(
        session_dir / meta["recordings"]["reference"], units=meta["units"], rate_hz=meta["rate_hz"]
    )
    digits = meta["fingers"] or [
        d
        for d in ("thumb", "index", "middle", "ring", "little")
        if all(s in reference.poses for s in digit_sensors(d))
    ]
    if not digits:
        raise FingerfitError(
            "the reference recording has the sensors of no digit",
            path=session_dir / meta["recordings"]["reference"],
        )
    meta["fingers"] = digits
    shown_digits = [d for d in digits if d in (PLAN[protocol][0] or digits)]
    if not shown_digits:
        raise FingerfitError(
            f"protocol '{protocol}' is for the {', '.join(PLAN[protocol][0] or ())}, which "
            "the session does not have",
            field="--protocol",
        )
    # What the fit will pool with the new recording: the folder's calibration recordings
    # (the one being replaced left out) and its landmarks when it has them.
    prior = [
        read_pose_csv(session_dir / f, units=meta["units"], rate_hz=meta["rate_hz"])
        for f in listed
        if f != name
    ]
    lm_path = session_dir / "landmarks.csv"
    lm = read_landmarks(lm_path, units=meta["units"]) if lm_path.is_file() else {}

    base = Session(
        str(meta.get("subject", session_dir.name)),
        str(meta.get("hand", "left")),
        "mm",
        meta["rate_hz"],
        digits,
        reference,
        prior,
        lm,
    )

    sensors = list(dict.fromkeys(s for d in digits for s in digit_sensors(d)))
    kind = src.split_spec(source)[0]
    if kind == "replay":
        path, speed = src.parse_replay(source)
        the_source = src.ReplaySource(
            read_pose_csv(path, units=meta["units"], rate_hz=meta["rate_hz"]), speed
        )
    elif kind == "liberty":
        port, baud = src.parse_liberty(source)
        mapping = (
            src.parse_stations(stations, sensors) if stations else src.default_stations(sensors)
        )
        the_source = src.LibertySource(port, baud, mapping, meta["rate_hz"])
    elif kind == "lsl":
        the_source = src.LslSource(src.split_spec(source)[1], sensors)
    else:
        raise FingerfitError(
            f"unknown source '{shown(source)}': replay:FILE, liberty:PORT or lsl:NAME",
            field="--source",
        )
    need = thresholds()
    acc = Accumulator(name, sensors)
    rows = evidence(base, shown_digits, second=False)
    live = None
    if not quiet and console.is_terminal:
        from rich.live import Live

        live = Live(_table(rows, need, 0, meta["rate_hz"]), console=console)
        live.start()
    interrupted = False
    # The evidence is computed beside the recording, in a child process: the loop only
    # collects frames, so it keeps up with the source whatever the evidence costs (or
    # the view, which the same child logs).
    try:
        viewer = None
        if view or view_save is not None:
            from ..view.evidence import EvidenceView

            viewer = EvidenceView
        child = EvidenceProcess(
            base, name, sensors, shown_digits, viewer=viewer, view_save=view_save
        )
    except BaseException:
        the_source.close()
        if live is not None:
            live.stop()
        raise
    final = None
    try:
        try:
            for block in the_source.blocks():
                if block is not None:
                    acc.add(block.recording)
                    child.add(block.recording)
                seconds = acc.n_frames / meta["rate_hz"]
                done = duration is not None and seconds >= duration
                result = child.latest()
                if result is not None:
                    rows, frames = result
                    if live is not None:
                        live.update(_table(rows, need, frames, meta["rate_hz"]))
                    if until_enough and all(r.enough for r in rows):
                        break
                if done:
                    break
        except KeyboardInterrupt:
            interrupted = True  # stop recording; what was recorded is kept
        finally:
            the_source.close()
            if not child.has_view:
                child.close()
            if live is not None:
                live.stop()
        rec = acc.recording()
        if duration is not None:
            rec = rec.slice(slice(0, min(rec.n_frames, math.ceil(duration * meta["rate_hz"]))))
        if rec.n_frames == 0:
            raise FingerfitError("nothing was recorded; no file written", field="--source")
        rows = evidence(replace(base, grasp=[*prior, rec]), shown_digits)
        final = (rows, rec.n_frames)
    finally:
        if child.has_view:
            child.close(final)  # the view logs the final evidence and closes its file
    out.print(_table(rows, need, rec.n_frames, meta["rate_hz"]))
    write_pose_csv(target, rec, units=meta["units"])
    toml = _write_meta(session_dir, meta, name, RECORDING_LIST)
    say(
        "{} frames ({} s){} -> [bold]{}[/]; {} lists it",
        rec.n_frames,
        f"{rec.n_frames / meta['rate_hz']:.1f}",
        " (interrupted)" if interrupted else "",
        target,
        toml,
    )
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
    if not (session_dir / "landmarks.csv").is_file():
        notice("note", f"{session_dir / 'landmarks.csv'} is missing: the fit needs it")


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


def _meta(
    folder: Path, subject: str | None, hand: str, units: str, rate: float, fingers: str | None
) -> dict:
    """The folder's ``session.toml`` (read as TOML), or one made of the options."""
    import tomllib

    from ..session import UNITS_TO_MM, check_subject_id
    from .app import parse_list

    path = folder / "session.toml"
    if path.is_file():
        try:
            meta = tomllib.loads(path.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise FingerfitError(f"invalid TOML ({exc})", path=path) from None
        for key in ("units", "rate_hz", "fingers", "recordings"):
            if key not in meta:
                raise FingerfitError(f"missing '{key}'", path=path, field=key)
        if meta["units"] not in UNITS_TO_MM:
            raise FingerfitError(
                f"must be one of {', '.join(UNITS_TO_MM)}", path=path, field="units"
            )
        meta["rate_hz"] = float(meta["rate_hz"])
        meta["recordings"].setdefault("reference", "reference.csv")
        return meta
    if subject is None:
        raise FingerfitError(
            f"{folder} has no session.toml: give --subject (and --hand, --units, --rate, "
            "--fingers) to start one",
            field="--subject",
        )
    check_subject_id(subject)
    if hand not in ("left", "right"):
        raise FingerfitError("must be left or right", field="--hand")
    if units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--units")
    digits = parse_list(fingers, ("thumb", "index", "middle", "ring", "little"), "--fingers")
    return {
        "format": "fingerfit.session/1",
        "subject": subject,
        "hand": hand,
        "units": units,
        "rate_hz": float(rate),
        "fingers": digits or [],
        "recordings": {"reference": "reference.csv", "grasp": []},
    }


def _write_meta(folder: Path, meta: dict, name: str, protocol: str) -> Path:
    """``session.toml`` with the new recording listed under ``protocol``, a key of
    ``[recordings]`` (atomically)."""
    from ..io.atomic import atomic_write

    recs = dict(meta["recordings"])
    listed = recs.get(protocol, [])
    listed = [listed] if isinstance(listed, str) else list(listed)
    if name not in listed:
        listed.append(name)
    recs[protocol] = listed
    lines = [
        f"format = {json.dumps(meta.get('format', 'fingerfit.session/1'))}",
        f"subject = {json.dumps(meta.get('subject', folder.name))}",
        f"hand = {json.dumps(meta.get('hand', 'left'))}",
        f"units = {json.dumps(meta['units'])}",
        f"rate_hz = {float(meta['rate_hz'])!r}",
        f"fingers = {json.dumps(list(meta['fingers']))}",
        "",
        "[recordings]",
    ]
    for key in ("reference", "grasp", "targets", "test", "events"):
        if key in recs:
            lines.append(f"{key} = {json.dumps(recs[key])}")
    path = folder / "session.toml"
    with atomic_write(path) as fh:
        fh.write("\n".join(lines) + "\n")
    return path
