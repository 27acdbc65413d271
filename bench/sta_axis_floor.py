"""The soft-tissue artefact's axis floor: the axis the sensors' motion shows, against the truth.

Run with ``.venv/bin/python bench/sta_axis_floor.py --subjects 8``.

A sensor on the skin slides and turns on its bone as the adjacent joints flex (the
simulator's soft-tissue artefact, ``SimConfig.sta``, in proportion to the adjacent joints'
angles: ``fingerfit.simulate.sensors``). Then the child sensor turns relative to the parent
sensor about a line that is *not* the joint's anatomical axis, whatever the estimator. This
bench measures that line, with no estimator in it, on noise-free sensors (``noise=0``, no
field distortion), and sets the default fit beside it.

For each subject (index finger, ``SimConfig(noise=0, distortion=False, sta=S)``, seeds
``1000 + i``) and each joint, over every frame of the grasp recordings:

* ``Q(t) = R_rel(t) R_rel,ref^T``, the child sensor's orientation relative to the parent
  sensor, ``R_rel = R_parent^T R_child``, taken from its reference-posture value (parent
  sensor frame);
* the **sensors' axis**: the first right singular vector of the stacked rotation vectors
  of ``Q(t)`` (the direction they share; for a rotation about one fixed line it is that
  line exactly), and the **spread**: the RMS angle of each frame's rotation vector (frames
  turned more than 10 deg) from it, how far the motion is from one fixed line;
* **sensors vs truth** (deg): the angle between the sensors' axis and the true flexion axis
  (``relative_truth_in_parent``);
* the **sensors' line**: the points the relative motion leaves in place, ``(Q - I) x = -d``
  by least squares over the frames turned more than 10 deg (``d`` the child sensor's
  displacement, parent frame), along the sensors' axis; its distance to the true axis at
  the point nearest the true centre (mm);
* the default fit (``fit_session``) on the same session: **fit vs truth** (the accuracy
  bench's axis error), **fit vs sensors**, and the fitted centre's distance to the true
  axis (the accuracy bench's centre error).

At ``sta=0`` the sensors' axis is the true axis (no ab/adduction) to numerical precision.
With ab/adduction at the MP the rotation vectors mix both axes, so the MP row is meaningful
with ``--no-abduction`` (the default runs both).
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import warnings

import numpy as np
from scipy.spatial.transform import Rotation

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.session import JOINTS, joint_sensors
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.simulate.study import relative_truth_in_parent
from fingerfit.transforms import angle_between_axes, distance_point_to_line

FINGER = "index"


def sensors_line(session, joint: str) -> tuple[np.ndarray, np.ndarray, float]:
    """The line the child sensor turns about relative to the parent (point mm, direction;
    parent sensor frame) and the spread of the frames' rotation axes about it (deg)."""
    parent, child = joint_sensors(FINGER)[joint]

    def relative(rec) -> tuple[np.ndarray, np.ndarray]:
        pp, pc = rec.pose(parent), rec.pose(child)
        rot = np.einsum("nji,njk->nik", pp.rotation, pc.rotation)
        pos = np.einsum("nji,nj->ni", pp.rotation, pc.position - pp.position)
        return rot, pos

    ref_rot, ref_pos = relative(session.reference)
    ref = Rotation.from_matrix(ref_rot).mean()
    ref_t = ref_pos.mean(axis=0)
    rot, pos = (np.concatenate(x) for x in zip(*(relative(r) for r in session.grasp), strict=True))
    q = Rotation.from_matrix(rot) * ref.inv()
    rv = q.as_rotvec()
    _, _, vt = np.linalg.svd(rv, full_matrices=False)
    axis = vt[0]
    big = np.linalg.norm(rv, axis=1) > np.radians(10.0)
    spread = np.degrees(angle_between_axes(rv[big], axis[None]))
    # The relative motion from the reference is x -> Q x + d with d = p - Q p_ref; a point
    # of the turning line stays put: (Q - I) x = -d, least squares over the moving frames.
    qm = q.as_matrix()[big]
    d = pos[big] - np.einsum("nij,j->ni", qm, ref_t)
    point = np.linalg.lstsq((qm - np.eye(3)).reshape(-1, 3), -d.reshape(-1), rcond=None)[0]
    return point, axis, float(np.sqrt(np.mean(spread**2)))


def line_to_truth_mm(point, axis, centre, true_axis) -> float:
    """Distance (mm) from the true axis of the line's point nearest the true centre."""
    u = axis / np.linalg.norm(axis)
    nearest = point + np.dot(centre - point, u) * u
    return float(distance_point_to_line(nearest, centre, true_axis))


def run(subjects: int, sta: float, abduction: bool) -> dict[str, np.ndarray]:
    out: dict[str, list] = {j: [] for j in JOINTS}
    for i in range(subjects):
        sim = simulate_subject(
            SimConfig(noise=0.0, distortion=False, sta=sta, abduction=abduction), 1000 + i
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = fit_session(sim.session, FitOptions(force=True))
        for j in JOINTS:
            point, axis, spread = sensors_line(sim.session, j)
            true_centre, true_axis = relative_truth_in_parent(sim, FINGER, j)
            fit_centre, fit_axis = model.in_parent(FINGER, j)
            out[j].append(
                [
                    np.degrees(angle_between_axes(axis, true_axis)),
                    spread,
                    np.degrees(angle_between_axes(fit_axis, true_axis)),
                    np.degrees(angle_between_axes(fit_axis, axis)),
                    line_to_truth_mm(point, axis, true_centre, true_axis),
                    float(distance_point_to_line(fit_centre, true_centre, true_axis)),
                ]
            )
    return {j: np.array(v) for j, v in out.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=8)
    ap.add_argument("--sta", default="0,1,2", help="artefact scales, comma separated")
    args = ap.parse_args()
    print(
        "| MP ab/adduction | sta | joint | sensors vs truth deg mean (max) | spread deg | "
        "fit vs truth deg mean (max) | fit vs sensors deg mean (max) | "
        "sensors' line to true axis mm mean (max) | fit centre to true axis mm mean (max) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for abduction in (False, True):
        for sta in (float(s) for s in args.sta.split(",")):
            res = run(args.subjects, sta, abduction)
            for j in JOINTS:
                r = res[j]
                print(
                    f"| {'on' if abduction else 'off'} | {sta:g} | {j} | "
                    f"{r[:, 0].mean():.2f} ({r[:, 0].max():.2f}) | {r[:, 1].mean():.2f} | "
                    f"{r[:, 2].mean():.2f} ({r[:, 2].max():.2f}) | "
                    f"{r[:, 3].mean():.2f} ({r[:, 3].max():.2f}) | "
                    f"{r[:, 4].mean():.2f} ({r[:, 4].max():.2f}) | "
                    f"{r[:, 5].mean():.2f} ({r[:, 5].max():.2f}) |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
