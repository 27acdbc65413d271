"""``fingerfit fit`` and ``fingerfit angles``."""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

if TYPE_CHECKING:
    from ..model import HandModel
    from ..session import Recording
import typer
from rich.markup import escape
from rich.table import Table

from ._names import DEFAULT_METHOD, METHODS
from .app import Quiet, QuietTable, app, notice, out, parse_list, progress, say, user_errors

#: One line per column of the fit table (``docs/methods.md`` explains each figure).
TABLE_LEGEND = {
    "digit": "digit name",
    "joint": "mp, pip, dip; the thumb's cmc, mcp, ip (flexion joints, proximal to distal)",
    "cycles": "grasp cycles (movement periods) the joint was fitted from",
    "ROM° mean (min–max)": "range of motion per cycle, degrees: mean over cycles (smallest–largest)",
    "c→axis mm": "mean distance of the per-cycle centres of rotation to the fitted axis (paper Fig. 8)",
    "s5/s6": "median over cycles of the centre system's two smallest singular values' ratio: "
    "rotation about the axis over rotation off it (large = one clear hinge axis)",
    "vs cycles°": "angle between the fitted axis and the cycles' own rotation axis (SVD null vectors)",
    "axis ±°": "95 % confidence half-angle of the flexion axis from its spread over the cycles "
    "(delete-one-cycle jackknife; `fingerfit capture` asks for <= 9)",
    "bone mm": "segment length from this joint's centre to the next joint's centre (dip: to the tip)",
    "two axes": "the joint's second (ab/adduction) axis, when fitted: its angle to the flexion "
    "axis and its line's distance from the flexion axis's line (a two-axis joint's rows of "
    "'c→axis' and 's5/s6' are '–': it has no per-cycle centres)",
}


#: One line per column of the fit table of a model fitted from markers (a bundle
#: adjustment over every frame: no grasp cycles, so none of the cycles' figures).
MARKER_LEGEND = {
    "digit": "digit name",
    "joint": "each axis, proximal to distal: the flexion joints and a two-axis joint's "
    "<joint>_abduction",
    "ROM°": "range of the axis's angle over the fitted frames, degrees",
    "residual mm": "RMS marker residual per coordinate of the digit's adjustment (the "
    "camera noise and skin slide it could not explain)",
    "axis SD°": "largest standard deviation of the axis direction (the camera noise's and "
    "the skin slide's, docs/markers.md)",
    "axis ±°": "95 % half-angle of the axis direction (the largest angle of its 95 % region)",
    "bone mm": "segment length from this joint's centre to the next joint's centre (dip: to "
    "the tip)",
}


def _table(model: HandModel, legend: dict[str, str]) -> Table:
    """An empty fit table titled with the model's subject, method and two-axis joints,
    its caption a line per column of ``legend`` (digit and joint left out)."""
    two = sorted({f"{j.upper()}" for fm in model.fingers.values() for j in fm.second_axes})
    t = Table(
        title=f"{escape(model.subject)}: method {escape(model.method)}"
        + (f", two-axis {', '.join(two)}" if two else ""),
        title_justify="left",
        caption="\n".join(f"{k}: {v}" for k, v in legend.items() if k not in ("digit", "joint")),
        caption_justify="left",
    )
    for c in legend:
        t.add_column(c, justify="left" if c in ("digit", "joint") else "right")
    return t


