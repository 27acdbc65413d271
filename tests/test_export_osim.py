"""OpenSim export checked by OpenSim 4.6 itself: the model loads and initialises, its
kinematics are fingerfit's, its motion file reproduces the angles CSV's tips and pads, and
OpenSim's IMU inverse kinematics on the exported orientations recovers fingerfit's angles.

Every OpenSim model is built once per module (fixtures); a test recording is cut to its
first seconds so that every one of its frames is checked in OpenSim without the suite
noticing.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.estimate import fit_session
from fingerfit.export import joint_names, osim_string, robot_hand, write_coordinates
from fingerfit.export.osim import HAND_COORDINATES, hand_coordinates
from fingerfit.io import read_pose_csv
from fingerfit.io.opensim import frame_name, write_motion, write_orientations
from fingerfit.io.sessiondir import read_landmarks
from fingerfit.kinematics import carry_by_hand, chain_points, compute_kinematics
from fingerfit.model import HandModel, load_model, save_model
from fingerfit.session import Recording
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.simulate.truthmodel import truth_model

from .conftest import subject

osim = pytest.importorskip("opensim")
osim.Logger.removeFileSink()  # no opensim.log in the working folder
osim.Logger.setLevelString("warn")

runner = CliRunner()
#: Agreement required between OpenSim's and fingerfit's points (mm) and frames.
POINT_TOL_MM = 0.01
ROT_TOL = 1e-9
#: OpenSim's IMU IK against fingerfit's angles, noise-free recordings (deg RMS).
IK_TOL_DEG = 0.2
#: Seconds of a test recording checked frame by frame.
SECONDS = 2.0


@functools.cache
def exact(fingers: tuple[str, ...], **kw) -> object:
    """A noise-free simulated subject (cached)."""
    return simulate_subject(SimConfig.exact(fingers=fingers, **kw), 3)


def case_subject(case: str):
    """The simulated subject of a case (``_true``: the same subject)."""
    return {
        "index": lambda: subject("exact", 11),
        "thumb_index_two_axis": lambda: exact(("thumb", "index"), abduction=True),
        "whole_hand": lambda: exact(("thumb", "index", "middle", "ring", "little")),
        "myohand": lambda: exact(("thumb", "index"), world="myohand", hand="right"),
    }[case.removesuffix("_true")]()


@functools.cache
def case_model(case: str) -> HandModel:
    """The fitted models the targets name: one finger (one-axis MP), thumb + index with
    two-axis MP and MCP, the whole hand, and the MyoHand world's thumb + index;
    ``<case>_true``: the subject's true model (exact for its noise-free recordings)."""
    if case.endswith("_true"):
        return truth_model(case_subject(case))
    return fit_session(case_subject(case).session)


CASES = ("index", "thumb_index_two_axis", "whole_hand", "myohand")


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("osim")


@functools.cache
def loaded(case: str, folder: Path):
    """``(hand model, OpenSim model, its state)`` of a case, the file written once."""
    model = case_model(case)
    path = folder / f"{case}.osim"
    path.write_text(osim_string(model), encoding="utf-8")
    om = osim.Model(str(path))
    return model, om, om.initSystem()


# --------------------------------------------------------------------------- OpenSim reads


def _mat(rotation) -> np.ndarray:
    return np.array([[rotation.get(i, j) for j in range(3)] for i in range(3)])


def _vec(v) -> np.ndarray:
    return np.array([v.get(i) for i in range(3)])


def set_coordinates(om, state, values: dict[str, float]) -> None:
    """Coordinate values (rad, m) by name, then the positions realised."""
    cs = om.getCoordinateSet()
    for name, v in values.items():
        cs.get(name).setValue(state, float(v), False)
    om.realizePosition(state)


def marker(om, state, name: str) -> np.ndarray:
    """A marker in ground (m)."""
    return _vec(om.getMarkerSet().get(name).getLocationInGround(state))


