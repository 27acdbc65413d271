"""``fingerfit view``: the .rrd it writes, read back with Rerun's own reader."""

from __future__ import annotations

import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.evaluate.truth import load_truth
from fingerfit.kinematics import compute_kinematics
from fingerfit.model import save_model
from fingerfit.simulate import write_subject

from .conftest import subject

DIGITS = ("thumb", "index", "middle")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    """A simulated session folder (with its truth), its fitted model and the grasp file."""
    from fingerfit.estimate import fit_session

    sub = subject("realistic", 2, DIGITS)
    folder = write_subject(sub, tmp_path_factory.mktemp("view") / "S01")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    path = save_model(model, folder / "model.json")
    return model, sub, folder, path


def _read(path):
    """Entity -> component -> list of (frame, value) of the temporal rows; static rows apart."""
    from rerun.chunk import RrdReader

    rows: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    static: dict[str, set] = defaultdict(set)
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n not in ("rerun.controls.RowId", "time")]
        if chunk.is_static:
            static[chunk.entity_path] |= set(names)
            continue
        frames = batch.column("frame").to_pylist()
        for name in names:
            if name != "frame":
                rows[chunk.entity_path][name] += list(
                    zip(frames, batch.column(name).to_pylist(), strict=True)
                )
        rows[chunk.entity_path]["frame"] += frames
    return rows, static


def test_view_save_writes_every_entity_once_per_frame(simulated, tmp_path):
    pytest.importorskip("rerun")
    pytest.importorskip("mujoco")
    model, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    out = tmp_path / "v" / "grasp.rrd"
    r = CliRunner().invoke(
        app,
        ["view", str(model_path), str(grasp), "--robot", "shadow", "--save", str(out), "-q"],
    )
    assert r.exit_code == 0, r.output
    assert out.is_file() and not list(out.parent.glob(".*part*"))
    rows, static = _read(out)
    rec = sub.session.grasp[0]
    n = rec.n_frames
    expected = [
        "/person/skeleton",
        "/person/joints",
        "/person/axes",
        "/person/tips",
        "/person/pads",
        "/person/orthogonal/tips",
        "/sensors",
        "/truth/tips",
        "/robot/geometry",
        "/robot/tips",
    ]
    expected += [f"/angles/{d}/{a}" for d in DIGITS for a in model.fingers[d].angle_names()]
    assert set(expected) <= set(rows), sorted(set(expected) - set(rows))
    for entity in rows:
        assert sorted(rows[entity]["frame"]) == list(range(n)), entity  # one point per frame
    # The tips, in float64 beside the float32 positions, are compute_kinematics' own.
    kin = compute_kinematics(model, rec)
    tips = np.stack([kin.motions["user_axis"][d].tip for d in model.fingers], axis=1)
    got = np.array([v for _, v in sorted(rows["/person/tips"]["tip_mm"])]).reshape(n, -1, 3)
    np.testing.assert_allclose(got, tips, rtol=0, atol=1e-6)
    shown = np.array([v for _, v in sorted(rows["/person/tips"]["Points3D:positions"])])
    np.testing.assert_allclose(shown, tips, rtol=0, atol=1e-3)  # float32 in the viewer
    # The angles in degrees, the truth's tips as written by the simulator.
    pip = np.array([v[0] for _, v in sorted(rows["/angles/index/pip"]["Scalars:scalars"])])
    np.testing.assert_allclose(
        pip, np.degrees(kin.motions["user_axis"]["index"].angles["pip"]), atol=1e-9
    )
    truth = np.array([v for _, v in sorted(rows["/truth/tips"]["Points3D:positions"])])
    written = load_truth(folder).tips[rec.name]
    np.testing.assert_allclose(truth, np.stack([written[d] for d in DIGITS], axis=1), atol=1e-3)
    assert "Points3D:labels" in static["/person/tips"]


def test_skeleton_is_rigid_and_starts_at_the_model(simulated):
    """The distal segment keeps its length; frame by frame the skeleton ends at the tip."""
    from fingerfit.view import hand_scene

    model, sub, _, _ = simulated
    rec = sub.session.grasp[0]
    scene = hand_scene(model, rec)
    for k, d in enumerate(scene.digits):
        fm = model.fingers[d]
        last = list(fm.joints)[-1]
        if fm.joints[last].migration is not None:
            continue
        length = np.linalg.norm(fm.tip - fm.joints[last].center)
        tip = scene.kinematics.motions["user_axis"][d].tip
        np.testing.assert_allclose(
            np.linalg.norm(tip - scene.centres[:, k, 2], axis=1), length, atol=1e-9
        )
    assert scene.axis_origins.shape == (rec.n_frames, len(scene.axes), 3)
    assert {kind for _, _, kind in scene.axes} == {"flexion", "abduction"}