def quality_table(model: HandModel) -> Table:
    """Per joint: cycles, range of motion, centre-to-axis distance, conditioning, bone
    length; of a model fitted from markers, :func:`marker_quality_table`.

    The caption is a one-line legend per column (:data:`TABLE_LEGEND`).
    """
    import numpy as np

    from ..transforms import angle_between_axes, distance_between_lines

    if model.markers:
        return marker_quality_table(model)
    t = _table(model, TABLE_LEGEND)
    for f, fm in model.fingers.items():
        for (j, jm), length in zip(fm.joints.items(), fm.segment_lengths.values(), strict=True):
            q = jm.quality
            rom = np.array(q.rom_deg)
            ab = fm.second_axes.get(j)
            if ab is None:
                two_axes = "–"
            else:
                gap = distance_between_lines(jm.center, jm.axis, ab.center, ab.axis)
                angle = np.degrees(angle_between_axes(jm.axis, ab.axis))
                two_axes = f"{angle:.0f}°, {gap:.1f} mm"
            t.add_row(
                f,
                j,
                str(q.cycles),
                f"{rom.mean():.0f} ({rom.min():.0f}–{rom.max():.0f})" if rom.size else "–",
                f"{np.mean(q.centre_distance_mm):.2f}" if q.centre_distance_mm else "–",
                f"{np.median(q.conditioning):.0f}" if q.conditioning else "–",
                f"{q.null_agreement_deg:.1f}",
                "–" if q.axis_ci_deg is None else f"{q.axis_ci_deg:.1f}",
                f"{length:.1f}",
                two_axes,
            )
    return t


def marker_quality_table(model: HandModel) -> Table:
    """Per axis of a model fitted from markers: range of motion, the digit's marker
    residual, the axis direction's SD and 95 % half-angle, bone length
    (:data:`MARKER_LEGEND`; the adjustment's :class:`~fingerfit.model.JointQuality`:
    ``rom_deg``, ``residual_mm``, ``axis_ci_deg``).

    An axis the markers did not determine (its direction's covariance infinite) shows
    ``–`` for its SD and half-angle.
    """
    import math

    from ..estimate.markers.fit import CHI2_95

    t = _table(model, MARKER_LEGEND)
    for f, fm in model.fingers.items():
        for (j, jm), length in zip(fm.joints.items(), fm.segment_lengths.values(), strict=True):
            for axis, bone in ((jm, f"{length:.1f}"), (fm.second_axes.get(j), "–")):
                if axis is None:
                    continue
                q = axis.quality
                ci = q.axis_ci_deg
                t.add_row(
                    f,
                    axis.name,
                    f"{max(q.rom_deg):.0f}" if q.rom_deg else "–",
                    f"{max(q.residual_mm):.2f}" if q.residual_mm else "–",
                    "–" if ci is None else f"{ci / math.sqrt(CHI2_95):.2f}",
                    "–" if ci is None else f"{ci:.1f}",
                    bone,
                )
    return t


def read_checked_recording(
    model: HandModel,
    path: Path,
    units: str,
    rate: float | None,
    force: bool,
    sensors: list[str] | None = None,
) -> Recording:
    """A pose CSV read for a model (``angles``, ``stream --source replay:``): its repair
    notes shown, ``sensors`` kept (``--sensors``; all when None), then checked against the
    model -- a wrong ``--units`` or quaternion order, or another subject's recording, gives
    wrong angles without complaint (:mod:`fingerfit.estimate.plausibility`); ``force`` goes
    on with warnings."""
    from ..estimate.plausibility import check_recording, enforce
    from ..io import read_pose_csv
    from ..track import select_sensors

    rec = select_sensors(read_pose_csv(path, units=units, rate_hz=rate), sensors)
    for note in rec.notes:
        notice("note", note)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        enforce(check_recording(model, rec, units, path), force)
    for w in caught:
        notice("warning", str(w.message))
    return rec


def is_marker_input(model: HandModel, model_path: Path, recording: Path) -> bool:
    """Whether ``recording`` is a marker recording (``.trc``, ``.tsv``, ``.c3d``) for a
    model fitted from markers (``angles``, ``view``, ``retarget``), else a pose recording
    for a 6-DOF model; the other kind refused in one line naming the file and the model."""
    from ..errors import FingerfitError
    from ..io.markers import MARKER_SUFFIXES, is_marker_file

    markers = is_marker_file(recording)
    if markers and not model.markers:
        raise FingerfitError(
            f"is a marker recording, but {model_path} was fitted from 6-DOF sensors and "
            "takes pose recordings (fit a model from a marker session: docs/markers.md)",
            path=recording,
        )
    if model.markers and not markers:
        raise FingerfitError(
            f"is not a marker recording ({', '.join(MARKER_SUFFIXES)}), but {model_path} "
            "was fitted from markers and takes recordings of its markers",
            path=recording,
        )
    return markers


