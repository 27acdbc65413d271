"""The fit's quality gates over many valid simulated hands: how many are refused, by which
gate, and how well the joints a gate flags are fitted.

    python bench/gates.py [--subjects 100] [--conditions all] [--before REV] [--json OUT]

Per world -- the conditions of ``bench/accuracy.py`` (the default world, MyoHand, and the
others), each with the thumb and the four fingers and the thumb's protocols --
``--subjects`` whole hands are simulated and fitted by ``fit_session`` with the default
options, as ``fingerfit fit`` does. Every simulated hand is a valid session (the
simulator's motion is a hand's), so every refusal is a gate refusing a valid hand;
refusals are counted by the gate that spoke. A refused hand is fitted again with
``force`` to show the refused joint's fitted flexion axis against the truth.

Per joint the figures each gate tests are kept (median cycle range of motion, pooled
``s5/s6``, null agreement, the 95 % axis confidence half-angle) with the angle between the
fitted and the true flexion axis (parent sensor frame, deg): the joints that carry a
"weak evidence" note are listed with both, so the table shows whether the reported
uncertainty covers the error.

``--before REV`` runs this script on that revision's ``src`` (``git archive``) over the
same hands in a subprocess and prints the counts side by side.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import CONDITIONS
from pool import run_tasks
from revision import run_at_revision, run_meta

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.simulate import SimConfig, simulate_subject
from fingerfit.simulate.truth import relative_truth_in_parent
from fingerfit.transforms import angle_between_axes

DIGITS = ("thumb", "index", "middle", "ring", "little")
#: Words of the quality notes that flag a joint as weakly determined (a warning of the fit).
FLAGS = ("weak evidence", "known only to", "fitted anyway")
#: Words of a refusal message -> the gate that spoke.
GATES = (
    ("grasp cycle(s) found", "cycles"),
    ("range of motion", "range of motion"),
    ("does not determine a hinge axis", "conditioning"),
    ("do not spread along one axis", "null agreement"),
    ("sagittal plane", "sagittal plane"),
    ("did not excite", "saddle excitation"),
)


def gate_of(message: str) -> str:
    """The gate a refusal message comes from (``plausibility`` for the physical checks,
    ``other`` for anything else)."""
    for words, gate in GATES:
        if words in message:
            return gate
    return "plausibility" if "implausible" in message or "plausib" in message else "other"


def joint_rows(sim, model) -> list[dict]:
    """Per fitted joint: the gates' figures, the weak-evidence notes and the true axis
    error (deg, parent sensor frame)."""
    rows = []
    for finger, fm in model.fingers.items():
        for j, jm in fm.joints.items():
            q = jm.quality
            _, axis = model.in_parent(finger, j)
            _, true_axis = relative_truth_in_parent(sim, finger, j)
            rows.append(
                {
                    "joint": f"{finger} {j}",
                    "rom_deg": float(np.median(q.rom_deg)) if q.rom_deg else None,
                    "pooled_conditioning": q.pooled_conditioning,
                    "null_agreement_deg": q.null_agreement_deg,
                    "axis_ci_deg": q.axis_ci_deg,
                    "axis_error_deg": float(np.degrees(angle_between_axes(axis, true_axis))),
                    "two_axes": j in fm.second_axes,
                    "notes": [n for n in q.notes if any(w in n for w in FLAGS)],
                }
            )
    return rows


def run_subject(task: tuple[str, dict, int]) -> dict:
    """Simulate one hand of one condition, fit it as ``fingerfit fit`` does; on a refusal,
    fit it again with ``force``."""
    cond, overrides, seed = task
    warnings.simplefilter("ignore")
    out: dict = {"condition": cond, "seed": seed, "refused": None}
    try:
        config = SimConfig(fingers=DIGITS, test=False, targets=False, **overrides)
    except (TypeError, FingerfitError) as exc:  # a revision (--before) without the condition
        out["unavailable"] = str(exc)
        return out
    sim = simulate_subject(config, seed)
    t0 = time.perf_counter()
    try:
        model = fit_session(sim.session, FitOptions())
    except FingerfitError as exc:
        out["refused"] = str(exc)
        out["gate"] = gate_of(str(exc))
        try:
            model = fit_session(sim.session, FitOptions(force=True))
        except FingerfitError as hard:
            out["forced"] = str(hard)
            return out
    out["fit_s"] = time.perf_counter() - t0
    out["joints"] = joint_rows(sim, model)
    return out


def summarise(results: list[dict], conditions: list[str]) -> dict:
    """Per condition: hands, refusals (by gate, with the messages), the joints noted as
    weakly determined (their uncertainty and true error), and the smallest margin to each
    gate over all joints."""
    summary = {}
    for cond in conditions:
        rs = [r for r in results if r["condition"] == cond]
        usable = [r for r in rs if "unavailable" not in r]
        refused = [r for r in usable if r["refused"]]
        by_gate: dict[str, int] = {}
        for r in refused:
            by_gate[r["gate"]] = by_gate.get(r["gate"], 0) + 1
        joints = [j for r in usable for j in r.get("joints", [])]
        weak = [{"seed": r["seed"], **j} for r in usable for j in r.get("joints", []) if j["notes"]]

        def smallest(key: str, js: list[dict] = joints) -> float | None:
            vals = [j[key] for j in js if j[key] is not None]
            return float(min(vals)) if vals else None

        errors = np.array([j["axis_error_deg"] for j in joints]) if joints else np.zeros(0)
        worst = sorted(
            ({"seed": r["seed"], **j} for r in usable for j in r.get("joints", [])),
            key=lambda j: -j["axis_error_deg"],
        )[:3]
        summary[cond] = {
            "hands": len(usable),
            "unavailable": len(rs) - len(usable),
            "refused": len(refused),
            "refused_by_gate": by_gate,
            "refusals": [{"seed": r["seed"], "message": r["refused"]} for r in refused],
            "weak_joints": weak,
            "smallest_rom_deg": smallest("rom_deg"),
            "smallest_pooled_conditioning": smallest("pooled_conditioning"),
            "largest_null_disagreement_deg": max(
                (j["null_agreement_deg"] for j in joints), default=None
            ),
            "axis_error_p95_deg": float(np.percentile(errors, 95)) if errors.size else None,
            "axis_error_max_deg": float(errors.max()) if errors.size else None,
            "largest_errors": worst,
        }
    return summary


def run(args: argparse.Namespace, conditions: list[str]) -> list[dict]:
    """Every hand of every condition, in ``args.workers`` processes."""
    tasks = []
    for ci, cond in enumerate(conditions):
        seeds = np.random.SeedSequence([args.seed, ci]).spawn(args.subjects)
        tasks += [(cond, CONDITIONS[cond], int(s.generate_state(1)[0])) for s in seeds]
    return run_tasks(run_subject, tasks, args.workers, "hands")


def run_before(rev: str, args: argparse.Namespace) -> dict:
    """This script on revision ``rev``'s ``src``, same hands."""
    cmd = ["--quiet", "--subjects", str(args.subjects), "--workers", str(args.workers)]
    cmd += ["--seed", str(args.seed), "--conditions", args.conditions]
    return run_at_revision(rev, __file__, cmd)["summary"]