def test_missing_rerun_is_one_line_naming_the_extra(simulated, tmp_path, monkeypatch):
    _, sub, folder, model_path = simulated
    monkeypatch.setitem(sys.modules, "rerun", None)
    grasp = folder / sub.session.grasp[0].name
    r = CliRunner().invoke(
        app, ["view", str(model_path), str(grasp), "--save", str(tmp_path / "v.rrd")]
    )
    assert r.exit_code == 2
    assert "pip install fingerfit[view]" in r.output
    assert len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "v.rrd").exists()


def test_save_must_be_an_rrd_and_map_needs_a_robot(simulated, tmp_path):
    _, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    r = CliRunner().invoke(
        app, ["view", str(model_path), str(grasp), "--save", str(tmp_path / "v.txt")]
    )
    assert r.exit_code == 2 and "--save" in r.output
    r = CliRunner().invoke(
        app,
        ["view", str(model_path), str(grasp), "--save", str(tmp_path / "v.rrd"), "--map", "m.toml"],
    )
    assert r.exit_code == 2 and "needs --robot" in r.output


# --- fingerfit stream --view-save: the same view, live, fed by the data lane ----------------


def _angles_tips(model, model_path, grasp, tmp_path):
    """The tips ``fingerfit angles`` writes, (n, d, 3) mm."""
    import pandas as pd

    out = tmp_path / "angles.csv"
    r = CliRunner().invoke(app, ["angles", str(model_path), str(grasp), "-o", str(out), "-q"])
    assert r.exit_code == 0, r.output
    table = pd.read_csv(out)
    cols = [f"{d}.tip.{c}" for d in model.fingers for c in "xyz"]
    return table[cols].to_numpy().reshape(len(table), -1, 3)


def test_stream_view_save_has_every_frame_and_the_angles_tips(simulated, tmp_path):
    pytest.importorskip("rerun")
    pytest.importorskip("mujoco")
    from fingerfit.io import read_pose_csv
    from fingerfit.retarget import resolve
    from fingerfit.view import robot_scene

    model, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    out = tmp_path / "live" / "grasp.rrd"
    args = ["stream", str(model_path), "--source", f"replay:{grasp}@50", "--view-save", str(out)]
    r = CliRunner().invoke(app, [*args, "--retarget", "shadow", "-q"])
    assert r.exit_code == 0, r.output
    assert out.is_file() and not list(out.parent.glob(".*part*"))
    rows, static = _read(out)
    n = sub.session.grasp[0].n_frames
    assert f"view {n} logged, 0 dropped" in r.output, r.output  # --view-save: every frame
    expected = ["/person/skeleton", "/person/joints", "/person/axes", "/person/tips"]
    expected += ["/person/pads", "/person/orthogonal/tips", "/sensors"]
    expected += ["/robot/geometry", "/robot/tips"]
    expected += [f"/angles/{d}/{a}" for d in DIGITS for a in model.fingers[d].angle_names()]
    assert set(expected) <= set(rows), sorted(set(expected) - set(rows))
    for entity in rows:
        assert sorted(rows[entity]["frame"]) == list(range(n)), entity  # one row per frame
    want = _angles_tips(model, model_path, grasp, tmp_path)
    got = np.array([v for _, v in sorted(rows["/person/tips"]["tip_mm"])]).reshape(want.shape)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    assert "Points3D:labels" in static["/person/tips"]
    assert "Points3D:labels" in static["/robot/tips"]
    # No live output: the data lane's retargeter steps through every frame, as offline.
    rec = read_pose_csv(grasp)
    offline = robot_scene(model, rec, *resolve("shadow", None, model.hand))
    series = {k.replace("\\", ""): v for k, v in rows.items()}  # entity paths escape ':'
    for j, name in enumerate(offline.joint_names):
        got = [v[0] for _, v in sorted(series[f"/robot_angles/{name}"]["Scalars:scalars"])]
        np.testing.assert_allclose(got, np.degrees(offline.q[:, j]), atol=1e-6, err_msg=name)


