"""Thumb CMC (saddle joint): the saddle estimator vs the finger two-axis MP estimator.

Run ``.venv/bin/python bench/saddle.py`` (``--seeds 20``). Each seed draws a thumb CMC
(``tests/_saddle_data.py``: axes 60-80 deg apart, each 5-15 deg off perpendicular to the
metacarpal, lines 3-8 mm apart) and a recording of 10 cycles of circumduction and
opposition (2,400 frames; flexion about -20..+40 deg, ab/adduction about -10..+40 deg),
seen through the simulator's tracker errors. Conditions: ``clean`` (no errors), ``noisy``
(the simulator's default tracker errors: ``noise = 1``, distortion field on) and
``noisy+sta`` (also the simulator's default skin sliding, ``sta = 1``). Both axis orders
are generated: ``flexion_first`` (the thumb CMC: flexion axis proximal) and
``abduction_first`` (the finger MP order). On the same data:

* ``saddle`` -- :func:`fingerfit.estimate.saddle.fit_saddle` with the generated order;
* ``twoaxis`` -- :func:`fingerfit.estimate.twoaxis.fit_two_axis` (the finger MP fit;
  model ``Rot(b_abd) Rot(a_flex)``), started from the pooled SARA hinge axis as in the
  fit pipeline, with the same cycles as ``groups`` (its axes whether or not it accepts
  them; where it does not, the pipeline keeps the hinge);
* ``hinge (SARA)`` -- the pooled hinge axis itself, scored against the flexion axis.

The saddle fit's reported jackknife SDs are listed beside its errors.

Errors: the angle between each fitted and true axis (deg) and the absolute error of the
signed offset between the lines (mm; each fit's axes signed to the truth first). Printed as
mean / max over the seeds.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests._saddle_data import make_case

from fingerfit.errors import FingerfitError
from fingerfit.estimate.pooled import sara_axis
from fingerfit.estimate.saddle import fit_saddle
from fingerfit.estimate.twoaxis import fit_two_axis
from fingerfit.transforms import angle_between_axes, unit

CONDITIONS = {
    "clean": dict(noise=0.0, distortion=False, sta=0.0),
    "noisy": dict(noise=1.0, distortion=True, sta=0.0),
    "noisy+sta": dict(noise=1.0, distortion=True, sta=1.0),
}


def _errors(case, flex, abd, c_flex, c_abd) -> tuple[float, float, float]:
    """Flexion and ab/adduction axis errors (deg) and offset error (mm)."""
    flex = flex * np.sign(flex @ case.flexion_axis)
    abd = abd * np.sign(abd @ case.abduction_axis)
    offset = float((c_abd - c_flex) @ unit(np.cross(flex, abd)))
    return (
        float(np.degrees(angle_between_axes(flex, case.flexion_axis))),
        float(np.degrees(angle_between_axes(abd, case.abduction_axis))),
        abs(offset - case.offset_mm),
    )


def run(seeds: int) -> dict:
    out: dict = {}
    for order in ("flexion_first", "abduction_first"):
        for cond, kw in CONDITIONS.items():
            rows = {"saddle": [], "twoaxis": [], "hinge": [], "sd": []}
            times = []
            accepted = 0
            refused = 0
            for seed in range(seeds):
                case = make_case(seed, order=order, **kw)
                args = (case.rotation, case.translation, case.reference_rotation)
                t0 = time.perf_counter()
                try:
                    f = fit_saddle(*args, order=order, groups=case.groups)
                except FingerfitError:
                    refused += 1
                    continue
                times.append(time.perf_counter() - t0)
                rows["saddle"].append(
                    _errors(
                        case, f.flexion_axis, f.abduction_axis, f.flexion_point, f.abduction_point
                    )
                )
                rows["sd"].append((f.flexion_sd_deg, f.abduction_sd_deg, f.offset_sd_mm))
                hinge = sara_axis(case.rotation)[0]
                rows["hinge"].append(
                    (
                        float(np.degrees(angle_between_axes(hinge, case.flexion_axis))),
                        np.nan,
                        np.nan,
                    )
                )
                t = fit_two_axis(*args, hinge, groups=case.groups)
                accepted += t.accepted
                rows["twoaxis"].append(
                    _errors(
                        case, t.flexion_axis, t.abduction_axis, t.flexion_point, t.abduction_point
                    )
                )
            out[(order, cond)] = dict(
                **{k: np.array(v) for k, v in rows.items()},
                accepted=accepted,
                refused=refused,
                seconds=float(np.median(times)) if times else float("nan"),
            )
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args()
    res = run(args.seeds)
    print(f"{args.seeds} seeds; errors mean / max (axes deg, offset mm)\n")
    print(
        "| data order | condition | estimator | flexion axis | ab/adduction axis | offset | note |"
    )
    print("|---|---|---|---|---|---|---|")
    for (order, cond), r in res.items():
        for est in ("saddle", "sd", "twoaxis", "hinge"):
            e = r[est]
            cells = [
                "-" if np.isnan(e[0, i]) else f"{e[:, i].mean():.3g} / {e[:, i].max():.3g}"
                for i in range(3)
            ]
            if est == "saddle":
                note = f"median {1000 * r['seconds']:.0f} ms per fit"
                if r["refused"]:
                    note += f"; refused {r['refused']}"
            elif est == "sd":
                est, note = "saddle jackknife SD", "the reported SDs, not errors"
            elif est == "twoaxis":
                note = f"two-axis accepted in {r['accepted']}/{e.shape[0]}"
            else:
                est, note = "hinge (SARA)", "vs the flexion axis"
            print(f"| {order} | {cond} | {est} | {' | '.join(cells)} | {note} |")


if __name__ == "__main__":
    main()