def frame(om, state, path: str) -> tuple[np.ndarray, np.ndarray]:
    """A frame's rotation (frame -> ground) and origin (m) in ground."""
    t = osim.PhysicalFrame.safeDownCast(om.getComponent(path)).getTransformInGround(state)
    return _mat(t.R()), _vec(t.p())


def sensor_paths(model: HandModel) -> dict[str, str]:
    """Sensor -> the path of its frame in the exported model."""
    return {s.name: f"/bodyset/{s.link}/{frame_name(s.name)}" for s in robot_hand(model).sensors}


def fingerfit_points(
    model: HandModel, angles: dict[str, np.ndarray], hand_r: np.ndarray, hand_t: np.ndarray
) -> dict[str, np.ndarray]:
    """fingerfit's forward kinematics (mm, tracker): tips, pads and each sensor's origin
    and axes' ends (origin + 1 mm along each axis) for angles ``{<digit>_<axis>: (n,)}``
    and hand sensor poses ``(n, 3, 3)``, ``(n, 3)``."""
    out = {}
    for f, fm in model.fingers.items():
        ang = {k.split("_", 1)[1]: v for k, v in angles.items() if k.split("_", 1)[0] == f}
        pts = {f"{f}_tip": (fm.tip, 3)}
        if fm.pad is not None:
            pts[f"{f}_pad"] = (fm.pad, 3)
        for depth, jm in enumerate(fm.joints.values(), start=1):
            t, r = model.reference_poses[jm.child]
            pts[jm.child] = (t, depth)
            for k in range(3):
                pts[f"{jm.child}:{k}"] = (t + r[:, k], depth)
        for name, (p, depth) in pts.items():
            out[name] = carry_by_hand(
                model, hand_r, hand_t, chain_points(fm, "user_axis", ang, p, depth)
            )
    return out


# --------------------------------------------------------------------------- loads


@pytest.mark.parametrize("case", CASES)
def test_opensim_loads_the_model_as_exported(case: str, folder: Path) -> None:
    """Names, units, ranges and the reference posture, as OpenSim reads them."""
    model, om, state = loaded(case, folder)
    hand = robot_hand(model)
    names = [om.getCoordinateSet().get(i).getName() for i in range(om.getNumCoordinates())]
    assert names == [*HAND_COORDINATES, *joint_names(model)]
    assert om.getLengthUnits().getAbbreviation() == "m"
    assert om.getForceUnits().getAbbreviation() == "N"
    for j in hand.joints:
        c = om.getCoordinateSet().get(j.name)
        assert (c.getRangeMin(), c.getRangeMax()) == (j.lower, j.upper)
        assert c.getMotionType() == 1  # rotational
        assert not c.getDefaultClamped()
    # one body per segment, a massless one between the two axes of a two-axis joint
    bodies = {
        om.getBodySet().get(i).getName(): om.getBodySet().get(i) for i in range(om.getNumBodies())
    }
    assert set(bodies) == {"hand", *(link.name for _, link in hand.chain())}
    for _, link in hand.chain():
        mass = bodies[link.name].getMass()
        assert mass == (0.0 if link.capsule is None else pytest.approx(link.mass, rel=1e-15))
    assert bodies["hand"].getMass() == pytest.approx(hand.palm.mass, rel=1e-15)
    assert hand.palm.mass > 0
    # markers: tip, pad, every sensor origin
    markers = {om.getMarkerSet().get(i).getName() for i in range(om.getMarkerSet().getSize())}
    assert markers == {
        *(f"{f}_{p}" for f in model.fingers for p in ("tip", "pad")),
        *(frame_name(s) for s in sensor_paths(model)),
    }
    # default coordinates = the reference posture: every sensor frame at its reference pose
    for sensor, path in sensor_paths(model).items():
        r, p = frame(om, state, path)
        t0, r0 = model.reference_poses[sensor]
        assert np.abs(p * 1000.0 - t0).max() < 1e-9, sensor
        assert np.abs(r - r0).max() < ROT_TOL, sensor


