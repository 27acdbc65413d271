"""Plausibility bounds against realistic hands: the ranges the checks must let through.

Run ``.venv/bin/python bench/plausibility_ranges.py``. On the realistic simulated subjects
(``SimConfig()``, seeds 0-9, all four fingers: 40 fingers) prints the range (mm) of the
landmark distances, sensor to landmark midpoint, fitted segment and finger lengths,
landmark to joint centre and sensor to joint centre; then the recording checks of every
grasp, target and test recording against the subject's model (largest residual, range of
the scale). The numbers of ``docs/plausibility.md`` ("Measured on the realistic simulated
subjects", and the recording residuals).
"""

from __future__ import annotations

import warnings

import numpy as np

from fingerfit.estimate import fit_session
from fingerfit.estimate.fit import reference_poses
from fingerfit.estimate.plausibility import recording_checks
from fingerfit.session import SEGMENTS
from fingerfit.simulate import SimConfig, simulate_subject

ALL = ("index", "middle", "ring", "little")
SEEDS = range(10)


def main() -> None:
    """Print one range per line."""
    stats: dict[str, list[float]] = {}
    rec_res, scales = [], []
    for seed in SEEDS:
        s = simulate_subject(SimConfig(fingers=ALL), seed).session
        ref = reference_poses(s)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = fit_session(s)
        ends = ("mp", "pip", "dip", "tip")
        for f in ALL:
            lm = {k: s.landmark(f"{f}.{k}") for k in ends}
            fm = m.fingers[f]
            for i, seg in enumerate(SEGMENTS):
                stats.setdefault(f"landmarks {ends[i]}-{ends[i + 1]}", []).append(
                    float(np.linalg.norm(lm[ends[i + 1]] - lm[ends[i]]))
                )
                mid = 0.5 * (lm[ends[i]] + lm[ends[i + 1]])
                stats.setdefault("sensor to landmark midpoint", []).append(
                    float(np.linalg.norm(ref[f"{f}.{seg}"][0] - mid))
                )
                stats.setdefault(f"segment {seg}", []).append(fm.segment_lengths[seg])
            stats.setdefault("finger length", []).append(sum(fm.segment_lengths.values()))
            for j, jm in fm.joints.items():
                stats.setdefault("landmark to centre", []).append(
                    float(np.linalg.norm(lm[j] - jm.center))
                )
                for sensor in (jm.parent, jm.child):
                    stats.setdefault("sensor to centre", []).append(
                        float(np.linalg.norm(ref[sensor][0] - jm.center))
                    )
        for rec in [*s.grasp, *s.targets, *s.test]:
            for c in recording_checks(m, rec):
                rec_res.append(c.residual_mm["as read"])
                scales.append(c.scale)
    for k, v in stats.items():
        print(f"{k}: {min(v):.1f}-{max(v):.1f} mm")
    print(
        f"recordings vs model: residual <= {max(rec_res):.2f} mm, "
        f"scale {min(scales):.3f}-{max(scales):.3f}"
    )


if __name__ == "__main__":
    main()
