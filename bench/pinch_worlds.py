"""Robot pinches over the person's pinch holds, in every simulated world.

    python bench/pinch_worlds.py [--seeds 4] [--conditions all] [--before REV] [--json OUT]

Per world -- the conditions of ``bench/accuracy.py`` (the default world, MyoHand, and the
others) -- ``--seeds`` thumb + index hands are simulated, fitted by ``fit_session`` with
the default options (pads from the pinch holds), and their ``pinch.csv`` retargeted onto
Shadow and Allegro by the ``tip`` method. Scored in every frame of every pinch hold of the
thumb and the index (``events.csv``: the simulator's truth of when the pads touch, not the
model's pad distance): the distance between the robot's thumb and index pad points (the
map's ``pad`` frames; Shadow its tip sites), mm. The target is <= 3 mm in every frame of
every hold. Each hand twice: fitted with every pinch event (the holds retargeted are
those the pads and the contact distance were fitted to), and fitted without
``pinch.csv``'s events (*unseen holds*: the model knows the one touch of the opposition
recording, as when a later or live recording is retargeted). ``--whole-hand`` adds hands
with the thumb and the four fingers in the default and MyoHand worlds.

``--before REV`` runs this script on that revision's ``src`` (``git archive``) over the same
hands in a subprocess and prints both side by side.
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
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import CONDITIONS
from pool import run_tasks
from revision import run_at_revision, run_meta

from fingerfit.errors import FingerfitError
from fingerfit.estimate import fit_session
from fingerfit.kinematics import compute_kinematics
from fingerfit.retarget import resolve, retarget
from fingerfit.simulate import SimConfig, simulate_subject

ROBOTS = ("shadow", "allegro")
PAIR = {"thumb", "index"}
#: The requirement: robot pad points at most this far apart in every hold frame (mm).
TARGET_MM = 3.0
WHOLE = ("thumb", "index", "middle", "ring", "little")
WHOLE_WORLDS = ("realistic", "MyoHand world")
#: The two calibrations of each hand (module docstring).
SCENARIOS = ("fitted holds", "unseen holds")


def run_hand(task: tuple[str, str, dict, int, tuple[str, ...]]) -> dict:
    """One hand: fit, retarget ``pinch.csv`` onto each robot, the pad gap per hold."""
    label, cond, overrides, seed, digits = task
    warnings.simplefilter("ignore")
    out: dict = {"world": label, "condition": cond, "seed": seed}
    try:
        config = SimConfig(fingers=digits, test=False, targets=False, **overrides)
    except (TypeError, FingerfitError) as exc:  # a revision (--before) without the condition
        out["unavailable"] = str(exc)
        return out
    sim = simulate_subject(config, seed)
    rec = sim.session.recording("pinch.csv")
    holds = [
        (rec.time >= e.start) & (rec.time <= e.end)
        for e in sim.session.events
        if e.recording == rec.name and e.is_pinch and {e.finger, e.target} == PAIR
    ]
    unseen = [e for e in sim.session.events if e.recording != rec.name]
    sessions = {
        SCENARIOS[0]: sim.session,
        SCENARIOS[1]: replace(sim.session, events=unseen),
    }
    for scenario, session in sessions.items():
        row: dict = {"robots": {}}
        out[scenario] = row
        try:
            model = fit_session(session)
        except FingerfitError as exc:
            row["refused"] = str(exc)
            continue
        kin = compute_kinematics(model, rec)
        person = np.linalg.norm(
            kin.motions["user_axis"]["thumb"].pad - kin.motions["user_axis"]["index"].pad, axis=1
        )
        contact = model.pinch_contact("thumb", "index")
        row["contact_mm"] = None if contact is None else contact.contact_mm["user_axis"]
        row["person_hold_mm"] = [float(np.median(person[h])) for h in holds]
        for name in ROBOTS:
            robot, rmap = resolve(name, None, model.hand)
            res = retarget(model, rec, robot, rmap, "tip", kin=kin)
            p = robot.positions(res.q, [rmap.digits["thumb"].pad, rmap.digits["index"].pad])
            gap = np.linalg.norm(p[:, 0] - p[:, 1], axis=1) * 1000.0
            tip = np.linalg.norm(res.tips - res.targets, axis=2)
            row["robots"][name] = {
                "hold_max_mm": [float(gap[h].max()) for h in holds],
                "hold_frames_mm": np.concatenate([gap[h] for h in holds]).tolist(),
                "tip_err_median_mm": float(np.nanmedian(tip)),
                "violations": int(res.violations),
            }
    return out


def tasks(args: argparse.Namespace, conditions: list[str]) -> list[tuple]:
    """(label, condition, overrides, seed, digits) of every hand; seeds 0 .. ``--seeds``-1."""
    out = [
        (c, c, CONDITIONS[c], s, ("thumb", "index")) for c in conditions for s in range(args.seeds)
    ]
    if args.whole_hand:
        out += [
            (f"{c}, whole hand", c, CONDITIONS[c], s, WHOLE)
            for c in WHOLE_WORLDS
            if c in conditions
            for s in range(args.seeds)
        ]
    return out


def summarise(results: list[dict]) -> dict:
    """Per world and calibration (``"<world>; <scenario>"``): :func:`_figures`."""
    summary: dict = {}
    for world in dict.fromkeys(r["world"] for r in results):
        for scenario in SCENARIOS:
            rs = [
                r[scenario] | {"seed": r["seed"]}
                for r in results
                if r["world"] == world and scenario in r
            ]
            summary[f"{world}; {scenario}"] = _figures(rs)
    return summary


def _figures(rs: list[dict]) -> dict:
    """One world and calibration: per robot, holds, holds with a frame over the target, the
    largest and the median gap over hold frames, the worst hands."""
    out: dict = {"hands": len(rs), "refused": sum("refused" in r for r in rs)}
    for name in ROBOTS:
        fitted = [r for r in rs if name in r["robots"]]
        maxima = [m for r in fitted for m in r["robots"][name]["hold_max_mm"]]
        frames = np.concatenate(
            [r["robots"][name]["hold_frames_mm"] for r in fitted] or [np.zeros(0)]
        )
        worst = sorted(
            ((max(r["robots"][name]["hold_max_mm"], default=0.0), r["seed"]) for r in fitted),
            reverse=True,
        )
        tips = [r["robots"][name]["tip_err_median_mm"] for r in fitted]
        out[name] = {
            "holds": len(maxima),
            "holds_over_target": int(sum(m > TARGET_MM for m in maxima)),
            "max_mm": float(max(maxima, default=float("nan"))),
            "median_mm": float(np.median(frames)) if frames.size else float("nan"),
            "tip_err_median_mm": float(np.median(tips)) if tips else float("nan"),
            "violations": int(sum(r["robots"][name]["violations"] for r in fitted)),
            "worst": [{"seed": s, "max_mm": m} for m, s in worst[:3] if m > TARGET_MM],
        }
    return out


def run(args: argparse.Namespace, conditions: list[str]) -> list[dict]:
    """Every hand, in ``args.workers`` processes, in the order of :func:`tasks`."""
    todo = tasks(args, conditions)
    results = run_tasks(run_hand, todo, args.workers, "hands")
    order = {t[0]: i for i, t in enumerate(todo)}
    return sorted(results, key=lambda r: (order[r["world"]], r["seed"]))


def run_before(rev: str, args: argparse.Namespace) -> dict:
    """This script on revision ``rev``'s ``src``, same hands."""
    cmd = ["--quiet", "--seeds", str(args.seeds), "--workers", str(args.workers)]
    cmd += ["--conditions", args.conditions] + (["--whole-hand"] if args.whole_hand else [])
    return run_at_revision(rev, __file__, cmd)["summary"]