@pytest.mark.parametrize("case", CASES)
def test_opensim_kinematics_are_fingerfits(case: str, folder: Path) -> None:
    """Random hand poses and joint angles inside the limits (the first set at the lower
    limits, the second at the upper): OpenSim's tips, pads and sensor frames equal
    fingerfit's forward kinematics."""
    model, om, state = loaded(case, folder)
    joints = robot_hand(model).joints
    lo, hi = np.array([j.lower for j in joints]), np.array([j.upper for j in joints])
    rng = np.random.default_rng(5)
    n = 12
    q = np.vstack([lo, hi, rng.uniform(lo, hi, (n - 2, lo.size))])
    t0, r0 = model.reference_poses["hand"]
    hand_r = r0 @ Rotation.from_rotvec(rng.normal(0, 0.6, (n, 3))).as_matrix()
    hand_t = t0 + rng.normal(0, 200.0, (n, 3))
    coords = hand_coordinates(model, hand_r, hand_t)
    ref = fingerfit_points(model, {j.name: q[:, k] for k, j in enumerate(joints)}, hand_r, hand_t)
    paths = sensor_paths(model)
    worst = 0.0
    for i in range(n):
        set_coordinates(
            om,
            state,
            {**dict(zip(HAND_COORDINATES, coords[i], strict=True)),
             **{j.name: q[i, k] for k, j in enumerate(joints)}},
        )  # fmt: skip
        r, p = frame(om, state, "/bodyset/hand")
        assert np.abs(r - hand_r[i]).max() < ROT_TOL
        assert np.abs(p * 1000.0 - hand_t[i]).max() < 1e-9
        for f in model.fingers:
            for kind in ("tip", "pad"):
                err = np.abs(marker(om, state, f"{f}_{kind}") * 1000.0 - ref[f"{f}_{kind}"][i])
                assert err.max() < POINT_TOL_MM, (f, kind, err)
                worst = max(worst, err.max())
        for sensor, path in paths.items():
            if sensor == "hand":
                continue
            r, p = frame(om, state, path)
            err = np.abs(p * 1000.0 - ref[sensor][i])
            assert err.max() < POINT_TOL_MM, (sensor, err)
            axes = np.column_stack([ref[f"{sensor}:{k}"][i] - ref[sensor][i] for k in range(3)])
            assert np.abs(r - axes).max() < 1e-9, sensor
            marker_err = marker(om, state, frame_name(sensor)) * 1000.0 - ref[sensor][i]
            assert np.abs(marker_err).max() < POINT_TOL_MM, sensor
            worst = max(worst, err.max())
    print(f"\n{case}: OpenSim vs fingerfit, largest point discrepancy {worst:.1e} mm")


def test_massless_links_simulate(folder: Path) -> None:
    """The massless bodies between two axes are no obstacle to a forward simulation: with
    gravity and the hand held, the digits swing."""
    model, om, _ = loaded("thumb_index_two_axis", folder)
    sim = om.clone()
    sim.setGravity(osim.Vec3(0, 0, -9.81))
    for name in HAND_COORDINATES:
        sim.updCoordinateSet().get(name).setDefaultLocked(True)
    state = sim.initSystem()
    manager = osim.Manager(sim)
    manager.initialize(state)
    state = manager.integrate(0.05)
    moved = [abs(sim.getCoordinateSet().get(n).getValue(state)) for n in joint_names(model)]
    assert max(moved) > 1e-3
    assert np.isfinite(moved).all()


