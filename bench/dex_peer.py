"""dex-retargeting as a peer of ``bench/retarget.py`` (run in its own venv, not fingerfit's).

    $FINGERFIT_DEX_PYTHON bench/dex_peer.py IN.npz OUT.npz

``FINGERFIT_DEX_PYTHON``: the python of a venv with dex-retargeting and torch
(docs/retargeting.md, section *dex-retargeting*).

Builds dex-retargeting's own optimisers from its ``RetargetingConfig`` (the package's
documented entry point) on a URDF and runs them frame by frame with the package's own
warm start (``SeqRetargeting``: each frame starts from the previous frame's solution,
the first from the middle of the joint limits). This script does not import fingerfit,
and fingerfit does not import dex-retargeting: the two meet only through the two files.

Input ``IN.npz`` (all positions metres, in the URDF's root frame; joints radians):

``urdf`` : str
    The robot file (the same one fingerfit loads).
``mode`` : str
    ``position`` (``PositionOptimizer``: the named links onto the given points) or
    ``dexpilot`` (``DexPilotOptimizer``: wrist-to-finger and finger-to-finger vectors,
    thumb-to-finger vectors projected to 0.1 mm while they are shorter than 30 mm).
``links`` : (k,) str
    The robot links to place (``dexpilot``: the thumb first, as the package expects).
``points`` : (n, k, 3) float
    Per frame, where each link should be.
``joints`` : (m,) str
    The joints dex-retargeting solves for (its ``target_joint_names``).
``fixed_names``, ``fixed_values`` : (nq - m,) str, float
    Every other joint, held at this value (its ``fixed_qpos``).
``wrist``, ``wrist_point`` : str, (3,) float -- ``dexpilot`` only
    The robot link of the person's wrist keypoint and where that keypoint is.
``pair_vectors`` : (n, k, k, 3) float -- ``dexpilot``, optional
    ``[:, i, j]``: the desired ``link_i - link_j`` (m, root frame axes), the input of the
    finger-to-finger vectors (whose length decides the pinch projection); default: the
    differences of ``points``.
``extra_names``, ``extra_parents``, ``extra_offsets`` : (e,) str, (e,) str, (e, 3) float
    Optional points the URDF does not name (a pad on a spherical fingertip): each becomes
    a fixed child link of its parent at that offset (parent's axes, m) in a derived copy
    of the URDF written to a temporary folder; the kinematics are otherwise unchanged.
``low_pass_alpha`` : float
    The package's output low-pass filter (1 = off).
``ftol_abs`` : float, optional
    Replaces the optimiser's stopping tolerance on the loss (nlopt ``set_ftol_abs``;
    the package sets 1e-5 for position, 1e-6 for DexPilot).

Output ``OUT.npz``:

``joint_names`` : (nq,) str
    The URDF's 1-DOF joints in the order of ``q`` (Pinocchio's, as the package uses).
``q`` : (n, nq) float
    Radians, every joint (held ones included).
``seconds`` : (n,) float
    Wall time of each frame's ``SeqRetargeting.retarget`` call.
``links_reached`` : (n, k, 3) float
    The package's own forward kinematics of ``links`` at ``q`` (m, root frame): lets
    the caller check that its kinematics and joint order agree.
``version`` : str
    dex-retargeting's version.
"""

from __future__ import annotations

import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from importlib.metadata import version
from pathlib import Path

import numpy as np


def derived_urdf(
    urdf: Path, names: list[str], parents: list[str], offsets: np.ndarray, folder: Path
) -> Path:
    """A copy of ``urdf`` in ``folder`` with a fixed child link per extra point.

    Parameters
    ----------
    names, parents : list of str
        ``e`` new link names and the existing link each is fixed to.
    offsets : ndarray, shape (e, 3)
        Each new link's origin in its parent's frame (m).

    Returns
    -------
    Path
        The copy (same file name; mesh references unchanged).
    """
    tree = ET.parse(urdf)
    root = tree.getroot()
    links = {e.get("name") for e in root.findall("link")}
    for name, parent, off in zip(names, parents, offsets, strict=True):
        if parent not in links:
            raise SystemExit(f"dex_peer: {urdf}: no link '{parent}' for extra point '{name}'")
        ET.SubElement(root, "link", name=name)
        joint = ET.SubElement(root, "joint", name=f"{name}_joint", type="fixed")
        ET.SubElement(joint, "parent", link=parent)
        ET.SubElement(joint, "child", link=name)
        ET.SubElement(joint, "origin", xyz=" ".join(f"{v:.9g}" for v in off), rpy="0 0 0")
    out = folder / urdf.name
    tree.write(out)
    return out