def read_marker_input(
    model: HandModel, path: Path, units: str | None, quiet: bool = False
) -> Recording:
    """A marker recording read for a model fitted from markers: its notes (gaps counted)
    shown unless ``quiet``, every marker of the model present (else one line naming the
    marker and the file). ``units`` overrides the file's own (``--units``; None: the
    file's)."""
    from ..io.markers import read_marker_recording
    from ..live.markers import check_marker_source

    rec = read_marker_recording(path, units=units)
    for note in rec.notes if not quiet else []:
        notice("note", note)
    check_marker_source(model, set(rec.markers), str(path), "recording")
    return rec


def check_solved(tracked, path: Path, force: bool) -> None:
    """The frames the model solved, checked against it (the residual of its solution: the
    pivot check of a reduced layout, :func:`fingerfit.estimate.plausibility.check_tracking`);
    ``force`` goes on with a warning."""
    from ..estimate.plausibility import check_tracking, enforce

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        enforce(check_tracking(tracked, path), force)
    for w in caught:
        notice("warning", str(w.message))


@app.command()
@user_errors
def fit(
    session: Annotated[Path, typer.Argument(help="Session directory (fingerfit.session/1).")],
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="Model JSON (default: SESSION/model.json)."),
    ] = None,
    method: Annotated[
        str,
        typer.Option(
            help=f"Axis estimator: {', '.join(METHODS)} (docs/methods.md; tang2018 = the paper)."
        ),
    ] = DEFAULT_METHOD,
    fingers: Annotated[
        str | None,
        typer.Option(
            help="Comma-separated digits: thumb, index, middle, ring, little (default: all)."
        ),
    ] = None,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="Fit joints the motion cannot determine and data that fail the plausibility "
            "checks (units, quaternion order); the warnings are stored in the model file.",
        ),
    ] = False,
    jobs: Annotated[
        int,
        typer.Option(
            "--jobs",
            "-j",
            min=1,
            help="Cores for a marker session's fit: its digits in worker processes side by "
            "side, and a digit's frames in threads when the digits are fewer.",
        ),
    ] = 1,
    mp_axes: Annotated[
        str,
        typer.Option(
            "--mp-axes",
            help="A marker session's finger MP and thumb MCP: auto (a second axis when the "
            "markers call for it), hinge or two (docs/markers.md).",
        ),
    ] = "auto",
    slide: Annotated[
        bool,
        typer.Option(
            "--slide",
            help="A marker session: estimate each marker's skin slide with the joint below "
            "it (slower; docs/markers.md measures what it gains and costs).",
        ),
    ] = False,
    quiet: QuietTable = False,
) -> None:
    """Fit the individual finger model of a session: joint centres, axes, lengths, frames."""
    from ..digits import DIGIT_NAMES as FINGERS
    from ..estimate import FitOptions, fit_session
    from ..estimate.fit import METHODS
    from ..estimate.markers.fit import MP_AXES
    from ..io import load_session
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..model import save_model

    if method not in METHODS:
        raise typer.BadParameter(f"must be one of {', '.join(METHODS)}", param_hint="--method")
    if mp_axes not in MP_AXES:
        raise typer.BadParameter("must be auto, hinge or two", param_hint="--mp-axes")
    names = parse_list(fingers, FINGERS, "--fingers")
    with progress(quiet) as bar:
        task = bar.add_task(f"reading {session}", total=2)
        s = load_session(session, test=False)  # the fit does not use the test recordings
        target = output or session / "model.json"
        refuse_writing_inputs([target], s.files)
        check_target(target)
        for note in (n for r in s.recordings() for n in r.notes):
            notice("note", note)
        n_fingers = len(names or s.fingers)
        if s.marker_map:
            model = _fit_markers(s, names, bar, task, jobs, mp_axes, slide)
            path = save_model(model, target)
            if not quiet:
                out.print(quality_table(model))
            say("model written to [bold]{}[/]", path)
            return
        if jobs > 1:
            raise typer.BadParameter(
                "only a marker session's digits are fitted in worker processes",
                param_hint="--jobs",
            )
        if mp_axes != "auto":
            raise typer.BadParameter(
                "only for a marker session (a 6-DOF session's MP axes: --method)",
                param_hint="--mp-axes",
            )
        if slide:
            raise typer.BadParameter(
                "only for a marker session (a 6-DOF session's sensors are fitted as rigid)",
                param_hint="--slide",
            )
        bar.update(task, advance=1, description=f"fitting {n_fingers} digit(s) ({method})")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = fit_session(
                s, FitOptions(method=method, force=force, fingers=tuple(names) if names else None)
            )
        bar.advance(task)
    for w in caught:
        notice("warning", str(w.message))
    if model.warnings:
        notice("warning", f"{len(model.warnings)} warning(s) stored in the model file")
    path = save_model(model, target)
    if not quiet:
        out.print(quality_table(model))
    say("model written to [bold]{}[/]", path)