def markdown(summary: dict, before: dict | None, rev: str | None) -> str:
    """One row per world and robot: holds over the target and the largest gap, before and
    after."""
    if before is None:
        head = "| world | robot | hands | holds | holds > 3 mm | max mm | median mm | tip err mm |"
        rule = "|---|---|---|---|---|---|---|---|"
    else:
        head = (
            f"| world | robot | hands | holds | holds > 3 mm before ({rev}) | after | "
            "max mm before | after | median mm before | after | tip err mm before | after |"
        )
        rule = "|---|---|---|---|---|---|---|---|---|---|---|---|"
    lines = ["### Robot pad distance over the person's thumb-index pinch holds", "", head, rule]
    for world, s in summary.items():
        for name in ROBOTS:
            a = s.get(name)
            if a is None:
                continue
            cells = [world, name, str(s["hands"]), str(a["holds"])]
            if before is None:
                cells += [
                    str(a["holds_over_target"]),
                    f"{a['max_mm']:.1f}",
                    f"{a['median_mm']:.2f}",
                    f"{a['tip_err_median_mm']:.1f}",
                ]
            else:
                b = before.get(world, {}).get(name, {})

                def pair(key: str, fmt: str, a=a, b=b) -> list[str]:
                    return [format(b[key], fmt) if key in b else "–", format(a[key], fmt)]

                cells += pair("holds_over_target", "d") + pair("max_mm", ".1f")
                cells += pair("median_mm", ".2f") + pair("tip_err_median_mm", ".1f")
            lines.append("| " + " | ".join(cells) + " |")
    bad = [
        f"- {w} {n}: seeds "
        + ", ".join(f"{x['seed']} ({x['max_mm']:.1f} mm)" for x in s[n]["worst"])
        for w, s in summary.items()
        for n in ROBOTS
        if n in s and s[n]["worst"]
    ]
    lines += ["", "Worst hands after (largest hold gap over the target):", ""]
    lines += bad or ["- none"]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument(
        "--conditions", default=",".join(CONDITIONS), help="comma-separated subset of the worlds"
    )
    ap.add_argument("--whole-hand", action="store_true", help="also whole hands (default, MyoHand)")
    ap.add_argument("--before", default=None, help="a git revision: its figures side by side")
    ap.add_argument("--quiet", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    chosen = [c.strip() for c in args.conditions.split(",")]
    for c in chosen:
        if c not in CONDITIONS:
            ap.error(f"unknown condition '{c}'")
    t0 = time.perf_counter()
    results = run(args, chosen)
    summary = summarise(results)
    meta = run_meta("pinch_worlds.py", time.perf_counter() - t0)
    before = run_before(args.before, args) if args.before else None
    if before is not None:
        meta["before"] = {"revision": args.before, "summary": before}
    if not args.quiet:
        print(markdown(summary, before, args.before))
    if args.json:

        def lean(row: dict) -> dict:
            """A calibration's row without the per-frame gaps."""
            robots = {
                n: {k: v for k, v in x.items() if k != "hold_frames_mm"}
                for n, x in row.get("robots", {}).items()
            }
            return row | {"robots": robots}

        hands = [{k: lean(v) if k in SCENARIOS else v for k, v in r.items()} for r in results]
        args.json.write_text(
            json.dumps({"meta": meta, "summary": summary, "hands": hands}, indent=1) + "\n"
        )


if __name__ == "__main__":
    main()
