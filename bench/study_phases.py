"""Where one study task's time goes: read, fit and evaluate, draw Fig. 9, compact result.

``python bench/study_phases.py SESSIONS_DIR [--n 6]``: the mean over ``n`` simulated
session folders in ``SESSIONS_DIR`` (e.g. written by ``bench/study_speed.py``'s
``simulate``), one core, after one warm-up task; the parts of
:func:`fingerfit.evaluate.study.study_subject` timed one after another.
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("sessions", type=Path)
    ap.add_argument("--n", type=int, default=6)
    args = ap.parse_args()
    from fingerfit.estimate import FitOptions
    from fingerfit.evaluate import figures, study
    from fingerfit.io import load_session

    dirs = sorted(p for p in args.sessions.iterdir() if p.is_dir())
    study.study_subject(dirs[0], FitOptions())  # imports, caches
    parts = {"read": 0.0, "fit and evaluate": 0.0, "Fig. 9 PNG": 0.0, "compact + pickle": 0.0}
    chosen = dirs[1 : args.n + 1]
    for d in chosen:
        t = time.perf_counter()
        session = load_session(d)
        parts["read"] += time.perf_counter() - t
        t = time.perf_counter()
        res = study._subject(session, FitOptions())
        parts["fit and evaluate"] += time.perf_counter() - t
        t = time.perf_counter()
        _name, trajectory_time, tips, label = study._trajectory(res)
        figures.trajectories_png(trajectory_time, tips, label)
        parts["Fig. 9 PNG"] += time.perf_counter() - t
        t = time.perf_counter()
        pickle.dumps(res.compact())
        parts["compact + pickle"] += time.perf_counter() - t
    per = {k: v / len(chosen) for k, v in parts.items()}
    print(
        " | ".join(f"{k} {v:.3f} s" for k, v in per.items()), f"| total {sum(per.values()):.3f} s"
    )


if __name__ == "__main__":
    main()