# --------------------------------------------------------------------------- files


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Path:
    """A noise-free thumb + index session with two-axis joints, its fitted model (the
    case's, as `fit` writes it) exported by the CLI, and its test recording cut to its
    first seconds with two gaps: the hand sensor missing in 5 frames, the index's middle
    sensor in 5 others."""
    d = write_subject(case_subject("thumb_index_two_axis"), tmp_path_factory.mktemp("s") / "S")
    save_model(case_model("thumb_index_two_axis"), d / "model.json")
    rows = pd.read_csv(d / "test.csv")
    rows = rows[rows["time"] < SECONDS]
    frames = np.sort(rows["time"].unique())
    gap_hand = rows["time"].isin(frames[100:105]) & (rows["sensor"] == "hand")
    gap_mid = rows["time"].isin(frames[200:205]) & (rows["sensor"] == "index.middle")
    rows[~(gap_hand | gap_mid)].to_csv(d / "short.csv", index=False)
    res = runner.invoke(app, ["export", str(d / "model.json"), "--osim", str(d / "hand.osim")])
    assert res.exit_code == 0, res.output
    return d


def _cli(*args) -> object:
    return runner.invoke(app, [str(a) for a in args])


def test_motion_file_drives_opensim_to_the_angles_csv(session: Path, tmp_path: Path) -> None:
    """Every frame of the test recording: OpenSim, set to the coordinates it reads from
    OUT.mot, puts every tip and pad marker where the angles CSV has it (0.01 mm), and
    every sensor frame's origin where fingerfit's model carries it."""
    model_path, rec_path = session / "model.json", session / "short.csv"
    for out in ("a.mot", "a.csv"):
        res = _cli("angles", model_path, rec_path, "-o", tmp_path / out, "--rate", 240)
        assert res.exit_code == 0, res.output
    model = load_model(model_path)
    table = osim.TimeSeriesTable(str(tmp_path / "a.mot"))  # OpenSim's own reader
    labels = list(table.getColumnLabels())
    assert labels == [*HAND_COORDINATES, *joint_names(model)]
    assert table.getTableMetaDataAsString("inDegrees") == "yes"
    values = table.getMatrix().to_numpy()
    angles = pd.read_csv(tmp_path / "a.csv")
    assert np.array_equal(np.array(table.getIndependentColumn()), angles["time"].to_numpy())
    om = osim.Model(str(session / "hand.osim"))
    state = om.initSystem()
    rotational = [om.getCoordinateSet().get(n).getMotionType() == 1 for n in labels]
    rad = np.where(rotational, np.radians(values), values)
    rec = read_pose_csv(rec_path, rate_hz=240)
    hand = rec.pose("hand")
    joint_cols = {n: rad[:, labels.index(n)] for n in joint_names(model)}
    ref = fingerfit_points(model, joint_cols, hand.rotation, hand.position)
    missing = ~np.isfinite(values).all(axis=1)
    tips = [f"{f}.{k}" for f in model.fingers for k in ("tip", "pad")]
    # the gaps as the angles CSV has them: without the hand sensor nothing is placed (NaN
    # in the motion, empty in the CSV); the index's middle sensor missing, the model
    # solves its angles (the motion holds them, and the tips below must still agree)
    hand_gap = ~np.isfinite(hand.position).all(axis=1)
    assert hand_gap.sum() == 5 and np.array_equal(missing, hand_gap)
    assert angles.loc[missing, [f"{t}.x" for t in tips]].isna().all(axis=None)
    assert (~np.isfinite(rec.pose("index.middle").position).all(axis=1)).sum() == 5
    worst, checked = 0.0, 0
    for i in np.flatnonzero(~missing):
        set_coordinates(om, state, dict(zip(labels, rad[i], strict=True)))
        for t in tips:
            got = marker(om, state, t.replace(".", "_")) * 1000.0
            err = np.abs(got - angles[[f"{t}.x", f"{t}.y", f"{t}.z"]].to_numpy()[i]).max()
            assert err < POINT_TOL_MM, (i, t, err)
            worst = max(worst, err)
        for sensor, path in sensor_paths(model).items():
            origin = frame(om, state, path)[1] * 1000.0
            want = hand.position[i] if sensor == "hand" else ref[sensor][i]
            assert np.abs(origin - want).max() < POINT_TOL_MM, (i, sensor)
        checked += 1
    print(f"\n.mot in OpenSim: {checked} frames, largest tip/pad discrepancy {worst:.1e} mm")
    assert checked == len(values) - 5


