"""Quaternion-convention checks: how far the right reading is from the wrong ones.

Run ``.venv/bin/python bench/plausibility_conventions.py``. On the realistic simulated
subjects (``SimConfig()``, seeds 0-9, all four fingers: 120 joints) prints the pivot
residual (mm) of each joint as read and the best other reading, and the static noise of
the reference; then the same grasp recordings written conjugated and in ``x,y,z,w``
order, as read and read the right way; then, when ``../shared/data/polhemus-liberty``
is beside the repository, the residual of each reading of the real Liberty recordings.
These are the margins of the table in ``docs/plausibility.md``
(``fingerfit.estimate.plausibility.pivot_residuals``, ``convention_checks``).
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests._conventions import KINDS, as_written
from tests._shared_recordings import LIBERTY, LIBERTY_FILES, liberty_pivot_residuals

from fingerfit.estimate.plausibility import convention_checks, pivot_residuals
from fingerfit.session import PoseSeries, Session
from fingerfit.simulate import SimConfig, simulate_subject

ALL = ("index", "middle", "ring", "little")
SEEDS = range(10)


@functools.cache
def _session(seed: int) -> Session:
    return simulate_subject(SimConfig(fingers=ALL), seed).session


def _grasp_pose(s: Session, sensor: str) -> PoseSeries:
    """A sensor's poses over all grasp recordings of a session."""
    return PoseSeries(
        *[
            np.concatenate([getattr(g.pose(sensor), k) for g in s.grasp])
            for k in ("position", "rotation")
        ]
    )


def main() -> None:
    """Print the margins, one line per kind of data."""
    rows = []
    for seed in SEEDS:
        for c in convention_checks(_session(seed), ALL):
            r = c.residual_mm
            rows.append((r["as read"], min(v for k, v in r.items() if k != "as read"), c.noise_mm))
    a = np.array(rows)
    print(
        f"realistic seeds 0-9, 4 fingers, 120 joints: as read {a[:, 0].min():.2f}-{a[:, 0].max():.2f} mm; "
        f"best other reading {a[:, 1].min():.2f}-{a[:, 1].max():.2f} mm; ratio >= {np.min(a[:, 1] / a[:, 0]):.1f}; "
        f"reference noise {a[:, 2].min():.2f}-{a[:, 2].max():.2f} mm"
    )
    for kind in KINDS:
        vals = []
        for seed in SEEDS:
            s = _session(seed)
            for f in ALL:
                for p, c in (
                    ("hand", f"{f}.proximal"),
                    (f"{f}.proximal", f"{f}.middle"),
                    (f"{f}.middle", f"{f}.distal"),
                ):
                    res, _ = pivot_residuals(
                        as_written(_grasp_pose(s, p), kind), as_written(_grasp_pose(s, c), kind)
                    )
                    vals.append((res["as read"], res[kind]))
        v = np.array(vals)
        print(
            f"written {kind}: as read {v[:, 0].min():.2f}-{v[:, 0].max():.2f} mm (median {np.median(v[:, 0]):.1f}); "
            f"read the right way {v[:, 1].min():.2f}-{v[:, 1].max():.2f} mm"
        )
    if (LIBERTY / LIBERTY_FILES[0]).is_file():
        for name, res in liberty_pivot_residuals().items():
            print(name, {k: round(v, 2) for k, v in res.items()})
    else:
        print(f"no Liberty recordings in {LIBERTY}")


if __name__ == "__main__":
    main()
