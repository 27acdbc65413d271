"""``fingerfit view``: the person's fitted hand (and a retargeted robot hand) in Rerun."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from ..errors import FingerfitError
from .app import Quiet, app, notice, progress, say, user_errors
from .retarget import (
    ROBOT_HELP,
    MapOption,
    MethodOption,
    OrthogonalOption,
    check_orthogonal,
    check_robot_options,
)


@app.command()
@user_errors
def view(
    model_path: Annotated[
        Path, typer.Argument(metavar="MODEL", help="Model JSON from `fingerfit fit`.")
    ],
    recording: Annotated[
        Path,
        typer.Argument(
            help="Pose CSV (canonical format); with a model fitted from markers, a marker "
            "recording (.trc, .tsv, .c3d)."
        ),
    ],
    robot: Annotated[
        str | None, typer.Option(help=f"Also show a robot hand posed by the retarget: {ROBOT_HELP}")
    ] = None,
    map_path: MapOption = None,
    method: MethodOption = "tip",
    orthogonal: OrthogonalOption = False,
    save: Annotated[
        Path | None,
        typer.Option(
            "--save", help="Write the view to this Rerun file (.rrd) instead of a window."
        ),
    ] = None,
    web: Annotated[
        bool,
        typer.Option(
            "--web",
            help="Serve the view and Rerun's web viewer on 127.0.0.1 (the page may reach "
            "nothing else) and print the address to open (until Ctrl-C).",
        ),
    ] = False,
    web_port: Annotated[
        int, typer.Option("--web-port", min=1, max=65535, help="HTTP port of --web's viewer.")
    ] = 9090,
    grpc_port: Annotated[
        int, typer.Option("--grpc-port", min=1, max=65535, help="Port --web's data is served on.")
    ] = 9876,
    units: Annotated[
        str | None,
        typer.Option(
            help="Units of the recording (default: the model's session units; a marker "
            "recording's own)."
        ),
    ] = None,
    force: Annotated[
        bool,
        typer.Option(
            "--force",
            help="Show the recording even when it does not fit the model (units, "
            "quaternion order, sensors), with a warning.",
        ),
    ] = False,
    quiet: Quiet = False,
) -> None:
    """Show the fitted hand per frame in the Rerun viewer: segments, joint centres and
    axes, tips and pads of both models, sensors, joint angles; a robot hand beside it.
    A model fitted from markers shows a marker recording: its markers as recorded and
    where the model puts them too (docs/markers.md)."""
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..model import load_model
    from ..session import UNITS_TO_MM
    from ..view import has_display, require_rerun
    from .fit import is_marker_input, read_checked_recording, read_marker_input

    inputs = [model_path, recording]
    if robot is not None:
        inputs += check_robot_options(robot, map_path, method, None)
    elif map_path is not None:
        raise FingerfitError("needs --robot", field="--map")
    if save is not None:
        if save.suffix.lower() != ".rrd":
            raise FingerfitError("must end in .rrd (a Rerun file)", field="--save")
        refuse_writing_inputs([save], inputs)
        check_target(save)
    if save is None and not web and not has_display():
        raise FingerfitError(
            "no display to open the viewer on: give --save OUT.rrd or --web", field="--save"
        )
    require_rerun()  # before any work: a missing package is one line naming the extra
    model = load_model(model_path)
    markers = is_marker_input(model, model_path, recording)
    check_orthogonal(model_path, markers, orthogonal)
    if markers:
        rec = read_marker_input(model, recording, units)
    else:
        units = units or model.session_units
        if units not in UNITS_TO_MM:
            raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--units")
        rec = read_checked_recording(model, recording, units, None, force)
    scene = _scene(model, rec, recording, robot, map_path, method, orthogonal, quiet)
    for note in scene.notes:
        notice("note", note)
    k = len(scene.digits)
    what = f"{scene.n_frames} frames, {k} digit{'s' if k != 1 else ''}" + (
        f", {scene.robot.name} robot" if scene.robot is not None else ""
    )
    if save is not None:
        from ..view import save_rrd

        say("{} -> [bold]{}[/] (mm, tracker frame)", what, save_rrd(scene, save))
    if web:
        _serve_web(scene, what, web_port, grpc_port)
    elif save is None:
        _spawn(scene, what)


def _scene(model, rec, recording: Path, robot, map_path, method, orthogonal, quiet):
    """The :class:`fingerfit.view.Scene` of a recording, with the robot and the truth."""
    from ..track import track_recording
    from ..view import hand_scene, robot_scene, truth_tips
    from ..view.scene import hand_recording, marker_scene

    with progress(quiet) as bar:
        task = bar.add_task("kinematics", total=3 if robot is not None else 2)
        if model.markers:  # the angles of `fingerfit angles`, the hand of its markers
            scene = marker_scene(model, rec)
            rec, kin = hand_recording(scene, rec), scene.kinematics
        else:
            kin = track_recording(model, rec).kinematics  # missing sensors: the model's
            scene = hand_scene(model, rec, kin)
        bar.update(task, advance=1, description="truth")
        scene.truth_tips, note = truth_tips(recording, rec.n_frames)
        if note:
            scene.notes.append(note)
        bar.advance(task)
        if robot is not None:
            from .retarget import resolve_robot

            bar.update(task, description=f"retargeting ({method})")
            robot_model, rmap = resolve_robot(robot, map_path, model.hand)
            variant = "orthogonal" if orthogonal else "user_axis"
            scene.robot = robot_scene(model, rec, robot_model, rmap, method, variant, kin)
            scene.notes += scene.robot.notes
            bar.advance(task)
    return scene


def _serve_web(scene, what: str, web_port: int, grpc_port: int) -> None:
    """Serve the scene over gRPC and the web viewer over HTTP, nothing beyond
    ``127.0.0.1``: the viewer's files from the ``rerun`` command bound there
    (:class:`fingerfit.view.webserve.LocalViewerServer`), to the browser through
    :class:`fingerfit.view.webserve.ViewerProxy` (its Content-Security-Policy keeps the
    page on this machine). Until Ctrl-C or SIGTERM, which stop both servers."""
    import signal
    import time

    from ..view import blueprint, log_scene, new_stream, no_usage_reporting
    from ..view.webserve import LocalViewerServer, ViewerProxy, serve_grpc_local

    def stop(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, stop)  # terminated: both servers stopped too
    viewer = proxy = stream = None
    try:
        with no_usage_reporting():
            stream = new_stream()
            try:
                uri = serve_grpc_local(stream, grpc_port, blueprint(scene.robot is not None))
                log_scene(scene, stream)
                stream.flush()
                viewer = LocalViewerServer(uri)
                proxy = ViewerProxy(web_port, viewer.port, grpc_port)
            except (OSError, RuntimeError) as exc:
                raise FingerfitError(f"cannot serve the viewer ({exc})", field="--web") from None
        say("{}: open [bold]{}[/] (Ctrl-C to stop)", what, proxy.url(uri))
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        if stream is not None:
            stream.disconnect()
    finally:
        if proxy is not None:
            proxy.close()
        if viewer is not None:
            viewer.close()
        signal.signal(signal.SIGTERM, previous)


def _spawn(scene, what: str) -> None:
    """Open the native Rerun viewer with the scene, its usage reporting off."""
    from ..view import blueprint, log_scene, new_stream, no_usage_reporting

    stream = new_stream()
    with no_usage_reporting():
        stream.spawn(default_blueprint=blueprint(scene.robot is not None))
    log_scene(scene, stream)
    stream.flush()
    say("{} sent to the Rerun viewer", what)