def ik_differences(ik_mot: Path, motion: Path, worst: bool = False) -> dict[str, float]:
    """RMS (``worst``: largest) difference (deg) per rotational coordinate of two motions,
    frames by time; frames where fingerfit has no angle (a sensor missing) left out."""
    ik, ref = osim.TimeSeriesTable(str(ik_mot)), osim.TimeSeriesTable(str(motion))
    t_ik, t_ref = np.array(ik.getIndependentColumn()), np.array(ref.getIndependentColumn())
    rows = np.abs(t_ref[None, :] - t_ik[:, None]).argmin(axis=1)
    assert np.abs(t_ref[rows] - t_ik).max() < 1e-9
    ref_labels = list(ref.getColumnLabels())
    out = {}
    for k, name in enumerate(ik.getColumnLabels()):
        if name in HAND_COORDINATES[3:]:
            continue  # orientations do not place the hand: the tool locks translations
        d = (
            ik.getMatrix().to_numpy()[:, k]
            - ref.getMatrix().to_numpy()[rows, ref_labels.index(name)]
        )
        out[name] = float(np.nanmax(np.abs(d)) if worst else np.sqrt(np.nanmean(d**2)))
    return out


def run_imu_ik(osim_path: Path, sto: Path, out: Path, seconds: float) -> Path:
    """OpenSim's ``IMUInverseKinematicsTool`` on an orientation table (no rotation between
    the table's frame and ground: both are the tracker frame)."""
    tool = osim.IMUInverseKinematicsTool()
    tool.set_model_file(str(osim_path))
    tool.set_orientations_file(str(sto))
    tool.set_sensor_to_opensim_rotations(osim.Vec3(0, 0, 0))
    tool.set_time_range(0, 0.0)
    tool.set_time_range(1, seconds)
    tool.set_results_directory(str(out.parent))
    tool.set_output_motion_file(str(out))
    assert tool.run(False)
    return out


def run_ik_solver(osim_path: Path, sto: Path, out: Path, accuracy: float) -> Path:
    """OpenSim's ``InverseKinematicsSolver`` on the orientations alone, every frame of the
    table, at ``accuracy``; the coordinates written as a motion (degrees)."""
    om = osim.Model(str(osim_path))
    state = om.initSystem()
    table = osim.TimeSeriesTableQuaternion(str(sto))
    rotations = osim.OpenSenseUtilities.convertQuaternionsToRotations(table)
    solver = osim.InverseKinematicsSolver(
        om,
        osim.MarkersReference(),
        osim.OrientationsReference(rotations),
        osim.SimTKArrayCoordinateReference(),
    )
    solver.setAccuracy(accuracy)
    times = list(table.getIndependentColumn())
    cs = om.getCoordinateSet()
    names = [cs.get(i).getName() for i in range(cs.getSize())]
    rows = []
    state.setTime(times[0])
    solver.assemble(state)
    for t in times:
        state.setTime(t)
        solver.track(state)
        rows.append([cs.get(n).getValue(state) for n in names])
    values = np.degrees(np.array(rows))
    return write_motion(
        out, pd.DataFrame({"time": times, **dict(zip(names, values.T, strict=True))}), name="ik"
    )


@functools.cache
def ik_inputs(case: str, folder: Path) -> tuple[Path, Path]:
    """The first second of a noise-free test recording as ``.sto`` and fingerfit's
    ``.mot`` of it, written once."""
    model, _, _ = loaded(case, folder)
    rec: Recording = case_subject(case).session.test[0]
    rec = rec.slice(rec.time < 1.0)
    d = folder / f"ik_{case}"
    d.mkdir()
    write_coordinates(d / "fingerfit.mot", compute_kinematics(model, rec), model, rec)
    return write_orientations(d / "rec.sto", rec), d / "fingerfit.mot"


