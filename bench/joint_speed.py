"""Time ``fit_joint`` against an earlier version of ``estimate/joint.py``, side by side.

Usage::

    git show <commit>:src/fingerfit/estimate/joint.py > /tmp/joint_before.py
    .venv/bin/python bench/joint_speed.py --before /tmp/joint_before.py

The earlier file is loaded as a sibling module of the installed ``fingerfit.estimate``
(so it uses today's estimators), and both versions run the same cases in alternation;
the table gives the median time of each and the ratio. Cases: simulated joints (the
hinge, two-axis and ball motions of ``tests/test_joint_api.py``, 1200 frames at 120 Hz)
and, when ``../shared/data`` is present, the real Liberty logs (120 Hz).
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def load_before(path: Path):
    """The earlier ``joint.py`` as module ``fingerfit.estimate._joint_before``."""
    import fingerfit.estimate

    spec = importlib.util.spec_from_file_location(
        "fingerfit.estimate._joint_before", path,
        submodule_search_locations=None,
    )  # fmt: skip
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = fingerfit.estimate.__name__
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


def cases() -> dict[str, tuple[np.ndarray, np.ndarray, float]]:
    """Name -> (parent (n, 4, 4) mm, child (n, 4, 4) mm, rate Hz)."""
    from tests.test_joint_api import DATA, LIBERTY_FILES, motion

    out = {f"simulated {k}": (*motion(k), 120.0) for k in ("hinge", "two_axis", "ball")}
    if all((DATA / f).is_file() for f in LIBERTY_FILES):
        from fingerfit.io.widecsv import read_wide_csv
        from fingerfit.transforms import transform_from_pr

        rec = read_wide_csv(DATA / "rotate-90deg-z.csv", units="cm", rate_hz=120.0)
        p, c = rec.poses["1"], rec.poses["2"]
        out["real Liberty z"] = (
            transform_from_pr(p.position, p.rotation), transform_from_pr(c.position, c.rotation),
            120.0,
        )  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True, help="earlier estimate/joint.py")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args()
    from fingerfit.estimate import joint as after

    before = load_before(args.before)
    rows = []
    for name, (p, c, rate) in cases().items():
        for kind, method in (("auto", "sara"), ("hinge", "sara"), ("hinge", "robust")):
            times: dict[str, list[float]] = {"before": [], "after": []}
            for _ in range(args.repeat):
                for tag, mod in (("before", before), ("after", after)):
                    t0 = time.perf_counter()
                    try:
                        mod.fit_joint(p, c, kind, method=method, rate_hz=rate)
                    except Exception as exc:  # a refusal costs time too; report it
                        err = type(exc).__name__
                    else:
                        err = ""
                    times[tag].append(time.perf_counter() - t0)
            b, a = statistics.median(times["before"]), statistics.median(times["after"])
            rows.append((name, kind, method, 1000 * b, 1000 * a, b / a, err))
    print(
        f"{'case':22s} {'kind':6s} {'method':7s} {'before ms':>10s} {'after ms':>9s} {'ratio':>6s}"
    )
    for name, kind, method, b, a, r, err in rows:
        print(f"{name:22s} {kind:6s} {method:7s} {b:10.1f} {a:9.1f} {r:6.2f} {err}")


if __name__ == "__main__":
    main()
