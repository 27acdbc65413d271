"""The person's hand and the robot side by side at chosen frames (matplotlib drawing).

Both are drawn in their own palm frame (x distal, z dorsal; mm): the person's digits as
base -> joint centres -> fingertip, the robot's as the anchors of its chain joints ->
tip frame, with the scaled targets of the ``tip`` method as crosses on the robot.
"""

from __future__ import annotations

import io

import numpy as np

from ..kinematics import chain_points, compute_kinematics
from ..model import HandModel
from ..session import Recording
from .maps import RobotMap
from .palm import in_palm
from .robots import Robot


def figure_png(
    model: HandModel,
    recording: Recording,
    result,
    robot: Robot,
    rmap: RobotMap,
    frames: list[int],
    variant: str = "user_axis",
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
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from . import setup

    s = setup(model, robot, rmap)
    kin = compute_kinematics(model, recording, variants=(variant,), fingers=s.digits)
    fig, axes = plt.subplots(len(frames), 2, figsize=(9, 3.6 * len(frames)), squeeze=False)
    colours = dict(zip(s.digits, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    for row, t in enumerate(frames):
        ax_p, ax_r = axes[row]
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
    fig.suptitle(f"{result.method} method: palm-frame side view; x = scaled target", fontsize=10)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


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
