"""The dex-retargeting comparison of ``bench/retarget.py`` and its peer ``bench/dex_peer.py``.

The frame conversion, the pad offsets handed to dex-retargeting and the peer's URDF copy
are checked against fingerfit's own robot kinematics here; the peer itself runs only where
a venv with dex-retargeting is named by the environment variable ``FINGERFIT_DEX_PYTHON``
(its interpreter; docs/retargeting.md, section *dex-retargeting*), and is skipped otherwise.
"""

from __future__ import annotations

import importlib.util
import os
import warnings
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from fingerfit.retarget import resolve, robot_points, setup
from fingerfit.retarget.robots import load_robot

from .conftest import subject

BENCH = Path(__file__).resolve().parents[1] / "bench"
#: The interpreter of a venv with dex-retargeting (docs/retargeting.md), or None.
DEX_PYTHON = os.environ.get("FINGERFIT_DEX_PYTHON") or None


def _no_dex_reason() -> str | None:
    """Why the peer cannot run here, or None when it can."""
    if DEX_PYTHON is None:
        return (
            "FINGERFIT_DEX_PYTHON is not set (the python of a venv with dex-retargeting; "
            "docs/retargeting.md, section dex-retargeting)"
        )
    if not Path(DEX_PYTHON).is_file():
        return f"FINGERFIT_DEX_PYTHON={DEX_PYTHON} is not a file"
    return None


def _module(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"bench_{name}", BENCH / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def allegro():
    """Setup of a fitted two-finger model (index, middle) on the Allegro, and the bench.

    Two fingers: dex-retargeting's position config refuses a single target link."""
    from fingerfit.estimate import fit_session

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(subject("exact", 11, ("index", "middle")).session)
    robot, rmap = resolve("allegro", None, model.hand)
    return setup(model, robot, rmap), _module("retarget")


def _feasible(s, n: int, seed: int = 0) -> np.ndarray:
    """``n`` feasible configurations between the neutral posture and a random one."""
    r = s.robot
    rng = np.random.default_rng(seed)
    goal = s.limits.project(rng.uniform(r.lower, r.upper))
    w = np.linspace(0.0, 1.0, n)[:, None]
    q = s.hold + (goal - s.hold) * w
    held = np.setdiff1d(np.arange(r.nq), s.free)
    q[:, held] = s.hold[held]
    return s.limits.project(q)


def test_to_world_inverts_the_palm_frame(allegro):
    s, bench = allegro
    frames = [s.rmap.digits[d].tip for d in s.digits] + [s.rmap.palm]
    q = _feasible(s, 5)
    world = s.robot.positions(q, frames)
    assert np.abs(bench.to_world(s, robot_points(s, q, frames)) - world).max() < 1e-12
    # a rotation, not the identity: the Allegro palm frame's x is the URDF's z
    assert np.abs(s.robot_palm.rotation - np.eye(3)).max() > 0.5


def test_rigid_offset_is_the_maps_pad_offset_and_refuses_a_moving_pair(allegro):
    s, bench = allegro
    dm = s.rmap.digits["index"]
    assert dm.pad != dm.tip  # the pad point fingerfit adds to the URDF
    assert np.allclose(bench.rigid_offset(s, dm.pad, dm.tip), [0.012, 0.0, 0.0], atol=1e-12)
    assert "link_3.0_tip" in bench.urdf_links(s.robot.path)
    assert dm.pad not in bench.urdf_links(s.robot.path)
    with pytest.raises(SystemExit, match="does not move rigidly"):
        bench.rigid_offset(s, dm.tip, s.rmap.palm)  # the finger moves against the palm


def test_peer_urdf_copy_places_the_pad_links_where_fingerfit_does(allegro, tmp_path):
    s, _ = allegro
    peer = _module("dex_peer")  # importable without torch: it imports dex-retargeting late
    dm = s.rmap.digits["index"]
    copy = peer.derived_urdf(
        s.robot.path, ["pad_a", "pad_b"], [dm.tip, "palm_link"],
        np.array([[0.012, 0.0, 0.0], [0.01, -0.02, 0.03]]), tmp_path,
    )  # fmt: skip
    assert copy.parent == tmp_path and copy.read_bytes() != s.robot.path.read_bytes()
    derived = load_robot(copy)
    assert derived.joint_names == s.robot.joint_names  # fixed links add no joint
    q = _feasible(s, 4, seed=3)
    want = s.robot.positions(q, [dm.pad, s.rmap.palm])
    got = derived.positions(q, ["pad_a", "palm_link"])
    assert np.abs(got - want).max() < 1e-12
    o, rot = s.robot.pose(q[0], "palm_link")
    got_b = derived.positions(q[:1], ["pad_b"])[0, 0]
    assert np.allclose(got_b, o + rot @ [0.01, -0.02, 0.03], atol=1e-12)
    with pytest.raises(SystemExit, match="no link 'nope'"):
        peer.derived_urdf(s.robot.path, ["x"], ["nope"], np.zeros((1, 3)), tmp_path)


@pytest.mark.skipif(_no_dex_reason() is not None, reason=_no_dex_reason() or "")
def test_dex_retargeting_follows_the_robots_own_fingertips(allegro):
    """Targets = the robot's own tip along a known trajectory: dex-retargeting's angles,
    mapped back by joint name, put the tip there (its tolerance: a few mm as shipped,
    sub-millimetre at ftol 1e-8) and hold the joints it was told to hold."""
    s, bench = allegro
    tips = [s.rmap.digits[d].tip for d in s.digits]
    q_true = _feasible(s, 240, seed=1)
    target = robot_points(s, q_true, tips)
    q, sec, version = bench.run_dex(DEX_PYTHON, s, "position", 1.0, tips, tips, target, ftol=1e-8)
    assert version and q.shape == q_true.shape and sec.shape == (240,)
    err = np.linalg.norm(robot_points(s, q, tips) - target, axis=2)[20:]  # after its cold start
    assert np.median(err) < 1.0
    held = np.setdiff1d(np.arange(s.robot.nq), s.free)
    assert np.abs(q[:, held] - s.hold[held]).max() < 1e-6
    # its bounds are the limits widened by 1e-3 rad (the bench reports those violations)
    assert (q >= s.robot.lower - 1.1e-3).all() and (q <= s.robot.upper + 1.1e-3).all()
