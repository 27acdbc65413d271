"""OpenSim's IMU inverse kinematics against fingerfit's angles, per coordinate.

Run with ``.venv/bin/python bench/opensim_ik.py --subjects 3 --seconds 10 --json bench/opensim_ik.json``
(needs the ``opensim`` extra).

For each world (``default``, ``myohand``) and condition (``exact``: noise-free, rigid
sensors, pure hinges; ``realistic``: the simulator's defaults, Liberty-like tracker noise
and distortion, soft-tissue artefact, centre migration, MP and MCP ab/adduction),
``--subjects`` thumb + index subjects are simulated and fitted (default method). Each
model is exported (``fingerfit.export.osim_string``), the first ``--seconds`` of its
free-motion test recording are written as OpenSim's orientation table
(``fingerfit.io.opensim.write_orientations``, what ``fingerfit convert -o X.sto``
writes) and as the motion of fingerfit's angles (``write_coordinates``, what
``fingerfit angles -o X.mot`` writes); OpenSim's ``IMUInverseKinematicsTool`` then
solves for the coordinates from the orientations alone. Reported per rotational
coordinate: the RMS over frames of the difference (deg), mean and largest over
subjects.

On realistic recordings the same is also run with each subject's **true** model
(``truth_model(sim, migration=False)``: the true axes, centres fixed, exported the same
way): what remains there comes from the two estimators, not from the fitted geometry. fingerfit computes each joint from the relative
orientation of the two sensors beside it (``docs/methods.md``); OpenSim's IK fits every
coordinate of the chain at once to every sensor's orientation in ground (each weight 1),
so a sensor's error is shared along the chain and the hand's orientation absorbs part of
it.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import json
import platform
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.test_export_osim import ik_differences, run_imu_ik

from fingerfit import __version__
from fingerfit.estimate import fit_session
from fingerfit.export import osim_string, write_coordinates
from fingerfit.io.opensim import write_orientations
from fingerfit.kinematics import compute_kinematics
from fingerfit.simulate import SimConfig, simulate_cohort
from fingerfit.simulate.truthmodel import truth_model

SEED = 2037
WORLDS = {"default": {}, "myohand": {"world": "myohand", "hand": "right"}}


def run(subjects: int, seconds: float, work: Path) -> dict:
    results: dict = {}
    for world, kw in WORLDS.items():
        for condition in ("exact", "realistic"):
            base = dict(fingers=("thumb", "index"), **kw)
            config = SimConfig.exact(**base) if condition == "exact" else SimConfig(**base)
            sims = simulate_cohort(config, subjects, seed=SEED)
            models = {"fitted": [fit_session(s.session) for s in sims]}
            if condition == "realistic":
                models["true"] = [truth_model(s, migration=False) for s in sims]
            for kind, per_subject in models.items():
                key = f"{world}/{condition}/{kind}"
                rows = []
                t0 = time.perf_counter()
                for i, (sim, model) in enumerate(zip(sims, per_subject, strict=True)):
                    d = work / key / f"S{i:02d}"
                    d.mkdir(parents=True)
                    rec = sim.session.test[0]
                    rec = rec.slice(rec.time < seconds)
                    (d / "hand.osim").write_text(osim_string(model), encoding="utf-8")
                    write_coordinates(
                        d / "fingerfit.mot", compute_kinematics(model, rec), model, rec
                    )
                    write_orientations(d / "rec.sto", rec)
                    ik = run_imu_ik(d / "hand.osim", d / "rec.sto", d / "ik.mot", seconds)
                    rows.append(ik_differences(ik, d / "fingerfit.mot"))
                names = list(rows[0])
                results[key] = {
                    n: {
                        "mean_rms_deg": float(np.mean([r[n] for r in rows])),
                        "max_rms_deg": float(np.max([r[n] for r in rows])),
                    }
                    for n in names
                }
                print(f"\n{key} ({subjects} subjects, {time.perf_counter() - t0:.0f} s)")
                for n, v in results[key].items():
                    print(f"  {n:24s} mean {v['mean_rms_deg']:6.3f}  max {v['max_rms_deg']:6.3f}")
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as tmp:
        results = run(args.subjects, args.seconds, Path(tmp))
    if args.json:
        import opensim as osim

        doc = {
            "fingerfit": __version__,
            "opensim": osim.GetVersion(),
            "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
            "machine": platform.platform(),
            "subjects": args.subjects,
            "seconds": args.seconds,
            "seed": SEED,
            "rms_deg": results,
        }
        args.json.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