@pytest.mark.parametrize("case", ["thumb_index_two_axis", "myohand"])
def test_opensim_imu_ik_recovers_fingerfits_angles(case: str, folder: Path) -> None:
    """Noise-free recordings: OpenSim's IMU IK tool on the exported orientations gives
    fingerfit's angles within 0.2 deg RMS for every rotational coordinate."""
    model = case_model(case)
    sto, mot = ik_inputs(case, folder)
    ik = run_imu_ik(folder / f"{case}.osim", sto, sto.parent / "tool.mot", 1.0)
    rms = ik_differences(ik, mot)
    print(
        f"\n{case}: OpenSim IMU IK vs fingerfit, RMS deg: "
        + ", ".join(f"{k} {v:.3f}" for k, v in rms.items())
    )
    assert set(rms) == {*HAND_COORDINATES[:3], *joint_names(model)}
    assert max(rms.values()) < IK_TOL_DEG


@pytest.mark.parametrize("case", ["thumb_index_two_axis_true", "myohand"])
def test_opensim_ik_solver_converges_to_fingerfits_angles(case: str, folder: Path) -> None:
    """A model that is exact for its recording (the true two-axis thumb + index; MyoHand's
    fitted hinges) leaves the IMU tool only its solver's accuracy (1e-4): OpenSim's IK
    solver at 1e-8 gives fingerfit's angles within 0.001 deg in every frame, the two-axis
    joints' order and axes included."""
    sto, mot = ik_inputs(case, folder)
    ik = run_ik_solver(folder / f"{case}.osim", sto, sto.parent / "solver.mot", 1e-8)
    rms = ik_differences(ik, mot, worst=True)
    print(
        f"\n{case}: OpenSim IK solver (1e-8) vs fingerfit, largest difference {max(rms.values()):.1e} deg"
    )
    assert max(rms.values()) < 1e-3


def test_convert_writes_what_opensim_reads(session: Path, tmp_path: Path) -> None:
    """``convert`` to .sto and .trc: OpenSim reads back the recording's orientations
    (w, x, y, z) and sensor origins (m) under the frame names of the model, gaps as NaN."""
    src = session / "short.csv"
    for out in ("r.sto", "r.trc"):
        res = _cli("convert", src, "-o", tmp_path / out, "--rate", 240)
        assert res.exit_code == 0, res.output
    rec = read_pose_csv(src, rate_hz=240)
    quats = osim.TimeSeriesTableQuaternion(str(tmp_path / "r.sto"))
    trc = osim.TimeSeriesTableVec3(str(tmp_path / "r.trc"))
    assert list(quats.getColumnLabels()) == [frame_name(s) for s in rec.sensors]
    assert list(trc.getColumnLabels()) == [frame_name(s) for s in rec.sensors]
    assert np.array_equal(np.array(quats.getIndependentColumn()), rec.time)
    assert np.abs(np.array(trc.getIndependentColumn()) - rec.time).max() < 1e-12
    flat_q, flat_p = quats.flatten(), trc.flatten()  # kept: their matrices are views
    q_all = flat_q.getMatrix().to_numpy()  # w, x, y, z of each sensor in turn
    p_all = flat_p.getMatrix().to_numpy()  # x, y, z of each sensor in turn
    for k, s in enumerate(rec.sensors):
        pose = rec.pose(s)
        q, p = q_all[:, 4 * k : 4 * k + 4], p_all[:, 3 * k : 3 * k + 3]
        ok = np.isfinite(pose.position).all(axis=1)
        r = Rotation.from_quat(q[ok][:, [1, 2, 3, 0]]).as_matrix()
        assert np.abs(r - pose.rotation[ok]).max() < 1e-12, s
        assert np.abs(p[ok] * 1000.0 - pose.position[ok]).max() < 1e-9, s
        assert np.isnan(q[~ok]).all() and np.isnan(p[~ok]).all(), s
    assert (~np.isfinite(rec.pose("hand").position).all(axis=1)).sum() == 5