def _transforms(rows, entity: str) -> tuple[np.ndarray, np.ndarray]:
    """An entity's transform per frame, in frame order: translation (n, 3), matrix (n, 3, 3)
    (Rerun stores it column by column)."""
    t = np.array([v[0] for _, v in sorted(rows[entity]["Transform3D:translation"])])
    m = np.array([v[0] for _, v in sorted(rows[entity]["Transform3D:mat3x3"])])
    return t, m.reshape(-1, 3, 3).transpose(0, 2, 1)


@pytest.mark.parametrize("robot_name", ["shadow", "allegro"])
def test_view_draws_the_robot_with_its_own_geometry(simulated, tmp_path, robot_name):
    """MJCF (Shadow) and URDF (Allegro): the hand's visual meshes, once, each under its
    link; a transform per link per frame (m, the robot's world) and one per frame for the
    robot's world beside the person (mm). Composed, they put each digit's tip frame where
    the robot's points are drawn (``robot/tips``, from the robot's own kinematics)."""
    pytest.importorskip("rerun")
    pytest.importorskip("mujoco")
    pytest.importorskip("pinocchio")
    from rerun.chunk import RrdReader

    from fingerfit.io import read_pose_csv, write_pose_csv
    from fingerfit.retarget import resolve
    from fingerfit.view.robotgeometry import robot_geometry

    model, sub, folder, model_path = simulated
    rec = read_pose_csv(folder / sub.session.grasp[0].name).slice(slice(0, 240, 3))
    short = write_pose_csv(tmp_path / "g.csv", rec)
    out = tmp_path / "robot.rrd"
    args = ["view", str(model_path), str(short), "--robot", robot_name, "--save", str(out)]
    r = CliRunner().invoke(app, [*args, "-q"])
    assert r.exit_code == 0, r.output
    rows, _ = _read(out)
    assert "/robot/skeleton" not in rows and "/robot/joints" not in rows
    robot, rmap = resolve(robot_name, None, model.hand)
    geometry = robot_geometry(robot, rmap.palm)
    meshes, vertices = 0, 0
    for chunk in RrdReader(out).stream().to_chunks():
        if chunk.is_static and chunk.entity_path.startswith("/robot/geometry/"):
            batch = chunk.to_record_batch()
            if "Mesh3D:vertex_positions" in batch.schema.names:
                meshes += 1
                vertices += len(batch.column("Mesh3D:vertex_positions").to_pylist()[0])
    want = [v for v in geometry.visuals if v.kind == "mesh"]
    assert meshes == len(want) > 10 and vertices == sum(len(v.vertices) for v in want)
    n = rec.n_frames
    world_t, world_m = _transforms(rows, "/robot/geometry")
    assert world_t.shape == (n, 3)
    np.testing.assert_allclose(np.linalg.det(world_m), 1000.0**3, rtol=1e-5)  # m -> mm
    tips = np.array([v for _, v in sorted(rows["/robot/tips"]["Points3D:positions"])])
    zero = np.zeros(robot.nq)
    link0_t, link0_r = geometry.link_poses(zero)
    for k, d in enumerate(rmap.digits):
        frame = rmap.digits[d].tip
        if robot.mujoco_model is not None:  # the site's body
            mj = robot.mujoco_model
            site = mj.site(frame).id
            link = geometry.links.index(mj.body(int(mj.site_bodyid[site])).name)
        else:
            link = geometry.links.index(frame)
        tip0 = robot.pose(zero, frame)[0]
        local = link0_r[0, link].T @ (tip0 - link0_t[0, link])  # m, the link's frame
        entity = "/robot/geometry/" + geometry.links[link].replace(":", "\\:")
        lt, lm = _transforms(rows, entity)
        at = world_t + np.einsum("nij,nj->ni", world_m, lt + lm @ local)
        np.testing.assert_allclose(at, tips[:, k], atol=0.01, err_msg=d)  # mm


def test_a_robot_without_visual_geometry_is_drawn_as_lines(simulated, tmp_path, monkeypatch):
    pytest.importorskip("rerun")
    pytest.importorskip("mujoco")
    from fingerfit.view import scene
    from fingerfit.view.robotgeometry import RobotGeometry

    _, sub, folder, model_path = simulated
    monkeypatch.setattr(scene, "robot_geometry", lambda robot, palm: RobotGeometry([], [], None))
    out = tmp_path / "lines.rrd"
    grasp = folder / sub.session.grasp[0].name
    r = CliRunner().invoke(
        app, ["view", str(model_path), str(grasp), "--robot", "shadow", "--save", str(out), "-q"]
    )
    assert r.exit_code == 0, r.output
    rows, _ = _read(out)
    assert {"/robot/skeleton", "/robot/joints", "/robot/tips"} <= set(rows)
    assert not any(e.startswith("/robot/geometry") for e in rows)


