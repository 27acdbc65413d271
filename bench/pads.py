"""Pads from pinch holds against the truth: simulated thumb + four-finger subjects.

Run with ``.venv/bin/python bench/pads.py --subjects 4``.

For each subject of ``SimConfig(fingers=("thumb", "index", "middle", "ring", "little"))``
(seeds ``simulate_cohort(config, n, seed=2026)``, the project's default world at default
noise) the session is fitted twice on the same data, with the ``<digit>.pad`` landmarks
digitised and without them, each with the pads fitted to the pinch holds (the default)
and without (``pinch_pads`` replaced by the identity: the landmark or geometry pads).
Figures, over the pad-to-pad events (``events.csv`` rows whose target is a digit), means
over each event's frames, then over events and subjects (user-axis model):

* **pad gap** (mm): distance between the two digits' model pad points;
* **to contact** (mm): mean distance of the two pad points from the true point where the
  pulps touch (truth ``thumb.contact.<finger>``);
* **contact_mm**: the model's pinch contact distance (the retarget engagement), mean over
  pairs.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import warnings

import numpy as np
import pandas as pd

import fingerfit.estimate.fit as fit_module
from fingerfit.estimate import fit_session
from fingerfit.evaluate.pinch import evaluate_pinches
from fingerfit.evaluate.truth import Truth
from fingerfit.simulate import SimConfig, simulate_cohort
from fingerfit.simulate.study import truth_table

DIGITS = ("thumb", "index", "middle", "ring", "little")


def _truth(sim) -> Truth:
    """The truth evaluate_pinches reads, built in memory (tips, pads, contacts)."""
    tips, pads, contacts = {}, {}, {}
    for name, frames in sim.truth.frames.items():
        t = truth_table(frames, sim.truth.pads)
        at = list(t.columns)

        def xyz(col: str, t=t) -> np.ndarray:
            return t[[f"{col}.{c}" for c in "xyz"]].to_numpy()

        tips[name] = {d: xyz(f"{d}.tip") for d in DIGITS}
        pads[name] = {d: xyz(f"{d}.pad") for d in DIGITS if f"{d}.pad.x" in at}
        contacts[name] = {
            ("thumb", d): xyz(f"thumb.contact.{d}") for d in DIGITS if f"thumb.contact.{d}.x" in at
        }
    return Truth({"contacts": sim.truth.contacts}, tips, pads, {}, contacts)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--subjects", type=int, default=4)
    ap.add_argument(
        "--sta", type=float, default=1.0, help="soft-tissue artefact scale (SimConfig.sta)"
    )
    args = ap.parse_args()
    rows = []
    for sim in simulate_cohort(SimConfig(fingers=DIGITS, sta=args.sta), args.subjects, seed=2026):
        truth = _truth(sim)
        session = sim.session
        landmarks = dict(session.landmarks)
        for digitised in (True, False):
            session.landmarks = {
                k: v for k, v in landmarks.items() if digitised or not k.endswith(".pad")
            }
            for pinch in (False, True):
                original = fit_module.pinch_pads
                if not pinch:
                    fit_module.pinch_pads = lambda s, m: m
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        model = fit_session(session)
                finally:
                    fit_module.pinch_pads = original
                pin = evaluate_pinches(model, session, truth)
                u = pin[pin["source"] == "user_axis"]
                contact = [c.contact_mm["user_axis"] for c in model.pinch_contacts]
                rows.append(
                    {
                        "subject": session.subject,
                        "pad landmarks": "digitised" if digitised else "none",
                        "pads": "pinch holds" if pinch else "prior only",
                        "pad gap mm": u["pad_gap_mm"].mean(),
                        "pad gap max mm": u["pad_gap_mm"].max(),
                        "to contact mm": u["pad_contact_mm"].mean(),
                        "to contact max mm": u["pad_contact_mm"].max(),
                        "contact_mm": np.mean(contact) if contact else np.nan,
                    }
                )
        session.landmarks = landmarks
    df = pd.DataFrame(rows)
    agg = {
        "pad gap mm": "mean",
        "pad gap max mm": "max",
        "to contact mm": "mean",
        "to contact max mm": "max",
        "contact_mm": "mean",
    }
    table = df.groupby(["pad landmarks", "pads"], sort=False).agg(agg).round(2)
    print(f"{args.subjects} subjects, {len(DIGITS)} digits, user-axis model")
    head = ["pad landmarks", "pads", *agg]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for (lm, pads), r in table.iterrows():
        print(f"| {lm} | {pads} | " + " | ".join(f"{r[c]:.2f}" for c in agg) + " |")


if __name__ == "__main__":
    main()
