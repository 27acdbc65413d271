"""Retargeting onto robot hands: solver recovery, pinch, limits, couplings, joint map, maps, CLI."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

from fingerfit.errors import FingerfitError
from fingerfit.retarget import resolve, retarget, setup
from fingerfit.retarget.joint import copy_angles
from fingerfit.retarget.limits import limits_of
from fingerfit.retarget.maps import check_map, parse_map
from fingerfit.retarget.palm import robot_palm
from fingerfit.retarget.robots import load_robot
from fingerfit.retarget.solve import MM, TipOptions, TipProblem, TipSolver, solve_tip

from .conftest import subject

FINGERS = ("index", "middle", "ring", "little")


def _problem(name: str, hand: str = "right"):
    robot, rmap = resolve(name, None, hand)
    lim = limits_of(robot, rmap)
    hold = lim.project(np.zeros(robot.nq))
    palm = robot_palm(robot, rmap, hold)
    frames = [d.tip for d in rmap.digits.values()]
    held = set(robot.ancestors(rmap.palm)) | {robot.joint_names.index(j) for j in rmap.neutral}
    free = np.array(sorted(set().union(*(set(robot.ancestors(f)) for f in frames)) - held))
    return robot, rmap, lim, TipProblem(robot, palm, frames, free, hold, lim)


def _trajectory(robot, lim, hold, free, n=720, seed=0):
    """A smooth feasible joint trajectory from the neutral posture to a random one and back
    (``n`` frames at 240 Hz: 3 s, joints up to ~2 rad/s, like a grasp)."""
    rng = np.random.default_rng(seed)
    goal = lim.project(rng.uniform(np.maximum(robot.lower, -1.6), np.minimum(robot.upper, 1.6)))
    s = (0.5 - 0.5 * np.cos(2 * np.pi * np.linspace(0, 1, n)))[:, None]
    q = hold + (goal - hold) * s
    fixed = np.setdiff1d(np.arange(robot.nq), free)
    q[:, fixed] = hold[fixed]
    return lim.project(q)


@pytest.mark.parametrize("name", ["allegro", "shadow"])
def test_tip_method_recovers_the_robots_own_fingertips(name):
    """Targets = the robot's own tips along a known joint trajectory: recovered < 0.5 mm
    (with the lag-removing polish; the default smoothness lags < 1 mm at ~2 rad/s)."""
    robot, _, lim, prob = _problem(name)
    q_true = _trajectory(robot, lim, prob.hold, prob.free)
    assert lim.violations(q_true) == 0
    palm = prob.palm
    tips = (robot.positions(q_true, prob.frames) - palm.origin) @ palm.rotation * MM
    fixed = np.setdiff1d(np.arange(robot.nq), prob.free)
    for options, worst, median in (
        (TipOptions(polish_smooth=1.0), 0.5, 0.05),
        (TipOptions(), 1.0, 0.1),
    ):
        res = solve_tip(prob, tips, options=options)
        got = (robot.positions(res.q, prob.frames) - palm.origin) @ palm.rotation * MM
        err = np.linalg.norm(got - tips, axis=2)
        assert err.max() < worst, (options, err.max())
        assert np.median(err) < median, (options, np.median(err))
        assert lim.violations(res.q) == 0
        # held joints (the wrist; none on Allegro) never move
        np.testing.assert_array_equal(
            res.q[:, fixed], np.broadcast_to(prob.hold[fixed], (len(res.q), fixed.size))
        )


def test_pinch_term_brings_two_robot_tip_points_together():
    """Synthetic pinch: thumb and index tips driven by the pinch term alone (target vector 0,
    weight ramping from 0 to 1); the other fingers hold their tip targets."""
    robot, _rmap, lim, prob = _problem("shadow")
    frames = prob.frames
    ith, iff = frames.index("robot0:S_thtip"), frames.index("robot0:S_fftip")
    n = 60
    tips = np.repeat(
        ((robot.positions(prob.hold[None], frames) - prob.palm.origin) @ prob.palm.rotation * MM),
        n,
        axis=0,
    )
    w_tip = np.ones((n, len(frames)))
    w_tip[:, [ith, iff]] = 0.0
    weight = np.clip(np.linspace(-0.5, 1.5, n), 0, 1)[:, None]
    res = solve_tip(prob, tips, w_tip, [(ith, iff)], np.zeros((n, 1, 3)), weight)
    pts = robot.positions(res.q, ["robot0:S_thtip", "robot0:S_fftip"])
    dist = np.linalg.norm(pts[:, 0] - pts[:, 1], axis=1) * MM
    assert dist[0] > 100.0  # no pinch weight: the neutral posture, thumb far from the index
    assert dist[-5:].max() < 3.0, dist[-5:]  # full pinch weight: the points meet
    assert lim.violations(res.q) == 0


@pytest.mark.parametrize("name", ["allegro", "shadow"])
def test_added_pad_point_moves_with_its_frame(name):
    """A map's ``pad_offset`` point (URDF operational frame / MJCF site) sits at the offset in
    its frame's axes for any configuration, and its Jacobian matches finite differences."""
    robot, rmap = resolve(name, None, "right")
    frame, offset = rmap.digits["index"].tip, np.array([0.012, -0.003, 0.004])
    robot.add_point("probe", frame, offset)
    rng = np.random.default_rng(3)
    q = rng.uniform(np.maximum(robot.lower, -2), np.minimum(robot.upper, 2), (5, robot.nq))
    got = robot.positions(q, ["probe"])[:, 0]
    for qi, g in zip(q, got, strict=True):
        o, r = robot.pose(qi, frame)
        np.testing.assert_allclose(g, o + r @ offset, atol=1e-12)
    pos, jac = robot.jacobians(q[0], robot.frame_ids(["probe"]))
    eps = 1e-7
    num = np.stack(
        [
            (robot.positions(q[0] + eps * np.eye(robot.nq)[i], ["probe"])[0, 0] - pos[0]) / eps
            for i in range(robot.nq)
        ],
        axis=1,
    )
    np.testing.assert_allclose(jac[0], num, atol=1e-6)
    if name == "allegro":  # the shipped map puts the pads on the tip spheres' palmar side
        assert rmap.digits["index"].pad == "fingerfit:index.pad"
        hold = np.zeros(robot.nq)
        o, r = robot.pose(hold, "link_3.0_tip")
        pad = robot.positions(hold[None], [rmap.digits["index"].pad])[0, 0]
        palm = robot_palm(robot, rmap, hold)
        assert np.linalg.norm(pad - o) == pytest.approx(0.012)
        assert (pad - o) @ palm.rotation[:, 2] == pytest.approx(-0.012)  # palmar = -dorsal


