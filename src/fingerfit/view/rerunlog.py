"""The scene into a Rerun recording stream: static entities once, each frame's as whole
columns (``send_columns``) on the time lines ``frame`` and ``time``; the blueprint and
the ``.rrd`` file."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..transforms import FloatArray
from .robotgeometry import RobotGeometry, Visual, vertex_normals
from .scene import (
    _COLOURS,
    _SENSOR_AXIS_COLOURS,
    APPLICATION_ID,
    SENSOR_AXIS_MM,
    RobotScene,
    Scene,
    no_usage_reporting,
    require_rerun,
)


def _indexes(rr, time: FloatArray, frames: np.ndarray) -> list:
    return [
        rr.TimeColumn("frame", sequence=np.asarray(frames, dtype=np.int64)),
        rr.TimeColumn("time", duration=np.asarray(time, dtype=float)),
    ]


def _static(rr, stream, entity: str, archetype) -> None:
    rr.log(entity, archetype, static=True, recording=stream)


def _points(rr, stream, entity: str, idx, pts: FloatArray, extra=()) -> None:
    """Points ``(n, k, 3)``: positions per frame (with the ``extra`` component columns in
    the same rows)."""
    n, k = pts.shape[:2]
    columns = rr.Points3D.columns(positions=pts.reshape(-1, 3)).partition(np.full(n, k))
    rr.send_columns(entity, indexes=idx, columns=[*columns, *extra], recording=stream)


def _strips(rr, stream, entity: str, idx, pts: FloatArray, strips: list[np.ndarray]) -> None:
    """Line strips through ``pts (n, k, 3)``, each strip a list of point indices."""
    n = pts.shape[0]
    lines = [pts[i, s] for i in range(n) for s in strips]
    rr.send_columns(
        entity,
        indexes=idx,
        columns=rr.LineStrips3D.columns(strips=lines).partition(np.full(n, len(strips))),
        recording=stream,
    )


def _arrows(rr, stream, entity: str, idx, origins: FloatArray, vectors: FloatArray) -> None:
    n, k = origins.shape[:2]
    rr.send_columns(
        entity,
        indexes=idx,
        columns=rr.Arrows3D.columns(
            origins=origins.reshape(-1, 3), vectors=vectors.reshape(-1, 3)
        ).partition(np.full(n, k)),
        recording=stream,
    )


def _transforms(rr, stream, entity: str, idx, translation: FloatArray, matrix: FloatArray) -> None:
    """One transform per frame: ``translation (n, 3)``, ``matrix (n, 3, 3)`` (child ->
    parent)."""
    rr.send_columns(
        entity,
        indexes=idx,
        columns=rr.Transform3D.columns(translation=translation, mat3x3=matrix.reshape(-1, 9)),
        recording=stream,
    )


def blueprint(robot: bool = False):
    """The default layout: the 3D scene beside the joint angles' time series (and the
    robot's joints, with a ``robot``)."""
    import rerun.blueprint as rrb

    series = [rrb.TimeSeriesView(origin="angles", name="joint angles (deg)")]
    if robot:
        series.append(rrb.TimeSeriesView(origin="robot_angles", name="robot joints (deg)"))
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                origin="/",
                contents=["/person/**", "/sensors/**", "/markers/**", "/truth/**", "/robot/**"],
                name="hand (mm, tracker frame)",
            ),
            rrb.Vertical(*series),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def _padded(scene: Scene) -> list[str]:
    return [g for g in scene.digits if scene.kinematics.motions["user_axis"][g].pad is not None]


def _truth_digits(scene: Scene) -> list[str]:
    return [g for g in scene.digits if g in scene.truth_tips] if scene.truth_tips else []


