"""Robot hand kinematics behind one interface, from MJCF (MuJoCo) or URDF (Pinocchio).

:class:`Robot` gives, for the robot's 1-DOF joints (hinge/revolute, slide/prismatic):
names, limits, frame positions for a batch of configurations, and positions with
translational Jacobians for one configuration (the solver's inner loop). Frames are
MJCF sites or bodies, or URDF links/joints (any Pinocchio frame). Positions are metres
in the robot's world frame; joint values radians (metres for a slide joint).

MuJoCo and Pinocchio are optional (``pip install fingerfit[retarget]``); they are
imported when a robot is loaded.
"""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FingerfitError
from ..transforms import FloatArray

EXTRA = "retarget"


def require(module: str) -> Any:
    """Import an optional dependency of the ``retarget`` extra (:func:`fingerfit.extras.require`)."""
    from ..extras import require as require_extra

    return require_extra(module, EXTRA, "robot retargeting")


@dataclass
class Robot:
    """A robot hand's kinematics (one backend: MuJoCo or Pinocchio).

    Attributes
    ----------
    path : Path
        The robot file.
    joint_names : tuple of str
        Every 1-DOF joint, in configuration order (``nq`` names).
    lower, upper : ndarray, shape (nq,)
        Joint limits (rad or m); ``-inf``/``inf`` for an unlimited joint.
    """

    path: Path
    joint_names: tuple[str, ...]
    lower: FloatArray
    upper: FloatArray
    _backend: Any = field(repr=False)

    @property
    def nq(self) -> int:
        """Number of joints."""
        return len(self.joint_names)

    def has_frame(self, name: str) -> bool:
        """Whether ``name`` is a frame (site, body, link) of the robot."""
        return self._backend.has_frame(name)

    def ancestors(self, frame: str) -> list[int]:
        """Indices of the joints that move ``frame``, root first."""
        return self._backend.ancestors(frame)

    def positions(self, q: FloatArray, frames: list[str]) -> FloatArray:
        """Frame origins for a batch of configurations.

        Parameters
        ----------
        q : ndarray, shape (n, nq)
            Joint values (rad / m).
        frames : list of str
            ``k`` frame names.

        Returns
        -------
        ndarray, shape (n, k, 3)
            Positions (m, robot world frame).
        """
        q = np.atleast_2d(np.asarray(q, dtype=float))
        ids = [self._backend.frame_id(f) for f in frames]
        out = np.empty((q.shape[0], len(frames), 3))
        for i, qi in enumerate(q):
            self._backend.set(qi)
            out[i] = self._backend.positions(ids)
        return out

    def pose(self, q: FloatArray, frame: str) -> tuple[FloatArray, FloatArray]:
        """Origin ``(3,)`` m and rotation ``(3, 3)`` (frame -> world) of one frame at ``q (nq,)``."""
        self._backend.set(np.asarray(q, dtype=float))
        return self._backend.pose(self._backend.frame_id(frame))

    def frame_ids(self, frames: list[str]) -> list[Any]:
        """Backend handles of ``frames`` for :meth:`jacobians`."""
        return [self._backend.frame_id(f) for f in frames]

    def jacobians(self, q: FloatArray, ids: list[Any]) -> tuple[FloatArray, FloatArray]:
        """Positions and translational Jacobians of frames at one configuration.

        Parameters
        ----------
        q : ndarray, shape (nq,)
        ids : list
            From :meth:`frame_ids` (``k`` frames).

        Returns
        -------
        pos : ndarray, shape (k, 3)
            m, world frame.
        jac : ndarray, shape (k, 3, nq)
            d pos / d q (m/rad), world frame.
        """
        self._backend.set(np.asarray(q, dtype=float), jacobians=True)
        return self._backend.positions(ids), self._backend.jacobians(ids)

    def anchors(self, q: FloatArray) -> FloatArray:
        """Joint anchor points ``(nq, 3)`` (m, world) at one configuration ``(nq,)``."""
        self._backend.set(np.asarray(q, dtype=float))
        return self._backend.anchors()

    @property
    def slide(self) -> np.ndarray:
        """``(nq,)`` bool: the joint is a slide (MJCF) / prismatic (URDF) joint, in metres;
        the others are hinges / revolute joints, in radians."""
        return self._backend.slide

    @property
    def mujoco_model(self) -> Any:
        """The ``mujoco.MjModel`` of an MJCF robot (for rendering); ``None`` for a URDF one."""
        return self._backend.m if isinstance(self._backend, _Mujoco) else None

    def add_point(self, name: str, frame: str, offset: FloatArray) -> None:
        """Add a frame fixed to ``frame`` at ``offset`` (m, in ``frame``'s axes).

        For points a robot file does not name, e.g. the pad on a spherical fingertip whose
        only frame is the sphere's centre (a map's ``pad_offset``). The new frame moves with
        ``frame``'s body and has its orientation; MJCF gets a site, URDF an operational frame.
        """
        if self.has_frame(name):
            raise ValueError(f"frame '{name}' exists")
        self._backend.add_point(name, frame, np.asarray(offset, dtype=float))