class _Outlet:
    """A live output that keeps what it is sent (the robot lane's pushes)."""

    def __init__(self):
        self.robot = []

    def push(self, angles, tips, valid, arrival, robot=None, source=None):
        self.robot.append(robot[0].copy())

    def has_consumers(self):
        return True

    def close(self):
        pass


def test_view_robot_follows_the_robot_lane_when_the_data_lane_has_no_robot(simulated, tmp_path):
    """With a live output and no bag, the view's robot is what the robot lane sent, at
    the frames it sent; the person has every frame."""
    pytest.importorskip("rerun")
    pytest.importorskip("mujoco")
    from fingerfit.live.sources import Block
    from fingerfit.live.stream import Streamer
    from fingerfit.retarget import Retargeter, resolve
    from fingerfit.view import LiveView

    model, sub, _, _ = simulated
    rec = sub.session.grasp[0].slice(slice(0, 60))
    robot, rmap = resolve("shadow", None, model.hand)
    out = tmp_path / "lane.rrd"
    outlet = _Outlet()
    streamer = Streamer(
        model,
        lsl=outlet,
        retargeter=Retargeter(model, robot, rmap, "tip"),
        max_age=60.0,
        view=LiveView(model, out, ("shadow", None)),
    )
    # Blocks of 1, 2 and 3 frames: the robot lane sends the newest of each.
    sizes = [1, 2, 3] * 10
    starts = np.cumsum([0, *sizes[:-1]])
    for i, k in zip(starts, sizes, strict=True):
        part = rec.slice(slice(i, i + k))
        streamer.process(Block(part, np.full(k, time.monotonic())))
    streamer.close()
    rows, _ = _read(out)
    assert sorted(rows["/person/tips"]["frame"]) == list(range(60))
    sent = [int(i + k - 1) for i, k in zip(starts, sizes, strict=True)]
    assert sorted(rows["/robot/tips"]["frame"]) == sent
    name = robot.joint_names[-1]
    series = {k.replace("\\", ""): v for k, v in rows.items()}  # entity paths escape ':'
    got = [v[0] for _, v in sorted(series[f"/robot_angles/{name}"]["Scalars:scalars"])]
    np.testing.assert_allclose(got, np.degrees([q[-1] for q in outlet.robot]), atol=1e-9)


def test_live_view_drop_policy_counts_what_it_dropped(simulated, tmp_path):
    """``drop`` (the policy of ``--view``): whatever the view's process kept up with, the
    frames logged and dropped add up to those pushed, and the logged ones keep the
    stream's frame numbers and the angles' tips."""
    pytest.importorskip("rerun")
    from fingerfit.view import VIEW_QUEUE_BLOCKS, LiveView

    model, sub, _, _ = simulated
    rec = sub.session.grasp[0].slice(slice(0, 4 * VIEW_QUEUE_BLOCKS))
    out = tmp_path / "drop.rrd"
    view = LiveView(model, out, policy="drop")
    for i in range(rec.n_frames):  # one frame a block: as fast as the loop goes
        view.push(rec.slice(slice(i, i + 1)))
    view.close()
    assert view.frames == rec.n_frames
    assert view.logged + view.dropped == rec.n_frames
    rows, _ = _read(out)
    frames = sorted(rows["/person/tips"]["frame"])
    assert len(frames) == view.logged and set(frames) <= set(range(rec.n_frames))
    want = compute_kinematics(model, rec).motions["user_axis"]
    got = dict(rows["/person/tips"]["tip_mm"])
    for f in frames:
        tips = np.stack([want[d].tip[f] for d in model.fingers])
        np.testing.assert_allclose(np.reshape(got[f], tips.shape), tips, rtol=0, atol=1e-6)


def test_live_view_process_errors_reach_the_stream(simulated, tmp_path):
    """A robot the view's process cannot resolve: the error it raised, in this process,
    and no file left behind."""
    pytest.importorskip("rerun")
    from fingerfit.errors import FingerfitError
    from fingerfit.view import LiveView

    model = simulated[0]
    out = tmp_path / "bad.rrd"
    with pytest.raises(FingerfitError, match="no-such-robot"):
        LiveView(model, out, ("no-such-robot", None))
    assert not list(tmp_path.iterdir())


