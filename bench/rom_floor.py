"""Where a small range of motion stops determining a joint axis: the fit's range-of-motion
floor (``FitOptions.rom_floor_deg``) against simulated grasps of shrinking range.

    python bench/rom_floor.py [--seeds 4]

Index finger, the default world, the paper's protocol with the grasp's range scaled by
``rom_scale`` (``SimConfig``), tracker noise 1x (Liberty-like) and 2x; each subject fitted
by the default method with ``force`` (nothing refused, so every joint shows what its data
determine). Per scale, noise and joint: the median cycle range of motion (deg), the pooled
``s5/s6``, the 95 % axis confidence half-angle (deg) and the true axis error (deg, parent
sensor frame), each as the range over the seeds; a joint whose grasp gives fewer than two
cycles cannot be fitted and is counted.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import warnings

import numpy as np

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.session import JOINTS
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.simulate.truth import relative_truth_in_parent
from fingerfit.transforms import angle_between_axes

SCALES = (0.05, 0.06, 0.08, 0.1, 0.2, 1.0)
NOISES = (1.0, 2.0)


def _span(values: list[float], fmt: str) -> str:
    """``min-max`` of the finite values, or ``-``."""
    v = [x for x in values if x is not None and np.isfinite(x)]
    return "-" if not v else f"{min(v):{fmt}}-{max(v):{fmt}}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=4)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    print(
        "| noise | ROM scale | joint | fitted | median ROM deg | pooled s5/s6 | "
        "axis +/- deg (95 %) | true axis error deg |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for noise in NOISES:
        for scale in SCALES:
            rows: dict[str, list] = {j: [] for j in JOINTS}
            unfit = 0
            for seed in range(args.seeds):
                config = SimConfig(rom_scale=scale, noise=noise, test=False, targets=False)
                sim = simulate_subject(config, seed)
                try:
                    model = fit_session(sim.session, FitOptions(force=True))
                except FingerfitError:
                    unfit += 1
                    continue
                for j in JOINTS:
                    q = model.fingers["index"].joints[j].quality
                    _, axis = model.in_parent("index", j)
                    _, true_axis = relative_truth_in_parent(sim, "index", j)
                    err = float(np.degrees(angle_between_axes(axis, true_axis)))
                    rows[j].append(
                        (np.median(q.rom_deg), q.pooled_conditioning, q.axis_ci_deg, err)
                    )
            for j, r in rows.items():
                cols = list(zip(*r, strict=True)) if r else [[], [], [], []]
                print(
                    f"| {noise:g}x | {scale:g} | {j} | {len(r)}/{args.seeds} | "
                    f"{_span(cols[0], '.1f')} | {_span(cols[1], '.1f')} | "
                    f"{_span(cols[2], '.1f')} | {_span(cols[3], '.1f')} |"
                )
            if unfit:
                print(
                    f"| {noise:g}x | {scale:g} | (fewer than 2 cycles) | {unfit} subjects | | | | |"
                )


if __name__ == "__main__":
    main()
