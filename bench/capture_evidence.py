"""What ``fingerfit capture`` shows on simulated sessions, and whether its loop keeps up.

Run with ``.venv/bin/python bench/capture_evidence.py --subjects 8`` (both worlds) and
``.venv/bin/python bench/capture_evidence.py --keepup``.

**Evidence.** For each world (``SimConfig(world=...)``: the default one, left hands; MyoHand,
right hands), ``simulate_cohort(config, N, seed=2026)`` with the thumb and four fingers, the
evidence of every joint (:func:`fingerfit.capture.evidence`: the fit's own functions) over

* ``full``: every calibration recording the simulator writes (``grasp.csv``,
  ``thumb_circumduction.csv``, ``thumb_opposition.csv``, ``pinch.csv``);
* ``grasp 3/10``, ``grasp 5/10``: ``grasp.csv`` alone cut after 3 or 5 tenths of its frames
  (3 or 5 of its 10 cycles; the fingers only: a grasp does not turn the thumb's CMC
  about both axes).

Per joint kind: the axis confidence half-angle (median, max) and how many joints are
*enough*, against ``FitOptions.max_axis_ci_deg``.

**Keep-up.** ``thumb_circumduction.csv`` of one simulated thumb+index session, after its
``grasp.csv``, handed over in blocks of 8 frames at their 240 Hz due times, as the capture
loop does, while the evidence is computed beside it (a) in a thread (b) in
:class:`fingerfit.capture.EvidenceProcess`: the loop's lateness (ms) behind the due times.
"""

from __future__ import annotations

import argparse
import threading
import time
from collections import defaultdict
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from fingerfit.capture import Accumulator, EvidenceProcess, evidence
from fingerfit.estimate import FitOptions
from fingerfit.session import Recording, Session
from fingerfit.simulate import SimConfig, simulate_cohort, simulate_subject

DIGITS = ["thumb", "index", "middle", "ring", "little"]


def survey(n: int) -> None:
    """The evidence table (module docstring)."""
    ci: dict[tuple, list[float]] = defaultdict(list)
    enough: dict[tuple, list[bool]] = defaultdict(list)
    for world in ("default", "myohand"):
        hand = "right" if world == "myohand" else "left"
        config = SimConfig(fingers=tuple(DIGITS), world=world, hand=hand)
        for sub in simulate_cohort(config, n, seed=2026):
            s = sub.session
            grasp = next(r for r in s.grasp if r.name == "grasp.csv")
            cases = {"full": (s, DIGITS)}
            for k in (3, 5):
                cut = replace(s, grasp=[grasp.slice(slice(0, grasp.n_frames * k // 10))])
                cases[f"grasp {k}/10"] = (cut, DIGITS[1:])
            for case, (session, digits) in cases.items():
                for r in evidence(session, digits):
                    kind = f"{'thumb' if r.digit == 'thumb' else 'finger'} {r.joint}"
                    ci[(world, case, kind)].append(r.axis_ci_deg)
                    enough[(world, case, kind)].append(r.enough)
    print(f"max_axis_ci_deg = {FitOptions().max_axis_ci_deg:g}; {n} subjects per world\n")
    print("| world | recordings | joint | joints | axis CI median deg | max deg | enough |")
    print("|---|---|---|---|---|---|---|")
    for key in sorted(ci):
        v = np.array(ci[key])
        e = enough[key]
        print(
            f"| {key[0]} | {key[1]} | {key[2]} | {v.size} | {np.nanmedian(v):.2f} | "
            f"{np.nanmax(v):.2f} | {sum(e)}/{len(e)} |"
        )


def _loop(rec: Recording, hand_over: Callable[[Recording, Accumulator], None]) -> np.ndarray:
    """Lateness (ms) of each block of 8 frames handed over at its 240 Hz due time."""
    acc = Accumulator(rec.name, list(rec.poses))
    late = []
    t0 = time.perf_counter()
    for i in range(0, rec.n_frames, 8):
        due = t0 + i / 240.0
        now = time.perf_counter()
        if due > now:
            time.sleep(due - now)
        late.append(time.perf_counter() - due)
        block = rec.slice(slice(i, i + 8))
        acc.add(block)
        hand_over(block, acc)
    return 1e3 * np.array(late)


def keepup() -> None:
    """The keep-up table (module docstring)."""
    s = simulate_subject(SimConfig(fingers=("thumb", "index")), 3).session
    rec = next(r for r in s.grasp if r.name == "thumb_circumduction.csv")
    base: Session = replace(s, grasp=[r for r in s.grasp if r.name == "grasp.csv"])
    digits = ["thumb", "index"]
    runs = [0]
    worker: list[threading.Thread] = []

    def thread(block: Recording, acc: Accumulator) -> None:
        if not worker or not worker[-1].is_alive():
            snap = acc.recording()

            def run() -> None:
                evidence(replace(base, grasp=[*base.grasp, snap]), digits)
                runs[0] += 1

            worker.append(threading.Thread(target=run))
            worker[-1].start()

    late_thread = _loop(rec, thread)
    worker[-1].join()
    child = EvidenceProcess(base, rec.name, list(rec.poses), digits)
    got = [0]

    def process(block: Recording, acc: Accumulator) -> None:
        child.add(block)
        got[0] += child.latest() is not None

    late_process = _loop(rec, process)
    child.close()
    print(f"{rec.n_frames} frames ({rec.n_frames / 240:.1f} s) in blocks of 8 at 240 Hz\n")
    print("| evidence computed | results | lateness median ms | p99 ms | max ms |")
    print("|---|---|---|---|---|")
    for name, late, k in (
        ("in a thread", late_thread, runs[0]),
        ("in EvidenceProcess", late_process, got[0]),
    ):
        print(
            f"| {name} | {k} | {np.median(late):.1f} | {np.percentile(late, 99):.1f} | "
            f"{late.max():.1f} |"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subjects", type=int, default=8)
    parser.add_argument("--keepup", action="store_true", help="the keep-up table only")
    args = parser.parse_args()
    if args.keepup:
        keepup()
    else:
        survey(args.subjects)