def test_stream_view_refusals_are_one_line(simulated, tmp_path, monkeypatch):
    _, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    base = ["stream", str(model_path), "--source", f"replay:{grasp}@50"]
    rrd = str(tmp_path / "v.rrd")
    cases = [
        (["--view", "--view-save", rrd], "--view-save"),
        (["--view-save", str(tmp_path / "v.txt")], "must end in .rrd"),
        (["--view-save", str(grasp)], "would overwrite the input"),
        (["--view-save", rrd, "--record", rrd], "--view-save"),
    ]
    for extra, says in cases:
        r = CliRunner().invoke(app, [*base, *extra])
        assert r.exit_code == 2, (extra, r.output)
        assert says in r.output and len(r.output.strip().splitlines()) == 1, (extra, r.output)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    r = CliRunner().invoke(app, [*base, "--view"])
    assert r.exit_code == 2 and "--view-save" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1
    monkeypatch.setitem(sys.modules, "rerun", None)
    r = CliRunner().invoke(app, [*base, "--view-save", rrd])
    assert r.exit_code == 2 and "pip install fingerfit[view]" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1
    assert not (tmp_path / "v.rrd").exists()


# --- fingerfit view --web: the web viewer, and a screenshot of it in headless Chromium ------


@pytest.fixture(scope="module")
def web_view(simulated):
    """``fingerfit view MODEL GRASP --web`` serving, on free ports; its address."""
    pytest.importorskip("rerun")
    from fingerfit.view.webshot import served_view

    _, sub, folder, model_path = simulated
    grasp = folder / sub.session.grasp[0].name
    with served_view([str(model_path), str(grasp)]) as url:
        yield url


def _listening_on(port: int) -> set[str]:
    """The IPv4/IPv6 addresses a TCP port listens on here, as ``/proc/net/tcp*`` writes
    them (hex); empty where there is no ``/proc``."""
    found = set()
    for name in ("tcp", "tcp6"):
        table = Path("/proc/net") / name
        if not table.exists():
            continue
        for line in table.read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            address, hexport = local.split(":")
            if state == "0A" and int(hexport, 16) == port:  # 0A: LISTEN
                found.add(address)
    return found


def test_web_view_serves_the_viewer_and_the_data(web_view):
    from urllib.parse import parse_qs, urlsplit
    from urllib.request import urlopen

    parts = urlsplit(web_view)
    assert parts.scheme == "http" and parts.hostname == "127.0.0.1", web_view
    data = parse_qs(parts.query)["url"][0]
    assert data.startswith("rerun+http://127.0.0.1:") and data.endswith("/proxy"), data
    with urlopen(web_view, timeout=60) as page:  # the viewer's page, from this machine
        assert page.status == 200 and b"re_viewer" in page.read()
        policy = page.headers["Content-Security-Policy"]
    grpc_port = urlsplit(data).port
    assert f"connect-src 'self' http://127.0.0.1:{grpc_port} " in policy, policy
    assert "https:" not in policy and "*" not in policy, policy
    if Path("/proc/net/tcp").exists():  # both ports we print listen on 127.0.0.1 only
        for port in (parts.port, grpc_port):
            assert _listening_on(port) == {"0100007F"}, (port, _listening_on(port))


def test_web_view_listens_on_this_machine_only(web_view):
    """The socket table of ``fingerfit view --web`` and of every process it started:
    every listening socket is on 127.0.0.1 or ::1 (the two printed ports among them)."""
    from urllib.parse import parse_qs, urlsplit

    psutil = pytest.importorskip("psutil")
    parts = urlsplit(web_view)
    grpc_port = urlsplit(parse_qs(parts.query)["url"][0]).port
    listening = set()
    for proc in psutil.Process().children(recursive=True):
        for conn in proc.net_connections(kind="inet"):
            if conn.status == psutil.CONN_LISTEN:
                listening.add((conn.laddr.ip, conn.laddr.port))
    assert {("127.0.0.1", parts.port), ("127.0.0.1", grpc_port)} <= listening, listening
    assert {ip for ip, _ in listening} <= {"127.0.0.1", "::1"}, listening