def test_solving_in_blocks_equals_solving_at_once():
    """The live stream solves blocks as they arrive: the warm start carries over exactly."""
    robot, _, lim, prob = _problem("shadow")
    q_true = _trajectory(robot, lim, prob.hold, prob.free, n=120, seed=4)
    tips = (robot.positions(q_true, prob.frames) - prob.palm.origin) @ prob.palm.rotation * MM
    whole = solve_tip(prob, tips).q
    solver = TipSolver(prob)
    parts = [solver.solve(tips[a:b]).q for a, b in ((0, 1), (1, 7), (7, 64), (64, 120))]
    np.testing.assert_array_equal(np.vstack(parts), whole)


def test_limits_and_couplings_hold_for_any_input():
    robot, _rmap, lim, _ = _problem("shadow")
    rng = np.random.default_rng(1)
    q = rng.uniform(-3, 3, (2000, robot.nq))
    p = lim.project(q)
    assert lim.violations(p) == 0
    assert lim.violations(q) > 0
    # feasible configurations are left alone
    np.testing.assert_allclose(lim.project(p), p, atol=1e-12)
    # the J1/J0 band: 0.00705 J0 - 0.00805 J1 within +-0.001 for every finger
    for f in ("FF", "MF", "RF", "LF"):
        j0 = p[:, robot.joint_names.index(f"robot0:{f}J0")]
        j1 = p[:, robot.joint_names.index(f"robot0:{f}J1")]
        assert np.all(np.abs(0.00705 * j0 - 0.00805 * j1) <= 0.001 + 1e-12)


ROBOT_XML = """
<mujoco model="toy">
  <compiler angle="radian"/>
  <worldbody>
    <body name="palm">
      <body name="f1" pos="0 0.02 0.05">
        <joint name="a_mp" type="hinge" axis="1 0 0" range="-0.5 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.04" size="0.008"/>
        <body name="f2" pos="0 0 0.04">
          <joint name="a_pip" type="hinge" axis="1 0 0" range="0 1.6"/>
          <geom type="capsule" fromto="0 0 0 0 0 0.03" size="0.007"/>
          <site name="a_tip" pos="0 0 0.03"/>
        </body>
      </body>
      <body name="g1" pos="0 -0.02 0.05">
        <joint name="b_mp" type="hinge" axis="1 0 0" range="0 1.5"/>
        <geom type="capsule" fromto="0 0 0 0 0 0.04" size="0.008"/>
        <site name="b_tip" pos="0 0 0.04"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""

MAP = """
[robot]
name = "toy"
file = "toy.xml"
hand = "right"
palm = "palm"
distal = [0, 0, 1]
dorsal = [0, 1, 0]