def test_osim_errors_leave_nothing(session: Path, tmp_path: Path) -> None:
    """An existing output without --overwrite, a file that is no model, two options naming
    one file: one error line, exit 2, no file written or changed."""
    model = session / "model.json"
    existing = tmp_path / "hand.osim"
    existing.write_text("mine")
    urdf = tmp_path / "h.urdf"
    for args, needle in (
        ((model, "--osim", existing, "--urdf", urdf), "exists; pass --overwrite"),
        ((session / "short.csv", "--osim", tmp_path / "x.osim"), "short.csv"),
        ((model, "--osim", urdf, "--urdf", urdf), "--urdf and --osim name the same file"),
    ):
        res = _cli("export", *args)
        assert res.exit_code == 2, res.output
        text = " ".join(res.output.split())
        assert text.startswith("error:") and needle in text, res.output
    assert existing.read_text() == "mine"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hand.osim"]
    res = _cli("export", model, "--osim", existing, "--overwrite")
    assert res.exit_code == 0, res.output
    assert existing.read_text().startswith("<?xml")


def test_landmarks_become_markers_on_their_segments(session: Path, tmp_path: Path) -> None:
    """``--landmarks``: each dorsal joint landmark is a marker on the joint's parent segment
    (it moves with the bone whose head it lies over), each target a marker on ground; at
    the reference posture each is at its landmark, and in any posture where fingerfit's
    model carries it."""
    out = tmp_path / "lm.osim"
    res = _cli(
        "export", session / "model.json", "--osim", out, "--landmarks", session / "landmarks.csv"
    )
    assert res.exit_code == 0, res.output
    assert "4 landmark(s) not made markers (index.tip, thumb.tip, thumb.pad, index.pad)" in (
        " ".join(res.output.split())
    )
    model = load_model(session / "model.json")
    landmarks = read_landmarks(session / "landmarks.csv", units=model.session_units)
    om = osim.Model(str(out))
    state = om.initSystem()
    joints = robot_hand(model).joints
    rng = np.random.default_rng(3)
    t0, r0 = model.reference_poses["hand"]
    for trial in range(3):
        q = {j.name: (rng.uniform(j.lower, j.upper) if trial else 0.0) for j in joints}
        hand_r = r0 @ Rotation.from_rotvec(rng.normal(0, 0.5, 3) * (trial > 0)).as_matrix()
        hand_t = t0 + rng.normal(0, 100.0, 3) * (trial > 0)
        coords = hand_coordinates(model, hand_r[None], hand_t[None])[0]
        set_coordinates(om, state, {**dict(zip(HAND_COORDINATES, coords, strict=True)), **q})
        checked = 0
        for name, p in landmarks.items():
            digit, _, joint = name.partition(".")
            if digit == "target":
                want = p
            elif joint in model.fingers[digit].joints:
                fm = model.fingers[digit]
                depth = list(fm.joints).index(joint)  # carried by the joints before it
                ang = {
                    k.split("_", 1)[1]: np.array([v])
                    for k, v in q.items()
                    if k.startswith(digit + "_")
                }
                # the MP's and CMC's landmarks are on the hand: no joint carries them
                ref = chain_points(fm, "user_axis", ang, p, depth) if depth else p[None]
                want = carry_by_hand(model, hand_r[None], hand_t[None], ref)[0]
                if trial == 0:
                    assert np.abs(want - p).max() < 1e-9
            else:
                continue
            name_in_model = f"target_{joint}" if digit == "target" else f"{digit}_{joint}_dorsal"
            got = marker(om, state, name_in_model) * 1000.0
            assert np.abs(got - want).max() < POINT_TOL_MM, (trial, name)
            checked += 1
        assert checked == len(landmarks) - 4  # all but the tips and pads
