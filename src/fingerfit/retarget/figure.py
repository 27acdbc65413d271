"""The person's hand and the robot side by side at chosen frames.

Both are drawn in their own palm frame (x distal, z dorsal; mm): the person's digits as
base -> joint centres -> fingertip, the robot's as the anchors of its chain joints ->
tip frame, with the scaled targets of the ``tip`` method as crosses on the robot. An MJCF
robot is also rendered by MuJoCo offscreen (its own geometry, the same side view), when
an OpenGL platform is available (EGL on a headless Linux machine); otherwise, and for a
URDF robot, the drawing stands alone and :func:`render_robot` says why.
"""

from __future__ import annotations

import io

import numpy as np

from ..kinematics import Kinematics, chain_points, compute_kinematics
from ..model import HandModel
from ..session import Recording
from ..transforms import FloatArray
from .maps import RobotMap
from .palm import Frame, in_palm
from .robots import Robot


def figure_png(
    model: HandModel,
    recording: Recording,
    result,
    robot: Robot,
    rmap: RobotMap,
    frames: list[int],
    variant: str = "user_axis",
    kin: Kinematics | None = None,
) -> bytes:
    """PNG bytes: one row per frame, the person (left) and the robot (right), side view.

    Parameters
    ----------
    model, recording : the retargeted inputs
    result : Retargeting
    robot, rmap : Robot, RobotMap
    frames : list of int
        0-based frame numbers.
    variant : str
        Model variant that drove the robot.
    kin : Kinematics, optional
        The kinematics that drove it (a model fitted from markers: its markers' angles,
        :func:`fingerfit.kinematics.markers.with_hand`); computed from ``recording``
        when not given.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from . import setup

    s = setup(model, robot, rmap)
    if kin is None:
        kin = compute_kinematics(model, recording, variants=(variant,), fingers=s.digits)
    renders = render_robot(robot, result.q[frames], s.robot_palm)
    cols = 2 if isinstance(renders, str) else 3
    fig, axes = plt.subplots(
        len(frames), cols, figsize=(4.5 * cols, 3.6 * len(frames)), squeeze=False
    )
    colours = dict(zip(s.digits, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    for row, t in enumerate(frames):
        ax_p, ax_r = axes[row][:2]
        if not isinstance(renders, str):
            axes[row][2].imshow(renders[row])
            axes[row][2].set_axis_off()
            axes[row][2].set_title(f"{rmap.name} (MuJoCo render), frame {t}", fontsize=9)
        for d in s.digits:
            fm = model.fingers[d]
            angles = {j: a[t : t + 1] for j, a in kin.motions[variant][d].angles.items()}
            names = list(fm.joints)
            try:  # base, joint centres, tip: all at the reference hand pose
                pts = [fm.joints[names[0]].center[None]]
                pts += [
                    chain_points(fm, variant, angles, fm.joints[names[k]].center, k)
                    for k in range(1, len(names))
                ]
                pts.append(chain_points(fm, variant, angles, fm.tip, len(names)))
                pp = (np.vstack(pts) - s.palm.origin) @ s.palm.rotation
            except (KeyError, TypeError, IndexError):  # no chain helper for this digit: base, tip
                tip = kin.motions[variant][d].tip[t : t + 1, None]
                one = in_palm(model, s.palm, _OneFrame(recording, t), tip)[0]
                pp = np.vstack([s.person_base[d], one[0]])
            ax_p.plot(pp[:, 0], pp[:, 2], "o-", color=colours[d], label=d)
            chain = robot.ancestors(rmap.digits[d].tip)
            base = robot.joint_names.index(rmap.digits[d].base)
            chain = chain[chain.index(base) :]
            q = result.q[t]
            anchors = robot.anchors(q)[chain]
            tip = robot.positions(q[None], [rmap.digits[d].tip])[0]
            rp = (np.vstack([anchors, tip]) - s.robot_palm.origin) @ s.robot_palm.rotation * 1000
            ax_r.plot(rp[:, 0], rp[:, 2], "o-", color=colours[d], label=d)
            k = result.digits.index(d)
            ax_r.plot(*result.targets[t, k, [0, 2]], "x", color=colours[d], ms=9)
        for ax, who in ((ax_p, f"person ({model.subject}, {variant})"), (ax_r, rmap.name)):
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_xlabel("distal (mm)")
            ax.set_ylabel("dorsal (mm)")
            ax.set_title(f"{who}, frame {t} (t = {result.time[t]:.2f} s)", fontsize=9)
            ax.grid(alpha=0.3)
        ax_r.legend(fontsize=7, loc="lower left")
    title = f"{result.method} method: palm-frame side view; x = scaled target"
    if isinstance(renders, str):
        title += f"\n(no render: {renders})"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


def render_robot(
    robot: Robot, q: FloatArray, palm: Frame, size: tuple[int, int] = (480, 360)
) -> list[np.ndarray] | str:
    """MuJoCo offscreen images of an MJCF robot, side view of its palm frame.

    Parameters
    ----------
    robot : Robot
    q : ndarray, shape (n, nq)
        Configurations (rad).
    palm : Frame
        The robot's palm frame (robot world, m): the camera looks along its -y axis (the
        side view of the drawing: distal to the right for a right hand, dorsal up).
    size : (int, int)
        Width and height (pixels).

    Returns
    -------
    list of ndarray, shape (height, width, 3), uint8
        One RGB image per configuration; or a one-line reason when it cannot render (a URDF
        robot, no OpenGL platform).
    """
    m = robot.mujoco_model
    if m is None:
        return "MuJoCo renders MJCF robots; this one is URDF"
    import mujoco

    w, h = min(size[0], int(m.vis.global_.offwidth)), min(size[1], int(m.vis.global_.offheight))
    try:
        renderer = mujoco.Renderer(m, h, w)
    except Exception as exc:  # no OpenGL platform: MuJoCo raises several types
        text = str(exc).strip().splitlines()
        return f"MuJoCo offscreen rendering unavailable ({text[0] if text else type(exc).__name__})"
    d = mujoco.MjData(m)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    look = -palm.rotation[:, 1]  # towards -y: the x-z plane seen from +y
    cam.azimuth = float(np.degrees(np.arctan2(look[1], look[0])))
    cam.elevation = float(np.degrees(np.arcsin(np.clip(look[2], -1.0, 1.0))))
    cam.distance = 0.32
    images = []
    try:
        for qi in np.atleast_2d(q):
            d.qpos[:] = qi
            mujoco.mj_forward(m, d)
            cam.lookat[:] = palm.origin + palm.rotation[:, 0] * 0.07
            renderer.update_scene(d, cam)
            images.append(renderer.render().copy())
    finally:
        renderer.close()
    return images


class _OneFrame:
    """One frame of a recording (only the hand sensor pose, as :func:`in_palm` needs)."""

    def __init__(self, recording: Recording, t: int) -> None:
        self._r, self._t = recording, t

    def pose(self, name: str):
        p = self._r.pose(name)

        class _P:
            rotation = p.rotation[self._t : self._t + 1]
            position = p.position[self._t : self._t + 1]

        return _P()