[digits.index]
tip = "a_tip"
base = "a_mp"
[digits.index.joints]
mp = { robot = "a_mp", sign = -1, scale = 0.5, offset = 0.1 }
pip = "a_pip"

[digits.middle]
tip = "b_tip"
base = "b_mp"
[digits.middle.joints]
mp = "b_mp"

[[coupling]]
joints = ["a_pip", "a_mp"]
coef = [1.0, -1.0]
range = [0.0, 0.2]
"""


@pytest.fixture
def toy(tmp_path):
    (tmp_path / "toy.xml").write_text(ROBOT_XML)
    (tmp_path / "toy.toml").write_text(MAP)
    rmap = parse_map(tmp_path / "toy.toml")
    robot = load_robot(rmap.robot_file)
    check_map(rmap, robot)
    return robot, rmap, tmp_path


def test_joint_method_maps_sign_scale_offset_then_limits_and_coupling(toy):
    robot, rmap, _ = toy
    lim = limits_of(robot, rmap)
    mp = np.array([0.0, -0.4, 1.0, 0.2, np.nan])
    pip = np.array([0.0, 0.1, 0.3, 2.0, 0.5])
    angles = {"index": {"mp": mp, "pip": pip}, "middle": {"mp": np.array([0.3, 0.3, 2.0, -1, 0.4])}}
    q, held = copy_angles(angles, rmap, robot.joint_names, np.zeros(robot.nq), lim)
    a_mp, a_pip, b_mp = (robot.joint_names.index(j) for j in ("a_mp", "a_pip", "b_mp"))
    # a_mp = -0.5 mp + 0.1 -> 0.1, 0.3, -0.4, 0.0, (missing: previous 0.0); -0.4 is
    # below the driver range the coupling allows (a_pip >= 0 needs a_mp >= -0.2)
    np.testing.assert_allclose(q[:, a_mp], [0.1, 0.3, -0.2, 0.0, 0.0])
    # a_pip within [a_mp, a_mp + 0.2] (coupling) and [0, 1.6]
    np.testing.assert_allclose(q[:, a_pip], [0.1, 0.3, 0.0, 0.2, 0.2])
    np.testing.assert_allclose(q[:, b_mp], [0.3, 0.3, 1.5, 0.0, 0.4])  # clipped to [0, 1.5]
    assert held == 1
    assert lim.violations(q) == 0


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (('tip = "a_tip"', 'tip = "nope"'), "digits.index.tip"),
        (('mp = "b_mp"', 'mp = "b_xx"'), "digits.middle.joints.mp.robot"),
        (('palm = "palm"', 'palm = "hand"'), "robot.palm"),
        (('hand = "right"', 'hand = "up"'), "robot.hand"),
        (("sign = -1", "sign = 2"), "digits.index.joints.mp.sign"),
        (('pip = "a_pip"', 'pip = "a_pip"\nknee = "a_mp"'), "digits.index.joints.knee"),
        (("range = [0.0, 0.2]", "range = [0.5, 0.2]"), "coupling[0].range"),
        (('joints = ["a_pip", "a_mp"]', 'joints = ["a_pip", "zz"]'), "coupling[0].joints"),
        (('tip = "b_tip"', 'tip = "b_tip"\npad_offset = [12, 0, 0]'), "digits.middle.pad_offset"),
        (('tip = "b_tip"', 'tip = "b_tip"\npad_offset = [0.01, 0]'), "digits.middle.pad_offset"),
    ],
)
def test_bad_map_names_file_and_field(toy, edit, field):
    robot, _, tmp = toy
    path = tmp / "bad.toml"
    path.write_text(MAP.replace(*edit))
    with pytest.raises(FingerfitError) as exc:
        check_map(parse_map(path), robot)
    msg = str(exc.value)
    assert "bad.toml" in msg and f"field '{field}'" in msg and "\n" not in msg


def test_not_toml_is_one_line(tmp_path):
    p = tmp_path / "m.toml"
    p.write_text("[robot\nname=")
    with pytest.raises(FingerfitError, match=r"m\.toml.*not valid TOML"):
        parse_map(p)


@pytest.fixture(scope="module")
def hand():
    from fingerfit.estimate import fit_session

    sub = subject("realistic", 2, FINGERS)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    return model, sub.session.grasp[0]


def test_person_onto_allegro_tip_beats_joint_and_keeps_limits(hand):
    model, rec = hand
    robot, rmap = resolve("allegro", None, model.hand)
    s = setup(model, robot, rmap)
    assert s.digits == ["index", "middle", "ring"]  # Allegro has no little finger
    assert set(s.scale) == set(s.digits) and all(1.0 < v < 1.6 for v in s.scale.values())
    n = 1500
    rec = rec.select(slice(0, n)) if hasattr(rec, "select") else rec
    tip = retarget(model, rec, robot, rmap, "tip")
    joint = retarget(model, rec, robot, rmap, "joint")
    for r in (tip, joint):
        assert r.violations == 0 and np.isfinite(r.q).all()
        assert r.q.shape == (len(rec.time), robot.nq)
    e_tip = np.linalg.norm(tip.tips - tip.targets, axis=2)
    e_joint = np.linalg.norm(joint.tips - joint.targets, axis=2)
    assert np.median(e_tip) < 1.0
    assert np.median(e_tip) < 0.2 * np.median(e_joint)


def test_left_hand_is_mirrored_onto_the_right_shadow(hand):
    model, _ = hand
    robot, rmap = resolve("shadow", None, model.hand)
    s = setup(model, robot, rmap)
    assert s.mirror == (model.hand == "left")
    # after mirroring, the index base lies radially (+y) of the little finger's, like the robot's
    tg = {d: s.robot_base[d] for d in s.digits}
    m = -1.0 if s.mirror else 1.0
    assert m * (s.person_base["index"][1] - s.person_base["little"][1]) > 0
    assert tg["index"][1] > tg["little"][1]


def test_cli_writes_csv_and_identical_npz(hand, tmp_path):
    from typer.testing import CliRunner

    from fingerfit.cli import app
    from fingerfit.io.posewrite import write_pose_csv
    from fingerfit.model import save_model

    model, rec = hand
    save_model(model, tmp_path / "model.json")
    src = write_pose_csv(tmp_path / "grasp.csv", rec, units=model.session_units)
    out = tmp_path / "o" / "q.csv"
    out.parent.mkdir()
    r = CliRunner().invoke(
        app,
        [
            "retarget",
            str(tmp_path / "model.json"),
            str(src),
            "--robot",
            "allegro",
            "--method",
            "joint",
            "-o",
            str(out),
            "-q",
        ],
    )
    assert r.exit_code == 0, r.output
    table = pd.read_csv(out)
    robot, _ = resolve("allegro", None, model.hand)
    assert list(table.columns) == ["time", *robot.joint_names]
    z = np.load(out.with_suffix(".npz"))
    assert list(z["joint_names"]) == list(robot.joint_names)
    np.testing.assert_array_equal(z["q"], table[list(robot.joint_names)].to_numpy())
    np.testing.assert_array_equal(z["time"], table["time"].to_numpy())


@pytest.mark.parametrize("name", ["shadow", "allegro"])
def test_whole_hand_pinch_brings_the_robot_pads_together(name):
    """Simulated whole hand (thumb, pad points), pinch recording: in every frame of the
    person's first thumb-index pinch hold (``events.csv``) the tip method's robot pad
    points are < 3 mm apart (the joint method's are centimetres apart); the pinch term
    engages at the contact distance of the person's own pinch holds (the model's
    ``pinch_contacts``), not at a fixed one. On the Allegro the thumb's fingertip target
    is ~7 cm out of reach: plain Gauss-Newton alternated between two postures there and
    held the pinch ~6 mm open; the trust region closes it."""
    from fingerfit.estimate import fit_session
    from fingerfit.session import PoseSeries, Recording

    sub = subject("realistic", 2, ("thumb", *FINGERS))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    contact = model.pinch_contact("thumb", "index")
    assert contact is not None and contact.contact_mm["user_axis"] < 5.0
    full = sub.session.recording("pinch.csv")
    ev = next(e for e in sub.session.events if e.recording == "pinch.csv" and e.is_pinch)
    robot, rmap = resolve(name, None, model.hand)
    first = int(np.searchsorted(full.time, ev.start))
    cut = slice(max(first - 240, 0), first + 360)  # the approach and the first touch
    rec = Recording(
        full.name,
        full.time[cut],
        {k: PoseSeries(v.position[cut], v.rotation[cut]) for k, v in full.poses.items()},
    )
    touch = (rec.time >= ev.start) & (rec.time <= ev.end)
    assert touch.sum() > 20
    gaps = {}
    for method in ("tip", "joint"):
        res = retarget(model, rec, robot, rmap, method)
        assert res.violations == 0
        p = robot.positions(res.q, [rmap.digits["thumb"].pad, rmap.digits["index"].pad])
        gaps[method] = np.linalg.norm(p[:, 0] - p[:, 1], axis=1)[touch] * MM
        if method == "tip":
            assert any("pinch thumb-index: the pads touch below" in n for n in res.notes)
    assert np.max(gaps["tip"]) < 3.0, np.max(gaps["tip"])
    assert np.median(gaps["joint"]) > 20.0


def _hold_gaps(model, sub, name, event, before_s=1.0):
    """The robot's thumb-index pad distance (mm) in every frame of the person's pinch hold
    ``event``, retargeting ``pinch.csv`` from ``before_s`` seconds before it."""
    from fingerfit.session import PoseSeries, Recording

    full = sub.session.recording("pinch.csv")
    cut = (full.time >= event.start - before_s) & (full.time <= event.end)
    rec = Recording(
        full.name,
        full.time[cut],
        {k: PoseSeries(v.position[cut], v.rotation[cut]) for k, v in full.poses.items()},
    )
    robot, rmap = resolve(name, None, model.hand)
    res = retarget(model, rec, robot, rmap, "tip")
    assert res.violations == 0
    hold = (rec.time >= event.start) & (rec.time <= event.end)
    p = robot.positions(res.q[hold], [rmap.digits["thumb"].pad, rmap.digits["index"].pad])
    return np.linalg.norm(p[:, 0] - p[:, 1], axis=1) * MM


def test_robot_pinch_closes_in_holds_the_fit_did_not_see():
    """Thumb + index hand calibrated without ``pinch.csv``'s events (its model knows one
    touch, in the opposition recording), then ``pinch.csv`` retargeted: holds the pads and
    the contact distance were not fitted to, as a later or live recording is. The model's
    touching pads come 5.2 mm apart in the third hold against a contact distance of 1.8 mm
    from the one touch it knew: the robot's pads stayed 3.5 mm apart. The contact distance
    now covers a hold the pads were not fitted to (leave-one-event-out; one event: the
    priors), and the robot's gap is flat near contact: every hold frame < 3 mm on both
    robots (measured 0.4 and 0.8 mm)."""
    from dataclasses import replace

    from fingerfit.estimate import fit_session

    sub = subject("realistic", 6, ("thumb", "index"))
    events = [e for e in sub.session.events if e.recording != "pinch.csv"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(replace(sub.session, events=events))
    assert model.pinch_contact("thumb", "index").events == 1
    holds = [e for e in sub.session.events if e.recording == "pinch.csv" and e.is_pinch]
    for name in ("shadow", "allegro"):
        gaps = _hold_gaps(model, sub, name, holds[-1])
        assert gaps.size > 100 and gaps.max() < 3.0, (name, gaps.max())


def test_robot_pinch_leaves_a_posture_caught_at_its_limits():
    """Allegro, thumb + index hand (seed 1): approaching the third tip pinch the robot's
    index and thumb came to rest at their joint limits on the far sides of the pinch, a
    posture from which no Gauss-Newton step closes it: the pads stayed 21.3 mm apart through
    the whole hold while the first two closed to 0.6 mm. The pinch restart closes the pinch
    alone from there and solves the frame again: every hold frame < 3 mm (0.9 mm)."""
    from fingerfit.estimate import fit_session

    sub = subject("realistic", 1, ("thumb", "index"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    holds = [e for e in sub.session.events if e.recording == "pinch.csv" and e.is_pinch]
    gaps = _hold_gaps(model, sub, "allegro", holds[-1], before_s=0.85)
    assert gaps.size > 100 and gaps.max() < 3.0, gaps.max()


def test_cli_signature_names_mirror_the_real_ones():
    from fingerfit.cli import _names
    from fingerfit.retarget import METHODS, Retargeter
    from fingerfit.retarget.maps import BUILTIN

    assert _names.RETARGET_METHODS == METHODS
    assert _names.RETARGET_ROBOTS == tuple(BUILTIN)
    import inspect

    from fingerfit.cli.retarget import retarget as command

    # No --contact-mm: the Retargeter's own default (per pair, from the model).
    default = inspect.signature(Retargeter).parameters["contact_mm"].default
    assert inspect.signature(command).parameters["contact_mm"].default is default is None


def test_shipped_maps_are_package_data():
    """The maps ship inside the package (pyproject package-data) and name real robot frames."""
    from importlib import resources

    maps = resources.files("fingerfit.retarget") / "maps"
    names = sorted(p.name for p in maps.iterdir() if p.name.endswith(".toml"))
    assert names == ["allegro_left.toml", "allegro_right.toml", "shadow.toml"]
    import tomllib
    from pathlib import Path

    pyproject = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    assert "maps/*.toml" in pyproject["tool"]["setuptools"]["package-data"]["fingerfit.retarget"]


@pytest.mark.parametrize("method", ["tip", "joint"])
def test_retargeter_in_blocks_equals_the_whole_recording(hand, method):
    """Live retargeting (blocks as they arrive, a digit's sensors all missing across a block
    boundary: nothing can solve it, it keeps its pose) gives the offline joints (to
    rounding: the person's kinematics of a short block take another NumPy path, equal to
    ~1e-14). One sensor missing is solved by the model instead: no frame is held."""
    from fingerfit.retarget import Retargeter
    from fingerfit.session import PoseSeries, Recording

    model, rec = hand
    n = 90
    robot, rmap = resolve("allegro", None, model.hand)

    def cut_with_gap(sensors: tuple[str, ...]) -> Recording:
        poses = {}
        for k, v in rec.poses.items():
            pos, rot = v.position[:n].copy(), v.rotation[:n].copy()
            if k in sensors:
                pos[28:41] = np.nan  # missing from frame 28 to 40
                rot[28:41] = np.nan
            poses[k] = PoseSeries(pos, rot)
        return Recording(rec.name, rec.time[:n], poses)

    solved = retarget(model, cut_with_gap(("index.middle",)), robot, rmap, method)
    assert not any("missing" in note for note in solved.notes)
    assert np.isfinite(solved.q).all()
    cut = cut_with_gap(("index.proximal", "index.middle", "index.distal"))
    whole = retarget(model, cut, robot, rmap, method)
    assert any("missing" in note for note in whole.notes)
    live = Retargeter(model, robot, rmap, method)
    parts = []
    for a, b in ((0, 1), (1, 30), (30, 35), (35, 90)):
        block = Recording(
            rec.name,
            cut.time[a:b],
            {k: PoseSeries(v.position[a:b], v.rotation[a:b]) for k, v in cut.poses.items()},
        )
        parts.append(live.step(block)[0])
    np.testing.assert_allclose(np.vstack(parts), whole.q, rtol=0, atol=1e-9)


_RENDER = """
import sys, numpy as np
from fingerfit.retarget import resolve
from fingerfit.retarget.figure import render_robot
from fingerfit.retarget.palm import robot_palm
robot, rmap = resolve(sys.argv[1], None, "right")
q = np.zeros((2, robot.nq))
q[1] = np.clip(1.2, robot.lower, robot.upper)  # every joint flexed
palm = robot_palm(robot, rmap, q[0])
out = render_robot(robot, q, palm, (160, 120))
if isinstance(out, str):
    print("reason:", out)
else:
    a, b = (x.astype(float) for x in out)
    print("shape", out[0].shape, "std", a.std(), "changed", np.mean(np.abs(a - b) > 30))
"""


@pytest.mark.parametrize("name", ["shadow", "allegro"])
def test_figure_renders_an_mjcf_robot_with_mujoco(name):
    """A fresh process (MuJoCo picks its OpenGL platform when first imported): the Shadow
    MJCF is rendered offscreen (EGL on this headless machine) and the image changes with
    the posture; the Allegro URDF gets the reason instead."""
    import os
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "DISPLAY")}
    r = subprocess.run(
        [sys.executable, "-c", _RENDER, name], capture_output=True, text=True, env=env, timeout=120
    )
    assert r.returncode == 0, r.stderr[-2000:]
    line = r.stdout.strip().splitlines()[-1]
    if name == "allegro":
        assert line == "reason: MuJoCo renders MJCF robots; this one is URDF"
        return
    if "rendering unavailable" in line:  # a machine without any OpenGL platform
        pytest.skip(line)
    words = line.split()
    assert words[0] == "shape", line
    assert float(words[words.index("std") + 1]) > 10.0  # not a blank image
    assert float(words[words.index("changed") + 1]) > 0.01  # the fingers moved in the image