def log_static(scene: Scene, stream) -> None:
    """What does not change from frame to frame (colours, radii, labels, the scene's
    axes), logged once; ``scene`` may be any block of frames of the recording (its
    digits, axes, sensors and variants are the recording's)."""
    rr = require_rerun()
    kin = scene.kinematics
    _static(rr, stream, "/", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
    _static(
        rr,
        stream,
        "person/skeleton",
        rr.LineStrips3D.from_fields(colors=[_COLOURS["skeleton"]], radii=[1.2]),
    )
    _static(
        rr,
        stream,
        "person/joints",
        rr.Points3D.from_fields(colors=[_COLOURS["joints"]], radii=[2.5]),
    )
    colours = [_COLOURS[kind] for _, _, kind in scene.axes]
    _static(rr, stream, "person/axes", rr.Arrows3D.from_fields(colors=colours, radii=[0.6]))
    _static(
        rr,
        stream,
        "person/tips",
        rr.Points3D.from_fields(colors=[_COLOURS["tips"]], radii=[3.0], labels=scene.digits),
    )
    padded = _padded(scene)
    if padded:
        _static(
            rr,
            stream,
            "person/pads",
            rr.Points3D.from_fields(colors=[_COLOURS["pads"]], radii=[2.5], labels=padded),
        )
    if "orthogonal" in kin.motions:
        _static(
            rr,
            stream,
            "person/orthogonal/tips",
            rr.Points3D.from_fields(colors=[_COLOURS["orthogonal"]], radii=[3.0]),
        )
    if scene.sensors:
        colours = list(_SENSOR_AXIS_COLOURS) * len(scene.sensors)
        _static(rr, stream, "sensors", rr.Arrows3D.from_fields(colors=colours, radii=[0.6]))
    if scene.markers is not None:
        labels = scene.markers.labels
        for entity, colour, radius in (
            ("measured", "markers", 2.0),
            ("model", "model_markers", 1.5),
        ):
            _static(
                rr,
                stream,
                f"markers/{entity}",
                rr.Points3D.from_fields(colors=[_COLOURS[colour]], radii=[radius], labels=labels),
            )
        _static(
            rr,
            stream,
            "markers/residual",
            rr.LineStrips3D.from_fields(colors=[_COLOURS["model_markers"]], radii=[0.4]),
        )
    have = _truth_digits(scene)
    if have:
        _static(
            rr,
            stream,
            "truth/tips",
            rr.Points3D.from_fields(colors=[_COLOURS["truth"]], radii=[2.0], labels=have),
        )
    if scene.robot is not None:
        log_robot_static(scene.robot.digits, stream, scene.robot.geometry)


def _link_entity(rr, geometry: RobotGeometry, k: int) -> str:
    return f"robot/geometry/{rr.escape_entity_path_part(geometry.links[k])}"


def log_robot_static(digits: list[str], stream, geometry: RobotGeometry | None = None) -> None:
    """The robot's colours, radii and labels, and its own shapes (``geometry``), logged
    once: each shape under its link, ``robot/geometry/<link>/<shape>``, with its pose in
    the link (m); without a shape, the lines and points that draw it instead."""
    rr = require_rerun()
    if geometry is not None and geometry.visuals:
        for v in geometry.visuals:
            entity = f"{_link_entity(rr, geometry, v.link)}/{rr.escape_entity_path_part(v.name)}"
            pose = rr.Transform3D(translation=v.translation, mat3x3=v.rotation)
            rr.log(entity, pose, _shape(rr, v), static=True, recording=stream)
    else:
        _static(
            rr,
            stream,
            "robot/skeleton",
            rr.LineStrips3D.from_fields(colors=[_COLOURS["robot"]], radii=[2.0]),
        )
        _static(
            rr,
            stream,
            "robot/joints",
            rr.Points3D.from_fields(colors=[_COLOURS["robot"]], radii=[3.0]),
        )
    _static(
        rr,
        stream,
        "robot/tips",
        rr.Points3D.from_fields(colors=[_COLOURS["robot_tips"]], radii=[4.0], labels=digits),
    )


def _shape(rr, v: Visual):
    """The Rerun archetype of one shape, in its own frame (m)."""
    colour = np.round(np.clip(v.rgba, 0.0, 1.0) * 255).astype(np.uint8)
    if v.kind == "mesh":
        return rr.Mesh3D(
            vertex_positions=v.vertices,
            triangle_indices=v.triangles,
            vertex_normals=vertex_normals(v.vertices, v.triangles),
            albedo_factor=colour,
        )
    if v.kind == "box":
        return rr.Boxes3D(half_sizes=[v.size], colors=[colour], fill_mode="solid")
    if v.kind in ("sphere", "ellipsoid"):
        return rr.Ellipsoids3D(half_sizes=[v.size], colors=[colour], fill_mode="solid")
    radius, half = v.size[0], v.size[1]
    if v.kind == "capsule":  # Rerun's runs from its origin along +z
        return rr.Capsules3D(
            lengths=[2 * half], radii=[radius], translations=[[0.0, 0.0, -half]], colors=[colour]
        )
    return rr.Cylinders3D(lengths=[2 * half], radii=[radius], colors=[colour], fill_mode="solid")


def log_frames(scene: Scene, stream, first: int = 0) -> None:
    """Send a block of frames of a :class:`Scene` (whose first frame is the recording's
    frame ``first``) to a Rerun recording stream, each entity as whole columns.

    Entities (``docs/view.md``): ``person/skeleton`` (per digit: joint centre to joint
    centre to tip), ``person/joints``, ``person/axes`` (every axis, flexion orange,
    ab/adduction purple), ``person/tips`` (with ``tip_mm``, the same tips in float64:
    Rerun stores positions in float32), ``person/pads``, ``person/orthogonal/tips``,
    ``sensors`` (each sensor's x, y, z axes), ``angles/<digit>/<angle>`` (deg),
    ``markers/measured``, ``markers/model`` and ``markers/residual`` (a marker model's
    markers as recorded, where the model puts them, a line between the two),
    ``truth/tips``, and the robot's (:func:`log_robot_frames`). Their colours and labels
    are :func:`log_static`'s.
    """
    rr = require_rerun()
    n = scene.n_frames
    if n == 0:
        return
    idx = _indexes(rr, scene.time, first + np.arange(n))
    kin = scene.kinematics
    d = len(scene.digits)
    # The person: each digit's skeleton, joint centre to joint centre to tip.
    tips = np.stack([kin.motions["user_axis"][g].tip for g in scene.digits], axis=1)
    skeleton = np.concatenate([scene.centres, tips[:, :, None, :]], axis=2)  # (n, d, 4, 3)
    strips = [np.arange(4) + 4 * k for k in range(d)]
    _strips(rr, stream, "person/skeleton", idx, skeleton.reshape(n, -1, 3), strips)
    _points(rr, stream, "person/joints", idx, scene.centres.reshape(n, -1, 3))
    _arrows(rr, stream, "person/axes", idx, scene.axis_origins, scene.axis_vectors)
    exact = rr.AnyValues.columns(tip_mm=tips.reshape(-1).astype(np.float64))
    _points(rr, stream, "person/tips", idx, tips, extra=exact.partition(np.full(n, 3 * d)))
    padded = _padded(scene)
    if padded:
        pads = np.stack([kin.motions["user_axis"][g].pad for g in padded], axis=1)
        _points(rr, stream, "person/pads", idx, pads)
    if "orthogonal" in kin.motions:
        ortho = np.stack([kin.motions["orthogonal"][g].tip for g in scene.digits], axis=1)
        _points(rr, stream, "person/orthogonal/tips", idx, ortho)
    # The sensors: each one's x, y, z axes.
    names = list(scene.sensors)
    if names:
        pos = np.stack([scene.sensors[s][0] for s in names], axis=1)  # (n, s, 3)
        rot = np.stack([scene.sensors[s][1] for s in names], axis=1)  # (n, s, 3, 3)
        origins = np.repeat(pos, 3, axis=1)
        vectors = SENSOR_AXIS_MM * np.swapaxes(rot, 2, 3).reshape(n, -1, 3)
        _arrows(rr, stream, "sensors", idx, origins, vectors)
    # Joint angles (deg), one series per angle.
    for g in scene.digits:
        for name, a in kin.motions["user_axis"][g].angles.items():
            rr.send_columns(
                f"angles/{g}/{name}",
                indexes=idx,
                columns=rr.Scalars.columns(scalars=np.degrees(a)),
                recording=stream,
            )
    if scene.markers is not None:  # measured, the model's, and a line between each pair
        m = scene.markers
        _points(rr, stream, "markers/measured", idx, m.measured)
        _points(rr, stream, "markers/model", idx, m.model)
        k = len(m.labels)
        pairs = [np.array([i, k + i]) for i in range(k)]
        both = np.concatenate([m.measured, m.model], axis=1)
        _strips(rr, stream, "markers/residual", idx, both, pairs)
    have = _truth_digits(scene)
    if have:
        truth = np.stack([scene.truth_tips[g] for g in have], axis=1)
        _points(rr, stream, "truth/tips", idx, truth)
    if scene.robot is not None:
        log_robot_frames(scene.robot, stream, first + np.arange(n), scene.time)


def log_robot_frames(robot: RobotScene, stream, frames: np.ndarray, time: FloatArray) -> None:
    """Send a robot hand's frames at the recording's frames ``frames`` (n,) and times
    ``time`` (n,) s: its shapes' transforms -- ``robot/geometry`` the robot's world
    placed beside the person (mm, tracker frame: translation, and its axes times 1000 mm
    per m), ``robot/geometry/<link>`` each link's pose in it (m) -- or, without shapes,
    ``robot/skeleton|joints``; ``robot/tips`` and ``robot_angles/<joint>`` in degrees."""
    rr = require_rerun()
    n = robot.q.shape[0]
    if n == 0:
        return
    idx = _indexes(rr, time, frames)
    if robot.drawn:
        assert robot.geometry is not None and robot.placement_rotation is not None
        scaled = 1000.0 * robot.placement_rotation  # m -> mm
        offset = robot.placement_translation
        ok = np.isfinite(scaled).all(axis=(1, 2)) & np.isfinite(offset).all(axis=1)
        if ok.any() and not ok.all():  # no hand sample: the placement of the nearest before
            near = np.maximum.accumulate(np.where(ok, np.arange(n), -1))
            near[near < 0] = np.flatnonzero(ok)[0]  # (before the first: the first)
            scaled, offset = scaled[near], offset[near]
        _transforms(rr, stream, "robot/geometry", idx, offset, scaled)
        for k in range(len(robot.geometry.links)):
            entity = _link_entity(rr, robot.geometry, k)
            _transforms(
                rr, stream, entity, idx, robot.link_translation[:, k], robot.link_rotation[:, k]
            )
    else:
        _strips(rr, stream, "robot/skeleton", idx, robot.points, robot.strips)
        _points(rr, stream, "robot/joints", idx, robot.points[:, 1 : -len(robot.digits)])
    _points(rr, stream, "robot/tips", idx, robot.tips)
    for j, name in enumerate(robot.joint_names):
        rr.send_columns(
            f"robot_angles/{name}",
            indexes=idx,
            columns=rr.Scalars.columns(scalars=np.degrees(robot.q[:, j])),
            recording=stream,
        )


def log_scene(scene: Scene, stream) -> None:
    """Send a whole :class:`Scene` to a Rerun recording stream: :func:`log_static`, then
    every frame as whole columns (:func:`log_frames`)."""
    log_static(scene, stream)
    log_frames(scene, stream)


def new_stream(recording_id: str | None = None):
    """A Rerun recording stream of application ``fingerfit``, not the global one."""
    rr = require_rerun()
    return rr.RecordingStream(APPLICATION_ID, recording_id=recording_id)


def save_rrd(scene: Scene, path: str | Path) -> Path:
    """Write ``scene`` to a Rerun ``.rrd`` file, atomically (all of it or nothing)."""
    from ..io.atomic import atomic_path

    path = Path(path)
    with atomic_path(path, suffix=".part.rrd") as tmp, no_usage_reporting():
        stream = new_stream()
        stream.save(tmp, default_blueprint=blueprint(scene.robot is not None))
        log_scene(scene, stream)
        stream.flush()
        stream.disconnect()
    return path


def open_view(save: Path | None, layout) -> tuple:
    """A new recording stream to a Rerun file written atomically (``save``) or to a
    spawned native viewer (its usage reporting off), with the default ``layout``.

    Returns
    -------
    (rerun.RecordingStream, contextlib.ExitStack)
        The stream, and what :func:`close_view` ends (the file's atomic write).
    """
    from ..io.atomic import atomic_path

    stack = contextlib.ExitStack()
    stream = new_stream()
    if save is not None:
        tmp = stack.enter_context(atomic_path(Path(save), suffix=".part.rrd"))
        stream.save(tmp, default_blueprint=layout)
    else:
        with no_usage_reporting():
            stream.spawn(default_blueprint=layout)
    return stream, stack


def close_view(stream, stack: contextlib.ExitStack, ok: bool) -> None:
    """Flush and disconnect a stream of :func:`open_view`; its file is kept when ``ok``,
    else removed."""
    try:
        stream.flush()
        stream.disconnect()
    finally:
        if ok:
            stack.close()
        else:
            with contextlib.suppress(BaseException):
                stack.__exit__(RuntimeError, RuntimeError("view not complete"), None)
