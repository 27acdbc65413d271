"""``fingerfit stream``: a person's fitted hand, live, to LSL, ROS 2 and files."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ._names import DEFAULT_MAX_AGE_MS, DEFAULT_RECONNECT_S, DEFAULT_SILENCE_MS
from .app import app, notice, say, user_errors
from .retarget import (
    DEFAULT_CONTACT_MM,
    ContactOption,
    MapOption,
    MethodOption,
    OrthogonalOption,
    check_orthogonal,
    check_robot_options,
    resolve_robot,
)


@app.command()
@user_errors
def stream(
    model_path: Annotated[
        Path, typer.Argument(metavar="MODEL", help="Model JSON from `fingerfit fit`.")
    ],
    source: Annotated[
        str,
        typer.Option(
            "--source",
            help="replay:FILE\\[@SPEED] (a pose CSV, SPEED times real time; with a model "
            "fitted from markers a .trc/.tsv/.c3d), liberty:PORT\\[@BAUD] (a Polhemus "
            "Liberty) or lsl:NAME (an LSL MoCap stream of poses, or of markers).",
        ),
    ],
    lsl: Annotated[
        bool, typer.Option("--lsl", help="LSL outlets PREFIX-angles (deg) and PREFIX-tips (mm).")
    ] = False,
    lsl_name: Annotated[
        str, typer.Option("--lsl-name", help="LSL stream name prefix.")
    ] = "fingerfit",
    ros2: Annotated[
        str | None,
        typer.Option(
            "--ros2",
            metavar="TOPIC",
            help="Publish sensor_msgs/JointState (rad) on this ROS 2 topic over DDS "
            "(domain ROS_DOMAIN_ID).",
        ),
    ] = None,
    ros2_bag: Annotated[
        Path | None,
        typer.Option(
            "--ros2-bag", help="Write the JointState messages to this rosbag2 folder (new)."
        ),
    ] = None,
    record: Annotated[
        Path | None,
        typer.Option(
            "--record",
            help="Write the angles CSV `fingerfit angles` writes (.parquet: Parquet, "
            "appended a row group per block).",
        ),
    ] = None,
    view: Annotated[
        bool,
        typer.Option(
            "--view",
            help="Show the hand live in the Rerun viewer (as `fingerfit view`; a display "
            "is needed), fed by the data lane, never by the robot lane.",
        ),
    ] = False,
    view_save: Annotated[
        Path | None,
        typer.Option(
            "--view-save",
            metavar="OUT.rrd",
            help="Write the live view to this Rerun file instead of a window (complete "
            "when the stream ends).",
        ),
    ] = None,
    tips_frame: Annotated[
        str, typer.Option("--tips-frame", help="LSL fingertips in the tracker or hand frame.")
    ] = "tracker",
    units: Annotated[
        str | None,
        typer.Option(help="Units of a replayed recording (default: the model's session units)."),
    ] = None,
    rate: Annotated[
        float | None,
        typer.Option(
            min=1e-6,
            help="Replay: sampling rate to keep dropped frames as rows (as `angles`); "
            "liberty: the device rate (default 240 Hz).",
        ),
    ] = None,
    stations: Annotated[
        str | None,
        typer.Option(
            help="Liberty station -> sensor, e.g. 1=hand,2=index.proximal,... "
            "(default: 1 = hand, then the model's sensors in order)."
        ),
    ] = None,
    wait: Annotated[
        bool,
        typer.Option(
            "--wait", help="Replay only: wait for a consumer on every LSL/DDS output first."
        ),
    ] = False,
    wait_timeout: Annotated[
        float, typer.Option(min=0.0, help="Seconds --wait waits before giving up.")
    ] = 60.0,
    duration: Annotated[
        float | None, typer.Option(min=0.0, help="Stop after this many seconds.")
    ] = None,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="Replay a recording that does not fit the model (units, quaternion order, "
            "sensors), with a warning.",
        ),
    ] = False,
    retarget: Annotated[
        str | None,
        typer.Option(
            "--retarget",
            metavar="ROBOT",
            help="Drive a robot hand: shadow, allegro or a .urdf/.xml file (needs --map). "
            "--ros2/--ros2-bag then carry the robot's joints (rad) and --lsl adds the "
            "outlet PREFIX-robot; the values are those of `fingerfit retarget`.",
        ),
    ] = None,
    map_path: MapOption = None,
    method: MethodOption = "tip",
    orthogonal: OrthogonalOption = False,
    contact_mm: ContactOption = DEFAULT_CONTACT_MM,
    max_age: Annotated[
        float,
        typer.Option(
            "--max-age",
            metavar="MS",
            help="Robot lane (LSL, DDS): never send a frame older than this (ms); of "
            "frames that wait, only the newest is sent.",
        ),
    ] = DEFAULT_MAX_AGE_MS,
    silence_ms: Annotated[
        float,
        typer.Option(
            "--silence-ms",
            metavar="MS",
            help="Watchdog: after this long without a frame (ms), valid = 0 on the live "
            "outputs and one warning line.",
        ),
    ] = DEFAULT_SILENCE_MS,
    on_silence: Annotated[
        str,
        typer.Option(
            "--on-silence",
            help="With --retarget, what the robot gets when the source falls silent: hold "
            "(its last pose) or release (its rest pose).",
        ),
    ] = "hold",
    reconnect: Annotated[
        float | None,
        typer.Option(
            "--reconnect",
            metavar="S",
            help="Live sources: how long (s) to keep reopening a lost serial port or "
            f"looking for a lost LSL stream before the stream ends (default "
            f"{DEFAULT_RECONNECT_S:g}; 0: end at once).",
        ),
    ] = None,
    realtime: Annotated[
        bool,
        typer.Option(
            "--realtime",
            help="Ask the OS for a real-time class for the robot lane where permitted "
            "(SCHED_FIFO 50, memory locked, its own CPU); one line says what was granted. "
            "Never fails the run.",
        ),
    ] = False,
    quiet: Annotated[
        bool,
        typer.Option(
            "--quiet",
            "-q",
            help="No status line (there is none either when stderr is not a terminal).",
        ),
    ] = False,
    verbose: Annotated[
        bool, typer.Option("--verbose", help="Show liblsl's own log lines (INFO|) on stderr.")
    ] = False,
) -> None:
    """Stream joint angles and fingertips of a live or replayed hand (Ctrl-C to stop).

    The values are those of `fingerfit angles` (same kinematics; a model fitted from
    markers streams a marker source: docs/markers.md). A frame with a missing
    sensor holds the last values and has valid = 0. With --retarget ROBOT, the robot's
    joints of `fingerfit retarget` go out too. LSL and DDS get the newest frame, never
    one older than --max-age; --record, --ros2-bag and --view get every frame.
    """
    import numpy as np

    from ..errors import FingerfitError
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..io.markers import is_marker_file
    from ..live import sources as src
    from ..live.markers import check_marker_source, is_marker_model, kinematics_of, marker_solver
    from ..live.outputs import BagOutput, LslOutput, RecordOutput, Ros2Output, dds_topic
    from ..live.stream import (
        SILENCE_POLICIES,
        Streamer,
        channels_of,
        check_max_age,
        check_silence,
        empty_recording,
        model_sensors,
        run,
    )
    from ..model import load_model
    from ..session import UNITS_TO_MM

    if tips_frame not in ("tracker", "hand"):
        raise typer.BadParameter("must be tracker or hand", param_hint="--tips-frame")
    kind, _, _ = src.split_spec(source)
    replay_path = src.parse_replay(source)[0] if kind == "replay" else None
    if ros2 is not None:
        dds_topic(ros2)
    if wait and kind != "replay":
        raise FingerfitError("only a replay source waits for consumers", field="--wait")
    if stations is not None and kind != "liberty":
        raise FingerfitError("only a liberty source has stations", field="--stations")
    if reconnect is not None and kind == "replay":
        raise FingerfitError("only a live source (liberty:, lsl:) reconnects", field="--reconnect")
    reconnect_s = src.check_reconnect(DEFAULT_RECONNECT_S if reconnect is None else reconnect)
    max_age_s = check_max_age(max_age)
    silence_s = check_silence(silence_ms)
    if on_silence not in SILENCE_POLICIES:
        raise FingerfitError(
            f"'{on_silence}' is not one of {', '.join(SILENCE_POLICIES)}", field="--on-silence"
        )
    if retarget is None:
        alone = [
            (on_silence != "hold", "--on-silence"),
            (map_path is not None, "--map"),
            (method != "tip", "--method"),
            (orthogonal, "--orthogonal"),
            (contact_mm is not None, "--contact-mm"),
        ]
        for given, name in alone:
            if given:
                raise FingerfitError("applies only with --retarget ROBOT", field=name)
        robot_files: list[Path] = []
    else:
        robot_files = check_robot_options(retarget, map_path, method, contact_mm)
    inputs = [model_path, *robot_files] + ([replay_path] if replay_path is not None else [])
    files = [p for p in (record, ros2_bag, view_save) if p is not None]
    refuse_writing_inputs(files, inputs)
    if record is not None:
        check_target(record)
    check_view(view, view_save, record)
    if (
        ros2_bag is not None
        and ros2_bag.exists()
        and not (ros2_bag.is_dir() and not any(ros2_bag.iterdir()))
    ):
        raise FingerfitError("exists; choose a new folder for the bag", path=ros2_bag)
    model = load_model(model_path)
    markers = is_marker_model(model)
    if markers:  # its import (about a second) before the source opens, not on its frames
        marker_solver()
    check_marker_stream(
        model_path,
        markers,
        kind,
        replay_path is not None and is_marker_file(replay_path),
        orthogonal,
    )
    units_given = units
    units = units or model.session_units
    if units not in UNITS_TO_MM:
        raise typer.BadParameter(f"must be one of {', '.join(UNITS_TO_MM)}", param_hint="--units")
    sensors = model_sensors(model)
    retargeter = bag_retargeter = None
    if retarget is not None:
        # The robot (MuJoCo / Pinocchio loaded here, not in the loop) and its map are
        # checked before the source opens: a bad map or robot leaves nothing behind.
        from ..live.stream import robot_joint_units
        from ..retarget import Retargeter

        robot, rmap = resolve_robot(retarget, map_path, model.hand, "--retarget")
        variant = "orthogonal" if orthogonal else "user_axis"
        retargeter = Retargeter(model, robot, rmap, method, variant, contact_mm=contact_mm)
        for note in retargeter.notes:
            notice("note", note)
        bag_retargeter = None
        if ros2_bag is not None and (lsl or ros2 is not None):
            # The data lane steps through every frame on its own thread: a second robot
            # (its own MuJoCo/Pinocchio data) and its own warm start.
            robot2, rmap2 = resolve_robot(retarget, map_path, model.hand, "--retarget")
            bag_retargeter = Retargeter(
                model, robot2, rmap2, method, variant, contact_mm=contact_mm
            )
    if not verbose and (lsl or kind == "lsl"):
        from ..live import quiet_lsl

        quiet_lsl()  # before any other LSL call

    # The source first: a file that does not read, or a device that does not open, fails
    # before any output exists.
    if kind == "replay" and markers:
        from ..io.markers import read_marker_recording

        path, speed = src.parse_replay(source)
        rec = read_marker_recording(path, units=units_given)
        for note in rec.notes:
            notice("note", note)
        check_marker_source(model, set(rec.markers), str(path))
        the_source = src.ReplaySource(rec, speed)
        step = float(np.nanmedian(np.diff(rec.time))) if rec.n_frames > 1 else 0.0
        nominal = float(speed * (rate or (1.0 / step if step > 0 else 0.0)))
    elif kind == "replay":
        from .fit import read_checked_recording

        path, speed = src.parse_replay(source)
        rec = read_checked_recording(model, path, units, rate, force)
        check_stream_layout(model, set(rec.poses), path)
        the_source = src.ReplaySource(rec, speed)
        step = float(np.nanmedian(np.diff(rec.time))) if rec.n_frames > 1 else 0.0
        native = rate or (1.0 / step if step > 0 else 0.0)
        nominal = float(speed * native)  # the LSL nominal rate: frames per second as sent
    elif kind == "liberty":
        port, baud = src.parse_liberty(source)
        mapping = (
            src.parse_stations(stations, sensors) if stations else src.default_stations(sensors)
        )
        check_stream_layout(model, set(mapping.values()), None, "--stations")
        nominal = rate or src.LIBERTY_RATE_HZ
        the_source = src.LibertySource(port, baud, mapping, nominal, reconnect_s)
    else:
        name = src.split_spec(source)[1]
        the_source = src.LslSource(
            name,
            sensors,
            reconnect=reconnect_s,
            check=(
                (lambda present: check_marker_source(model, present, f"lsl:{name}"))
                if markers
                else (lambda present: check_stream_layout(model, present, f"lsl:{name}"))
            ),
            markers=markers,
        )
        nominal = 0.0

    from ..export.geometry import joint_names

    names = list(robot.joint_names) if retargeter is not None else joint_names(model)
    streamer = None
    from ..live.realtime import task_ids

    threads_before = task_ids()  # the live outputs' threads: those started from here on
    try:
        lsl_out = ros_out = bag_out = rec_out = live_view = None
        empty = empty_recording(sensors, markers)
        ch = channels_of(model, kinematics_of(model, empty, ("user_axis",))[0])
        if lsl:
            robot_outlet = (
                {
                    "robot_labels": names,
                    "robot_units": robot_joint_units(robot),
                    "robot_name": rmap.name,
                }
                if retargeter is not None
                else {}
            )
            lsl_out = LslOutput(
                lsl_name,
                ch.angle_labels,
                ch.tip_labels,
                nominal,
                tips_frame,
                source_labels=ch.source_labels,
                **robot_outlet,
            )
        if ros2 is not None:
            ros_out = Ros2Output(ros2, names, source_names=ch.digits)
        if ros2_bag is not None:
            bag_out = BagOutput(ros2_bag, ros2 or "/joint_states", names, source_names=ch.digits)
        if record is not None:
            rec_out = RecordOutput(record, units)
        if view or view_save is not None:
            from ..view import LiveView

            # The view's process poses its robot on a robot of its own.
            view_robot = (retarget, map_path) if retarget is not None else None
            live_view = LiveView(model, view_save, view_robot)
        streamer = Streamer(
            model,
            lsl=lsl_out,
            ros2=ros_out,
            bag=bag_out,
            record=rec_out,
            record_units=units,
            tips_frame=tips_frame,
            channels=ch,
            retargeter=retargeter,
            bag_retargeter=bag_retargeter,
            max_age=max_age_s,
            on_silence=on_silence,
            view=live_view,
        )
    except BaseException:
        the_source.close()
        for o in (lsl_out, ros_out):
            if o is not None:
                o.close()
        for o in (bag_out, rec_out, live_view):
            if o is not None:
                o.close(ok=False)
        raise
    try:
        summary = run(
            the_source,
            streamer,
            wait=wait_timeout if wait else None,
            status=not quiet,
            duration=duration,
            silence=silence_s,
            warn=lambda text: notice("warning", text),
            realtime=realtime,
            note=lambda text: notice("realtime", text),
            threads_before=threads_before,
        )
    except FingerfitError as exc:
        if streamer.summary.frames:
            kept = [str(p) for p in (record, ros2_bag, view_save) if p is not None]
            extra = f"; kept {', '.join(kept)}" if kept else ""
            n = streamer.summary.reconnects
            back = f", {n} reconnect{'s' * (n > 1)}" if n else ""
            raise FingerfitError(
                f"{exc} (after {streamer.summary.frames} frames{back}{extra})"
            ) from None
        raise
    say(
        "{}",
        summary_line(
            summary,
            streamer.live,
            streamer.data is not None,
            max_age,
            retargeter is not None,
            view=live_view is not None,
        ),
    )
    if retargeter is not None and (retargeter.missing or retargeter.held):
        notice(
            "note",
            f"robot ({rmap.name}, {method}): "
            + (
                f"{retargeter.missing} frame(s) with a missing sensor kept those digits' pose"
                if method == "tip"
                else f"{retargeter.held} frame(s) with a missing angle kept the previous value"
            ),
        )
    if the_source.stats.skipped_bytes or the_source.stats.rejected:
        notice(
            "note",
            f"{the_source.stats.skipped_bytes} bytes skipped and {the_source.stats.rejected} "
            "records rejected while resynchronising",
        )
    for p, what in ((record, "angles CSV"), (ros2_bag, "rosbag2"), (view_save, "view")):
        if p is not None:
            say("{} -> [bold]{}[/]", what, p)


def check_marker_stream(
    model_path: Path,
    markers: bool,
    kind: str,
    marker_file: bool,
    orthogonal: bool,
) -> None:
    """Refuse, in one line, a source of the other kind than the model (a model fitted from
    markers streams marker positions, a 6-DOF model sensor poses) and, for a marker model,
    ``--orthogonal`` (it has its fitted axes only)."""
    from ..errors import FingerfitError

    if not markers:
        if marker_file:
            raise FingerfitError(
                "was fitted from 6-DOF sensors: it streams poses, not a marker recording "
                "(fit a model from a marker session: docs/markers.md)",
                path=model_path,
            )
        return
    if kind == "liberty" or (kind == "replay" and not marker_file):
        raise FingerfitError(
            "was fitted from markers: it streams marker positions (--source "
            "replay:X.trc|.tsv|.c3d or lsl:NAME, a MoCap stream of markers), not poses",
            path=model_path,
        )
    check_orthogonal(model_path, markers, orthogonal)


def check_view(view: bool, view_save: Path | None, record: Path | None) -> None:
    """``--view`` needs a display, ``--view-save`` a new .rrd file (:func:`check_view_save`;
    not both); either needs Rerun (one line naming the extra). Checked before the source
    opens (``stream``, ``capture``)."""
    from ..errors import FingerfitError

    if view_save is not None:
        check_view_save(view_save, view, record)
    if view:
        from ..view import has_display

        if not has_display():
            raise FingerfitError(
                "no display to open the viewer on: give --view-save OUT.rrd", field="--view"
            )
    if view or view_save is not None:
        from ..view import require_rerun

        require_rerun()


def check_view_save(path: Path, view: bool, record: Path | None) -> None:
    """``--view-save OUT.rrd``: a Rerun file, not with ``--view``, not the record."""
    from ..errors import FingerfitError
    from ..io.atomic import check_target

    if view:
        raise FingerfitError(
            "one of --view (a window) or --view-save (a file)", field="--view-save"
        )
    if path.suffix.lower() != ".rrd":
        raise FingerfitError("must end in .rrd (a Rerun file)", field="--view-save")
    if record is not None and path.resolve() == record.resolve():
        raise FingerfitError("must not be the --record file", field="--view-save")
    check_target(path)


def check_stream_layout(
    model, sensors: set[str], where: Path | str | None, field: str | None = None
) -> None:
    """Refuse a source whose sensors cannot determine every joint of the model (one line
    naming the joint and the sensor that would: :func:`fingerfit.track.check_layout`), and
    say in a note which sensors it lacks (their digits are solved by the model, or held by
    a model without calibration statistics)."""
    from ..track import check_layout

    layouts = check_layout(
        model, sensors, list(model.fingers), None if where is None else str(where), field
    )
    missing = [s for lay in layouts.values() for s in lay.missing]
    if missing:
        how = (
            "solved by the model (docs/tracking.md)"
            if model.tracking is not None
            else "held: the model has no tracking statistics (fit it again to solve them)"
        )
        notice("note", f"the source has no {', '.join(missing)}: those digits' frames are {how}")


def summary_line(
    summary,
    live: bool,
    files: bool,
    max_age_ms: float,
    retargets: bool = False,
    view: bool = False,
) -> str:
    """The last line: the lanes' counts (which add up: received = sent + skipped +
    stale with a live output, recorded = received with a file output), then the robot
    lane's timings.

    Parameters
    ----------
    summary : fingerfit.live.stream.Summary
    live, files : bool
        Whether the stream has a robot lane (LSL, DDS) and a data lane (files).
    max_age_ms : float
        ``--max-age`` (ms).
    retargets : bool
        The robot lane computes a robot's joints (``--retarget``).
    view : bool
        The stream has a live view (``--view``, ``--view-save``): the frames its process
        logged and those dropped while it was behind.
    """
    import numpy as np

    s = summary
    counts = []
    if live:
        counts.append(
            f"{s.sent} sent, {s.skipped} skipped, {s.stale} stale (--max-age {max_age_ms:g} ms)"
            + (f", {s.unconverged} marker solves of them unconverged" if s.unconverged else "")
        )
    if files:
        counts.append(
            f"{s.recorded} recorded"
            + (f" ({s.data_unconverged} marker solves unconverged)" if s.data_unconverged else "")
        )
    if view:
        counts.append(f"view {s.view_logged} logged, {s.view_dropped} dropped")
    text = f"{s.received} frames received in {s.seconds:.1f} s"
    if counts:
        text += ": " + ", ".join(counts)
    text += f" ({s.lost} lost, {s.invalid} with a missing sensor"
    if s.invalid:
        text += f": {s.invalid - s.held} solved by the model, {s.held} held"
    if s.silences:
        text += f", {s.silences} silence{'s' * (s.silences > 1)}"
    if s.outages:
        text += f", {s.outages} outage{'s' * (s.outages > 1)}, {s.reconnects} reconnected"
    text += ")"
    lat, age, comp = s.latency_ms(), s.age_ms(), s.compute_ms_per_frame()
    if lat.size:
        text += (
            f"; arrival -> sent p50 {np.percentile(lat, 50):.2f} ms, p99 "
            f"{np.percentile(lat, 99):.2f} ms; age at send max {age.max():.2f} ms"
        )
    if comp.size:
        what = "compute per frame" + (" (retargeting included)" if retargets else "")
        text += (
            f"; {what} p50 {np.percentile(comp, 50):.2f} ms, p99 {np.percentile(comp, 99):.2f} ms"
        )
    if files and s.recorded:
        text += f"; files up to {1e3 * s.data_lag:.0f} ms behind"
    if s.interrupted:
        text += " -- stopped by Ctrl-C"
    return text