def test_web_view_renders_in_headless_chromium_and_asks_nothing_beyond_this_machine(
    web_view, tmp_path
):
    """The web viewer draws the hand: a screenshot that is not blank, with the hand's
    coloured axes, tips and labels in the 3D view (``fingerfit.view.webshot``); and every
    request the page makes to another host is refused by its Content-Security-Policy
    before it is sent (Chromium's resolver, which maps other hosts to nothing, would
    fail them otherwise with another reason)."""
    from urllib.parse import urlsplit

    from fingerfit.view.webshot import (
        SCENE_BOX,
        HeadlessChromium,
        coloured_share,
        find_chromium,
        png_pixels,
        shoot,
    )

    binary = find_chromium()
    if binary is None:
        pytest.skip(
            "Debian chromium is not installed (make test installs it when apt-get is available)"
        )
    with HeadlessChromium(binary, (1400, 800)) as browser:
        webgl = browser.webgl()
        browser.record_requests()
        png = shoot(browser, web_view, lambda p: not webgl or coloured_share(p, SCENE_BOX) > 0.005)
        requests = browser.requests()
    local = [r for r in requests if urlsplit(r["url"]).hostname in ("127.0.0.1", "localhost")]
    assert local and all(r["blocked"] is None for r in local), local  # the page, its data
    away = [r for r in requests if r not in local]
    assert all(r["blocked"] == "csp" for r in away), away  # refused, none sent
    (tmp_path / "web.png").write_bytes(png)  # kept by pytest's tmp_path, to look at
    if not webgl:
        pytest.skip(
            "no WebGL in headless Chromium here (SwiftShader unavailable): the drawing check "
            "is skipped; the page, its data and its requests are checked"
        )
    pixels = png_pixels(png)
    assert pixels.shape == (800, 1400, 3)
    assert pixels.std() > 0.05  # not a blank page
    assert coloured_share(pixels, SCENE_BOX) > 0.005  # the hand, drawn in the 3D view


def _chunks(path) -> dict[str, int]:
    """Entity -> the temporal chunks of a .rrd."""
    from rerun.chunk import RrdReader

    out: dict[str, int] = defaultdict(int)
    for chunk in RrdReader(path).stream().to_chunks():
        if not chunk.is_static:
            out[chunk.entity_path] += 1
    return out


def test_live_view_save_joins_blocks_into_few_chunks(simulated, tmp_path):
    """``--view-save`` gets a stream's frames in small blocks; the file holds them in
    chunks of FILE_BATCH_FRAMES (each chunk carries about 1.2 kB of Rerun's own), so it is
    no larger than the file of the same frames logged at once."""
    pytest.importorskip("rerun")
    from fingerfit.view import FILE_BATCH_FRAMES, LiveView, hand_scene, save_rrd

    model, sub, _, _ = simulated
    rec = sub.session.grasp[0].slice(slice(0, 600))
    view = LiveView(model, tmp_path / "live.rrd")
    for i in range(0, rec.n_frames, 3):  # 3 frames a block, as a real-time stream
        view.push(rec.slice(slice(i, i + 3)))
    view.close()
    assert view.logged == rec.n_frames
    chunks = _chunks(tmp_path / "live.rrd")
    assert chunks and max(chunks.values()) <= -(-rec.n_frames // FILE_BATCH_FRAMES), chunks
    whole = save_rrd(hand_scene(model, rec, compute_kinematics(model, rec)), tmp_path / "w.rrd")
    assert (tmp_path / "live.rrd").stat().st_size < 1.05 * whole.stat().st_size
    rows, _ = _read(tmp_path / "live.rrd")
    assert sorted(rows["/person/tips"]["frame"]) == list(range(rec.n_frames))


def test_a_script_makes_a_live_view_without_a_main_guard(simulated, tmp_path):
    """The view's process runs nothing of the script that made it: no
    ``if __name__ == "__main__":`` is needed, and the script's top level runs once."""
    pytest.importorskip("rerun")
    import subprocess

    _, sub, folder, model_path = simulated
    script = tmp_path / "live_script.py"
    script.write_text(
        "from pathlib import Path\n"
        "from fingerfit.io import read_pose_csv\n"
        "from fingerfit.model import load_model\n"
        "from fingerfit.view import LiveView\n"
        f"model = load_model({str(model_path)!r})\n"
        f"rec = read_pose_csv({str(folder / sub.session.grasp[0].name)!r}).slice(slice(0, 40))\n"
        "with open('ran.txt', 'a') as fh:\n"
        "    fh.write('top level\\n')\n"
        "view = LiveView(model, Path('live.rrd'))\n"
        "view.push(rec)\n"
        "view.close()\n"
        "print('logged', view.logged)\n"
    )
    res = subprocess.run(
        [sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "logged 40", res.stdout + res.stderr
    assert (tmp_path / "ran.txt").read_text() == "top level\n"
    assert (tmp_path / "live.rrd").is_file()
