"""``fingerfit session``: assemble a session directory from canonical recordings and
landmarks, or from marker recordings and their marker map."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Annotated

import typer

from ..errors import FingerfitError
from .app import Quiet, app, notice, parse_list, progress, say, user_errors


@app.command()
@user_errors
def session(
    out_dir: Annotated[Path, typer.Argument(help="Session directory to create (must not exist).")],
    subject: Annotated[str, typer.Option(help="Subject identifier.")],
    reference: Annotated[
        Path,
        typer.Option(
            help="Static reference recording (pose CSV or .parquet; with --markers a marker file)."
        ),
    ],
    grasp: Annotated[list[Path], typer.Option(help="Grasp recording(s); repeat the option.")],
    landmarks: Annotated[
        Path | None,
        typer.Option(help="Stylus landmarks CSV (name,x,y,z); optional with --markers."),
    ] = None,
    markers: Annotated[
        Path | None,
        typer.Option(
            help="Marker map (TOML: [markers] segment = [labels]); the recordings are then "
            "marker files (.trc, .tsv, .c3d)."
        ),
    ] = None,
    hand: Annotated[str, typer.Option(help="left or right.")] = "left",
    units: Annotated[
        str,
        typer.Option(
            help="Units of every x,y,z given (marker files are read in the units they state)."
        ),
    ] = "mm",
    rate: Annotated[float, typer.Option(min=1e-6, help="Sampling rate (Hz).")] = 240.0,
    fingers: Annotated[str, typer.Option(help="Comma-separated fingers.")] = "index",
    targets: Annotated[
        list[Path] | None, typer.Option(help="Target-reaching recording(s).")
    ] = None,
    test: Annotated[list[Path] | None, typer.Option(help="Free-motion test recording(s).")] = None,
    events: Annotated[Path | None, typer.Option(help="Touch events CSV.")] = None,
    quiet: Quiet = False,
) -> None:
    """Build a fingerfit.session/1 directory from pose CSVs or their .parquet form (e.g.
    from `fingerfit convert`), or, with --markers, from marker recordings (TRC, Qualisys
    TSV, C3D) and their marker map.

    Every file is read and checked first; the directory is written only if all are valid,
    and then loaded back and validated as a whole (sensors or mapped markers of every
    finger, landmarks).
    """
    from ..digits import DIGIT_NAMES as FINGERS
    from ..io import load_session, read_pose_csv
    from ..io.atomic import staged_directory
    from ..io.markers import is_marker_file, read_marker_recording
    from ..io.markers.markermap import MAP_FILE, read_marker_map
    from ..io.markers.session import check_marker_session
    from ..io.sessiondir import (
        EVENTS_FILE,
        LANDMARKS_FILE,
        SESSION_FILE,
        read_events,
        read_landmarks,
        write_session_toml,
    )
    from ..session import UNITS_TO_MM, Session, check_subject_id

    if hand not in ("left", "right"):
        raise typer.BadParameter("must be left or right", param_hint="--hand")
    if units not in UNITS_TO_MM:
        raise typer.BadParameter(f"must be one of {', '.join(UNITS_TO_MM)}", param_hint="--units")
    check_subject_id(subject, field="--subject")
    if out_dir.exists():
        raise FingerfitError("already exists; choose a new directory", path=out_dir)
    names = parse_list(fingers, FINGERS, "--fingers") or []
    if landmarks is None and markers is None:
        raise FingerfitError("needed (stylus landmarks CSV) unless --markers", field="--landmarks")
    marker_map = read_marker_map(markers) if markers is not None else {}

    n_files = 1 + len(grasp) + len(targets or []) + len(test or [])
    with progress(quiet) as bar:
        task = bar.add_task("reading recordings", total=n_files + 1)

        def read(paths: list[Path] | None) -> list:
            recs = []
            for p in paths or []:
                bar.update(task, description=f"reading {p.name}")
                if markers is not None:
                    recs.append(read_marker_recording(p))  # in the units the file states
                elif is_marker_file(p):
                    raise FingerfitError(
                        "is a marker recording: give its marker map (--markers)", path=p
                    )
                else:
                    recs.append(read_pose_csv(p, units=units, rate_hz=rate))
                bar.advance(task)
            return recs

        s = Session(
            subject=subject,
            hand=hand,
            units=units,
            rate_hz=rate,
            fingers=names,
            reference=read([reference])[0],
            grasp=read(grasp),
            landmarks=read_landmarks(landmarks, units) if landmarks is not None else {},
            targets=read(targets),
            test=read(test),
            events=read_events(events) if events else [],
            marker_map=marker_map,
        )
        names_used = [r.name for r in s.recordings()]
        reserved = {LANDMARKS_FILE, EVENTS_FILE, MAP_FILE, SESSION_FILE}
        if len(set(names_used)) != len(names_used) or reserved & set(names_used):
            raise FingerfitError(
                f"recordings need distinct file names (not {', '.join(sorted(reserved))})"
            )
        for rec in s.recordings():
            for note in rec.notes:
                notice("note", f"{rec.name}: {note}")
        sources = [reference, *grasp, *(targets or []), *(test or [])]
        if markers is not None:  # checked against the files given, named in messages
            check_marker_session(s, markers, {p.name: p for p in sources})
        # Copy the checked files byte for byte, write session.toml, validate the whole
        # session, and only then let the directory appear (errors name OUT_DIR, not the
        # staging folder).
        bar.update(task, description="writing and checking the session")
        with staged_directory(out_dir) as tmp:
            for src in sources:
                shutil.copyfile(src, tmp / src.name)
            if landmarks is not None:
                shutil.copyfile(landmarks, tmp / LANDMARKS_FILE)
            if markers is not None:
                shutil.copyfile(markers, tmp / MAP_FILE)
            if events:
                shutil.copyfile(events, tmp / EVENTS_FILE)
            write_session_toml(s, tmp)
            load_session(tmp, parsed=s)  # the files read above are not parsed again
        bar.advance(task)
    say("session written to [bold]{}[/]", out_dir)