def _f(x: float | None, fmt: str = ".1f") -> str:
    return "–" if x is None else format(x, fmt)


def markdown(summary: dict, before: dict | None, rev: str | None) -> str:
    """Refusals per world (before and after), the margins, and the weakly determined
    joints."""
    head = "| world | hands | refused |"
    rule = "|---|---|---|"
    if before is not None:
        head = f"| world | hands | refused before ({rev}) | refused after | gates before |"
        rule = "|---|---|---|---|---|"
    lines = [
        "### Refusals of valid whole hands (default options)",
        "",
        head + " smallest ROM deg | smallest pooled s5/s6 | axis error p95 / max deg |",
        rule + "---|---|---|",
    ]
    for cond, s in summary.items():
        cells = [cond, str(s["hands"])]
        if before is not None:
            b = before.get(cond, {})
            gates = ", ".join(f"{g} {n}" for g, n in b.get("refused_by_gate", {}).items())
            cells += [str(b.get("refused", "–")), str(s["refused"]), gates or "–"]
        else:
            cells.append(str(s["refused"]))
        cells += [
            _f(s["smallest_rom_deg"]),
            _f(s["smallest_pooled_conditioning"], ".2f"),
            f"{_f(s['axis_error_p95_deg'])} / {_f(s['axis_error_max_deg'])}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    refusals = [(c, r) for c, s in summary.items() for r in s["refusals"]]
    if before is not None:
        refusals_before = [(c, r) for c, s in before.items() for r in s["refusals"]]
        lines += ["", f"Refusals before ({rev}):", ""]
        lines += [f"- {c}, seed {r['seed']}: {r['message']}" for c, r in refusals_before]
        lines += ["- none"] if not refusals_before else []
    lines += ["", "Refusals after:", ""]
    lines += [f"- {c}, seed {r['seed']}: {r['message']}" for c, r in refusals]
    lines += ["- none"] if not refusals else []
    head = [
        "| world | seed | joint | ROM deg | pooled s5/s6 | axis +/- deg (95 %) | "
        "true axis error deg | two axes | flagged |",
        "|---|---|---|---|---|---|---|---|---|",
    ]

    def row(c: str, j: dict) -> str:
        return (
            f"| {c} | {j['seed']} | {j['joint']} | {_f(j['rom_deg'])} | "
            f"{_f(j['pooled_conditioning'], '.2f')} | {_f(j['axis_ci_deg'])} | "
            f"{j['axis_error_deg']:.1f} | {'yes' if j['two_axes'] else 'no'} | "
            f"{'yes' if j['notes'] else 'no'} |"
        )

    lines += ["", "### Joints the fit flagged (after): weak evidence, axis confidence", ""]
    lines += head + [row(c, j) for c, s in summary.items() for j in s["weak_joints"]]
    lines += ["", "### The largest true axis errors per world (after)", ""]
    lines += head + [row(c, j) for c, s in summary.items() for j in s["largest_errors"]]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--subjects", type=int, default=100)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--seed", type=int, default=39)
    ap.add_argument(
        "--conditions", default=",".join(CONDITIONS), help="comma-separated subset of the worlds"
    )
    ap.add_argument("--before", default=None, help="a git revision: its counts side by side")
    ap.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    chosen = [c.strip() for c in args.conditions.split(",")]
    for c in chosen:
        if c not in CONDITIONS:
            ap.error(f"unknown condition '{c}'")
    t0 = time.perf_counter()
    summary = summarise(run(args, chosen), chosen)
    meta = run_meta("gates.py", time.perf_counter() - t0, subjects=args.subjects)
    before = run_before(args.before, args) if args.before else None
    if before is not None:
        meta["before"] = {"revision": args.before, "summary": before}
    if not args.quiet:
        print(markdown(summary, before, args.before))
    if args.json:
        args.json.write_text(json.dumps({"meta": meta, "summary": summary}, indent=1) + "\n")


if __name__ == "__main__":
    main()