def main() -> None:
    src, dst = Path(sys.argv[1]), Path(sys.argv[2])
    with tempfile.TemporaryDirectory(prefix="dex_peer-") as tmp:
        run(src, dst, Path(tmp))


def run(src: Path, dst: Path, tmp: Path) -> None:
    """Read the inputs ``src``, retarget every frame, write ``dst`` (module docstring)."""
    import torch
    from dex_retargeting.optimizer import DexPilotOptimizer
    from dex_retargeting.retargeting_config import RetargetingConfig

    z = np.load(src, allow_pickle=False)
    urdf = Path(str(z["urdf"]))
    mode = str(z["mode"])
    links = [str(x) for x in z["links"]]
    points = np.asarray(z["points"], dtype=float)
    joints = [str(x) for x in z["joints"]]
    fixed_names = [str(x) for x in z["fixed_names"]]
    fixed_values = np.asarray(z["fixed_values"], dtype=float)
    if "extra_names" in z and len(z["extra_names"]):
        urdf = derived_urdf(
            urdf,
            [str(x) for x in z["extra_names"]],
            [str(x) for x in z["extra_parents"]],
            np.asarray(z["extra_offsets"], dtype=float),
            tmp,
        )
    torch.set_num_threads(1)  # tiny tensors; fingerfit's solver is single-threaded too
    common = {
        "urdf_path": str(urdf),
        "target_joint_names": joints,
        "low_pass_alpha": float(z["low_pass_alpha"]),
    }
    if mode == "position":
        if len(links) < 2:  # it squeezes the index array: one target fails its shape check
            raise SystemExit("dex_peer: dex-retargeting's position config needs 2+ links")
        cfg = RetargetingConfig(
            type="position",
            target_link_names=links,
            target_link_human_indices=np.arange(len(links)),
            **common,
        )
        refs = points
    elif mode == "dexpilot":
        cfg = RetargetingConfig(
            type="dexpilot",
            wrist_link_name=str(z["wrist"]),
            finger_tip_link_names=links,
            **common,
        )
        # The package's own vector layout: finger-to-finger pairs, then wrist-to-finger;
        # keypoint 0 is the wrist, 1..k the fingers in the order of ``links``; each
        # vector is keypoint[task] - keypoint[origin].
        origin, task = DexPilotOptimizer.generate_link_indices(len(links))
        kp = np.concatenate(
            [np.broadcast_to(z["wrist_point"], (len(points), 1, 3)), points], axis=1
        )
        refs = kp[:, task] - kp[:, origin]
        if "pair_vectors" in z:
            pv = np.asarray(z["pair_vectors"], dtype=float)
            for v, (o, t) in enumerate(zip(origin, task, strict=True)):
                if o > 0:
                    refs[:, v] = pv[:, t - 1, o - 1]
    else:
        raise SystemExit(f"dex_peer: unknown mode '{mode}'")
    seq = cfg.build()
    if "ftol_abs" in z:
        seq.optimizer.opt.set_ftol_abs(float(z["ftol_abs"]))
    names = list(seq.joint_names)
    fixed = {n: v for n, v in zip(fixed_names, fixed_values, strict=True)}
    order = [n for n in names if n not in joints]
    if set(order) != set(fixed) or seq.optimizer.fixed_joint_names != order:
        raise SystemExit(
            f"dex_peer: fixed joints {sorted(fixed)} are not the robot's other joints {order}"
        )
    fixed_q = np.array([fixed[n] for n in order])
    n = len(refs)
    q = np.empty((n, len(names)))
    seconds = np.empty(n)
    for i in range(n):
        t0 = time.perf_counter()
        q[i] = seq.retarget(refs[i], fixed_qpos=fixed_q)
        seconds[i] = time.perf_counter() - t0
    robot = seq.optimizer.robot
    ids = [robot.get_link_index(x) for x in links]
    reached = np.empty((n, len(links), 3))
    for i in range(n):
        robot.compute_forward_kinematics(q[i])
        reached[i] = [robot.get_link_pose(j)[:3, 3] for j in ids]
    np.savez(
        dst,
        joint_names=np.array(names),
        q=q,
        seconds=seconds,
        links_reached=reached,
        version=np.array(version("dex-retargeting")),
    )


if __name__ == "__main__":
    main()