def _fit_markers(
    session,
    names: list[str] | None,
    bar,
    task,
    jobs: int = 1,
    mp_axes: str = "auto",
    slide: bool = False,
):
    """The marker fit of a marker session (:mod:`fingerfit.estimate.markers`) on ``jobs``
    cores (its digits in up to ``jobs`` worker processes, the cores left over threads of
    each digit's adjustment), its notes shown one per line."""
    import dataclasses

    from ..estimate.markers.fit import fit_marker_session
    from ..evaluate.study import study_executor

    if names:
        session = dataclasses.replace(session, fingers=[d for d in session.fingers if d in names])
    bar.update(task, advance=1, description=f"fitting {len(session.fingers)} digit(s) (markers)")
    workers = max(1, min(jobs, len(session.fingers)))
    with study_executor(workers) as pool:
        result = fit_marker_session(
            session,
            mp_axes=mp_axes,
            slide=slide,
            executor=pool,
            threads=max(1, jobs // workers),
        )
    bar.advance(task)
    for note in result.notes:
        notice("note", note)
    return result.model


def _marker_angles(model, recording: Path, output: Path, quiet: bool) -> None:
    """``fingerfit angles`` of a marker recording with a model fitted from markers."""
    from ..estimate.markers.angles import angles_table, marker_angles
    from ..io.atomic import atomic_write

    rec = read_marker_input(model, recording, None, quiet)
    result = marker_angles(model, rec)
    for d, a in result.items():
        if a.unconverged:
            notice(
                "warning",
                f"{d}: {a.unconverged} frames unconverged (their angles the last iterate's)",
            )
    table = angles_table(rec.time, result)
    with atomic_write(output, newline="") as fh:
        table.to_csv(fh, index=False, lineterminator="\n")
    rms = ", ".join(f"{d} {a.rms_mm:.2f} mm" for d, a in result.items())
    say(
        "{} frames -> {} (angles deg, fingertips mm, tracker frame); marker residual {}",
        rec.n_frames,
        output,
        rms,
    )


@app.command()
@user_errors
def angles(
    model_path: Annotated[
        Path, typer.Argument(metavar="MODEL", help="Model JSON from `fingerfit fit`.")
    ],
    recording: Annotated[
        Path, typer.Argument(help="Pose CSV (canonical format), or its .parquet form.")
    ],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="Angles CSV to write (.parquet: Parquet; .mot: OpenSim motion of the "
            "exported .osim).",
        ),
    ],
    units: Annotated[
        str | None,
        typer.Option(help="Units of the recording (default: the model's session units)."),
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(help="Sampling rate (Hz) to keep dropped frames visible as empty rows."),
    ] = None,
    urdf_names: Annotated[
        Path | None,
        typer.Option(
            "--urdf-names",
            help="Also write the joint-angle trajectory (rad, URDF joint names, user-axis "
            "model; .parquet: Parquet).",
        ),
    ] = None,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="Compute angles even when the recording does not fit the model (units, "
            "quaternion order, sensors), with a warning.",
        ),
    ] = False,
    sensors: Annotated[
        str | None,
        typer.Option(
            help="Use only these sensors of the recording (comma-separated, e.g. "
            "hand,index.distal): try a reduced layout on a full recording (docs/tracking.md).",
        ),
    ] = None,
    fingers: Annotated[
        str | None,
        typer.Option(help="Comma-separated digits to compute (default: every digit of the model)."),
    ] = None,
    uncertainty: Annotated[
        bool,
        typer.Option(
            "--uncertainty",
            help="Also write each angle's standard deviation where the model solved the "
            "frame (<digit>.<joint>.sd, deg).",
        ),
    ] = False,
    quiet: Quiet = False,
) -> None:
    """Joint angles (deg) and fingertips of every frame, user-axis and orthogonal models.

    A frame with a digit's sensor missing (absent from the recording, a dropout, or left
    out with --sensors) is solved by the model: docs/tracking.md.
    """
    from ..digits import DIGIT_NAMES
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..io.parquet import angles_meta, write_table_file
    from ..kinematics import kinematics_table
    from ..model import load_model
    from ..session import UNITS_TO_MM
    from ..track import check_layout, track_recording
    from ..track.report import tracking_columns, tracking_lines

    outputs = [output] if urdf_names is None else [output, urdf_names]
    refuse_writing_inputs(outputs, [model_path, recording])
    for target in outputs:
        check_target(target)
    model = load_model(model_path)
    units = units or model.session_units
    if units not in UNITS_TO_MM:
        raise typer.BadParameter(f"must be one of {', '.join(UNITS_TO_MM)}", param_hint="--units")
    names = parse_list(fingers, DIGIT_NAMES, "--fingers")
    for d in names or []:
        if d not in model.fingers:
            raise typer.BadParameter(
                f"the model has no '{d}' (has: {', '.join(model.fingers)})", param_hint="--fingers"
            )
    if is_marker_input(model, model_path, recording):
        _marker_angles(model, recording, output, quiet)
        return
    chosen = None if sensors is None else [x.strip() for x in sensors.split(",") if x.strip()]
    rec = read_checked_recording(model, recording, units, rate, force, chosen)
    with progress(quiet) as bar:
        n = rec.n_frames
        task = bar.add_task("angles and fingertips", total=n + n)
        check_layout(
            model, set(rec.poses), names or list(model.fingers), str(recording), skip="--fingers"
        )
        tracked = track_recording(model, rec, fingers=names)
        check_solved(tracked, recording, force)
        kin = tracked.kinematics
        if output.suffix.lower() == ".mot":  # every coordinate of `export --osim`
            from ..export.trajectory import write_coordinates

            write_coordinates(output, kin, model, rec)
        else:
            table = kinematics_table(kin, units=units)
            extra = tracking_columns(tracked, uncertainty)
            if extra:
                import pandas as pd

                table = pd.concat([table, pd.DataFrame(extra)], axis=1)
            bar.update(task, advance=n, description=f"writing {output.name}")
            # Atomic, in batches of rows (progress bar): CSV floats in shortest round-trip
            # form, or Parquet (OUT.parquet) float64 with the units in its metadata.
            write_table_file(
                output, table, angles_meta(units), progress=lambda rows: bar.advance(task, rows)
            )
    if urdf_names is not None:
        from ..export.trajectory import write_trajectory

        say("joint trajectory (rad) -> [bold]{}[/]", write_trajectory(urdf_names, kin, model))
    say(
        "{} frames -> [bold]{}[/] ({})",
        rec.n_frames,
        output,
        "OpenSim coordinates: deg, hand translations m, tracker frame"
        if output.suffix.lower() == ".mot"
        else f"angles deg, fingertips {units}, tracker frame",
    )
    for line in tracking_lines(tracked):
        say("{}", line)