def _headless_gl() -> None:
    """Let MuJoCo render offscreen through EGL on a Linux machine without a display.

    MuJoCo picks its OpenGL platform once, when first imported (``MUJOCO_GL``); its default
    needs a display. A ``MUJOCO_GL`` the user set is kept.
    """
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        os.environ.setdefault("MUJOCO_GL", "egl")


class _Mujoco:
    def __init__(self, path: Path) -> None:
        _headless_gl()
        mujoco = require("mujoco")
        self.mj = mujoco
        try:
            self.spec = mujoco.MjSpec.from_file(str(path))
            self.m = self.spec.compile()
        except Exception as exc:  # mujoco raises ValueError with a multi-line text
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise FingerfitError(f"not a loadable MJCF robot: {first}", path=path) from None
        m = self.m
        self.d = mujoco.MjData(m)
        ok = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
        for j in range(m.njnt):
            if int(m.jnt_type[j]) not in ok:
                raise FingerfitError(
                    f"joint '{m.joint(j).name}' is not a hinge or slide joint (free and ball "
                    "joints are not supported)",
                    path=path,
                )
        if m.nq != m.njnt or m.nv != m.njnt:
            raise FingerfitError("robot has joints with more than one degree of freedom", path=path)
        self.names = tuple(m.joint(j).name for j in range(m.njnt))
        self.slide = m.jnt_type == int(mujoco.mjtJoint.mjJNT_SLIDE)
        limited = m.jnt_limited.astype(bool)
        self.lower = np.where(limited, m.jnt_range[:, 0], -np.inf)
        self.upper = np.where(limited, m.jnt_range[:, 1], np.inf)
        self.jacp = np.zeros((3, m.nv))

    def has_frame(self, name: str) -> bool:
        mj = self.mj
        return any(
            mj.mj_name2id(self.m, t, name) >= 0
            for t in (mj.mjtObj.mjOBJ_SITE, mj.mjtObj.mjOBJ_BODY)
        )

    def frame_id(self, name: str) -> tuple[str, int]:
        mj = self.mj
        i = mj.mj_name2id(self.m, mj.mjtObj.mjOBJ_SITE, name)
        if i >= 0:
            return ("site", i)
        i = mj.mj_name2id(self.m, mj.mjtObj.mjOBJ_BODY, name)
        if i >= 0:
            return ("body", i)
        raise KeyError(name)

    def _body(self, fid: tuple[str, int]) -> int:
        return int(self.m.site_bodyid[fid[1]]) if fid[0] == "site" else fid[1]

    def ancestors(self, frame: str) -> list[int]:
        m, b = self.m, self._body(self.frame_id(frame))
        out: list[int] = []
        while b > 0:
            start, num = m.body_jntadr[b], m.body_jntnum[b]
            out = list(range(start, start + num)) + out
            b = int(m.body_parentid[b])
        return out

    def set(self, q: FloatArray, jacobians: bool = False) -> None:
        self.d.qpos[:] = q
        self.mj.mj_kinematics(self.m, self.d)
        if jacobians:
            self.mj.mj_comPos(self.m, self.d)

    def positions(self, ids: list[tuple[str, int]]) -> FloatArray:
        return np.array([self.d.site_xpos[i] if k == "site" else self.d.xpos[i] for k, i in ids])

    def pose(self, fid: tuple[str, int]) -> tuple[FloatArray, FloatArray]:
        k, i = fid
        if k == "site":
            return self.d.site_xpos[i].copy(), self.d.site_xmat[i].reshape(3, 3).copy()
        return self.d.xpos[i].copy(), self.d.xmat[i].reshape(3, 3).copy()

    def jacobians(self, ids: list[tuple[str, int]]) -> FloatArray:
        out = np.empty((len(ids), 3, self.m.nv))
        for n, (k, i) in enumerate(ids):
            if k == "site":
                self.mj.mj_jacSite(self.m, self.d, self.jacp, None, i)
            else:
                self.mj.mj_jacBody(self.m, self.d, self.jacp, None, i)
            out[n] = self.jacp
        return out

    def anchors(self) -> FloatArray:
        return self.d.xanchor.copy()

    def add_point(self, name: str, frame: str, offset: FloatArray) -> None:
        if (
            self.frame_id(frame)[0] == "site"
        ):  # a site's offset is in the site's axes: move it into its body's
            site = self.spec.site(frame)
            body, rot = site.parent, np.empty(9)
            self.mj.mju_quat2Mat(rot, np.asarray(site.quat, dtype=float))
            pos = np.asarray(site.pos, dtype=float) + rot.reshape(3, 3) @ offset
            body.add_site(name=name, pos=pos, quat=np.asarray(site.quat, dtype=float))
        else:
            self.spec.body(frame).add_site(name=name, pos=offset)
        self.m = self.spec.compile()
        self.d = self.mj.MjData(self.m)


