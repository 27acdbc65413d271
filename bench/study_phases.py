"""Where one study task's time goes: read, fit and evaluate, draw Fig. 9, compact result.

``python bench/study_phases.py SESSIONS_DIR [--n 6]``: the mean over ``n`` simulated
session folders in ``SESSIONS_DIR`` (e.g. written by ``bench/study_speed.py``'s
``simulate``), one core, after one warm-up task; the parts of
:func:`fingerfit.evaluate.subject.study_subject` timed one after another.

``--before SRC`` (the ``src`` folder of older code, e.g. from ``git worktree add
/tmp/before <commit>``) times that code beside this one in one run: ``--rounds`` rounds,
each a fresh process of the older code and then one of this code on the same sessions,
and reports each part's range over the rounds and the ratio of the medians (this / older).
"""

from __future__ import annotations

import argparse
import json
import os
import pickle
import statistics
import subprocess
import sys
import time
from pathlib import Path

PARTS = ("read", "fit and evaluate", "Fig. 9 PNG", "compact + pickle")


def _fig9(study, figures, result) -> None:
    """Draw a subject's Fig. 9 as the study task does (or did, in older code)."""
    if hasattr(study, "fig09_data"):
        _name, t, tips, label = study.fig09_data(result)
        figures.trajectories_png(t, tips, label)
    elif hasattr(study, "_trajectory"):  # evaluate/study.py before it was split (2026-11-26)
        _name, t, tips, label = study._trajectory(result)
        figures.trajectories_png(t, tips, label)
    else:  # before the kept figure (2026-11-26)
        import io

        _name, build = study._trajectory_figure(result)
        figures.save_to(build(), io.BytesIO(), tight=False)


def measure(sessions: Path, n: int) -> dict[str, float]:
    """Mean seconds per subject of each part, over ``n`` sessions after a warm-up one."""
    from fingerfit.estimate import FitOptions
    from fingerfit.evaluate import figures
    from fingerfit.io import load_session

    try:
        from fingerfit.evaluate import subject as study  # the study task's module
    except ImportError:  # older code: all in evaluate/study.py
        from fingerfit.evaluate import study
    evaluate = getattr(study, "evaluate_subject", None) or study._subject

    dirs = sorted(p for p in sessions.iterdir() if p.is_dir())
    study.study_subject(dirs[0], FitOptions())  # imports, caches
    parts = dict.fromkeys(PARTS, 0.0)
    chosen = dirs[1 : n + 1]
    for d in chosen:
        t = time.perf_counter()
        session = load_session(d)
        parts["read"] += time.perf_counter() - t
        t = time.perf_counter()
        res = evaluate(session, FitOptions())
        parts["fit and evaluate"] += time.perf_counter() - t
        t = time.perf_counter()
        _fig9(study, figures, res)
        parts["Fig. 9 PNG"] += time.perf_counter() - t
        t = time.perf_counter()
        pickle.dumps(res.compact())
        parts["compact + pickle"] += time.perf_counter() - t
    per = {k: v / len(chosen) for k, v in parts.items()}
    per["total"] = sum(per.values())
    return per


def _run(sessions: Path, n: int, src: str | None) -> dict[str, float]:
    """:func:`measure` in a fresh process, with ``src`` first on its path when given."""
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [src, env.get("PYTHONPATH")]))
    cmd = [sys.executable, __file__, str(sessions), "--n", str(n), "--json-line"]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if res.returncode:
        raise RuntimeError(res.stderr[-3000:])
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("sessions", type=Path)
    ap.add_argument("--n", type=int, default=6)
    ap.add_argument("--before", help="src folder of older code to time beside this one")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--json-line", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.json_line:
        print(json.dumps(measure(args.sessions, args.n)))
        return
    if args.before is None:
        per = measure(args.sessions, args.n)
        print(" | ".join(f"{k} {v:.3f} s" for k, v in per.items()))
        return
    runs: dict[str, list[dict[str, float]]] = {"before": [], "now": []}
    for r in range(args.rounds):
        for tag, src in (("before", args.before), ("now", None)):
            runs[tag].append(_run(args.sessions, args.n, src))
            print(f"round {r + 1} {tag}: total {runs[tag][-1]['total']:.3f} s", flush=True)
    print(f"\n| part (s per subject) | before ({args.before}) | now | now / before |")
    print("|---|---|---|---|")
    for part in (*PARTS, "total"):
        b = [x[part] for x in runs["before"]]
        a = [x[part] for x in runs["now"]]
        ratio = statistics.median(a) / statistics.median(b)
        print(f"| {part} | {min(b):.3f}-{max(b):.3f} | {min(a):.3f}-{max(a):.3f} | {ratio:.2f} |")


if __name__ == "__main__":
    main()