class _Pinocchio:
    def __init__(self, path: Path) -> None:
        pin = require("pinocchio")
        self.pin = pin
        try:
            self.m = pin.buildModelFromUrdf(str(path))
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise FingerfitError(f"not a loadable URDF robot: {first}", path=path) from None
        m = self.m
        for j in range(1, m.njoints):
            if m.joints[j].nq != 1 or m.joints[j].nv != 1:
                raise FingerfitError(
                    f"joint '{m.names[j]}' ({m.joints[j].shortname()}) is not a 1-DOF "
                    "revolute or prismatic joint",
                    path=path,
                )
        order = sorted(range(1, m.njoints), key=lambda j: m.joints[j].idx_q)
        self.names = tuple(m.names[j] for j in order)
        # JointModelPX|PY|PZ|PrismaticUnaligned move in metres (multi-DOF joints are refused).
        self.slide = np.array([m.joints[j].shortname().startswith("JointModelP") for j in order])
        self.idx = {m.names[j]: m.joints[j].idx_q for j in order}
        lo, hi = np.array(m.lowerPositionLimit, float), np.array(m.upperPositionLimit, float)
        # URDF continuous joints and missing limits come out as +-max float.
        self.lower = np.where(lo < -1e10, -np.inf, lo)
        self.upper = np.where(hi > 1e10, np.inf, hi)
        self.d = m.createData()
        self.frame = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

    def has_frame(self, name: str) -> bool:
        return bool(self.m.existFrame(name))

    def frame_id(self, name: str) -> int:
        if not self.m.existFrame(name):
            raise KeyError(name)
        return int(self.m.getFrameId(name))

    def ancestors(self, frame: str) -> list[int]:
        m = self.m
        j = m.frames[self.frame_id(frame)].parentJoint
        out: list[int] = []
        while j > 0:
            out.insert(0, m.joints[j].idx_q)
            j = m.parents[j]
        return out

    def set(self, q: FloatArray, jacobians: bool = False) -> None:
        if jacobians:
            self.pin.computeJointJacobians(self.m, self.d, q)
            self.pin.updateFramePlacements(self.m, self.d)
        else:
            self.pin.framesForwardKinematics(self.m, self.d, q)

    def positions(self, ids: list[int]) -> FloatArray:
        return np.array([self.d.oMf[i].translation for i in ids])

    def pose(self, fid: int) -> tuple[FloatArray, FloatArray]:
        p = self.d.oMf[fid]
        return np.array(p.translation), np.array(p.rotation)

    def jacobians(self, ids: list[int]) -> FloatArray:
        return np.array([self.pin.getFrameJacobian(self.m, self.d, i, self.frame)[:3] for i in ids])

    def anchors(self) -> FloatArray:
        m = self.m
        out = np.empty((m.nq, 3))
        for j in range(1, m.njoints):
            out[m.joints[j].idx_q] = self.d.oMi[j].translation
        return out

    def add_point(self, name: str, frame: str, offset: FloatArray) -> None:
        pin, m = self.pin, self.m
        fid = self.frame_id(frame)
        parent = m.frames[fid]
        placement = parent.placement * pin.SE3(np.eye(3), offset)
        m.addFrame(pin.Frame(name, parent.parentJoint, fid, placement, pin.FrameType.OP_FRAME))
        self.d = m.createData()


def load_robot(path: str | Path) -> Robot:
    """Load a robot hand from an MJCF (``.xml``) or URDF (``.urdf``) file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Robot

    Raises
    ------
    FingerfitError
        Missing or unreadable file, a multi-DOF joint, a missing optional package.
    """
    path = Path(path)
    if not path.is_file():
        raise FingerfitError("robot file not found", path=path)
    suffix = path.suffix.lower()
    if suffix == ".xml":
        backend: Any = _Mujoco(path)
    elif suffix == ".urdf":
        backend = _Pinocchio(path)
    else:
        raise FingerfitError("robot file must be MJCF (.xml) or URDF (.urdf)", path=path)
    if not backend.names:
        raise FingerfitError("robot has no joints", path=path)
    return Robot(path, backend.names, backend.lower, backend.upper, backend)
