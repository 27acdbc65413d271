"""The share of reading and writing files in ``session``, ``fit`` and ``angles`` on a
2 M-row Parquet recording (issue 29's last target: the I/O at most 10 % of the commands).

A simulated subject (one finger: the hand sensor and three on the finger) is written as
Parquet recordings: its reference, grasp and target recordings as simulated, and a
free-motion test recording tiled to ``--rows`` rows (``--rows / 4`` frames at 240 Hz;
2,000,000 rows: 35 minutes). Then, in one process (after one warm-up run of the three
commands on the subject's own short test recording)::

    fingerfit session S --subject S01 --reference reference.parquet --grasp grasp.parquet \\
        --targets targets.parquet --test test.parquet --landmarks landmarks.csv --events events.csv
    fingerfit fit S -o model.json
    fingerfit angles model.json S/test.parquet -o angles.parquet

Each command's wall time is measured, and within it the time spent in the functions that
read or write files: the recording readers (``read_pose_csv``, whatever their format),
the file copies of ``session`` (``shutil.copyfile``), the table writers
(``write_table_file``, ``write_parquet``, ``ParquetSink``'s writes and close), the model's
JSON (``load_model``, ``save_model``). Calls nested in another timed call count once.
What is left is the commands' own work: the checks of a session, the fit, the
kinematics, the progress bars.

``python bench/io_share.py --rows 2000000 [--repeat 2] [--json FILE]``
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

#: (module, attribute) of the functions counted as reading or writing files.
IO_FUNCTIONS = (
    ("fingerfit.io.posecsv", "read_pose_csv"),
    ("fingerfit.io.parquet", "write_table_file"),
    ("fingerfit.io.parquet", "write_parquet"),
    ("fingerfit.model.file", "load_model"),
    ("fingerfit.model.file", "save_model"),
    ("shutil", "copyfile"),
)


class IoClock:
    """Wall time inside the I/O functions, each function patched wherever a module holds
    it by name (for the rest of the process); a call inside another timed call is not
    counted again."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)
        self.depth = 0

    def _wrap(self, name: str, func):
        @functools.wraps(func)
        def timed(*args, **kwargs):
            if self.depth:
                return func(*args, **kwargs)
            self.depth += 1
            t = time.perf_counter()
            try:
                return func(*args, **kwargs)
            finally:
                self.seconds[name] += time.perf_counter() - t
                self.depth -= 1

        return timed

    def install(self) -> None:
        import importlib

        import fingerfit.io.parquet as pq_mod

        targets = {}
        for mod_name, attr in IO_FUNCTIONS:
            func = getattr(importlib.import_module(mod_name), attr)
            targets[id(func)] = (attr, func)
        wrapped = {k: self._wrap(name, f) for k, (name, f) in targets.items()}
        for mod in list(sys.modules.values()):
            if mod is None or not (getattr(mod, "__name__", "") or "").startswith(
                ("fingerfit", "shutil")
            ):
                continue
            for attr, value in list(vars(mod).items()):
                if id(value) in wrapped and callable(value):
                    setattr(mod, attr, wrapped[id(value)])
        sink = pq_mod.ParquetSink
        for method in ("write", "write_blocks", "close"):
            func = getattr(sink, method)
            setattr(sink, method, self._wrap("ParquetSink", func))

    def reset(self) -> None:
        self.seconds.clear()


def make_inputs(directory: Path, rows: int) -> dict[str, Path]:
    """The subject's recordings as Parquet (the test recording tiled to ``rows`` rows),
    its landmarks and events as CSV."""
    import numpy as np

    from fingerfit.io import write_pose_csv
    from fingerfit.io.sessiondir import write_events, write_landmarks
    from fingerfit.session import PoseSeries, Recording
    from fingerfit.simulate import SimConfig, simulate_subject

    session = simulate_subject(SimConfig(fingers=("index",)), 0).session
    out: dict[str, Path] = {
        "landmarks": write_landmarks(directory / "landmarks.csv", session.landmarks),
        "events": write_events(
            directory / "events.csv",
            [
                dataclasses.replace(e, recording=Path(e.recording).stem + ".parquet")
                for e in session.events
            ],
        ),
        "short_test": directory / "short" / "test.parquet",
    }
    (directory / "short").mkdir()
    for kind, recs in (
        ("reference", [session.reference]),
        ("grasp", session.grasp),
        ("targets", session.targets),
    ):
        out[kind] = write_pose_csv(directory / f"{kind}.parquet", recs[0])
    test = session.test[0]
    write_pose_csv(out["short_test"], test)
    n_frames = rows // len(test.poses)
    reps = -(-n_frames // test.n_frames)
    long = Recording(
        "test.parquet",
        np.arange(n_frames) / session.rate_hz,
        {
            k: PoseSeries(
                np.tile(v.position, (reps, 1))[:n_frames],
                np.tile(v.rotation, (reps, 1, 1))[:n_frames],
            )
            for k, v in test.poses.items()
        },
    )
    out["test"] = write_pose_csv(directory / "test.parquet", long)
    return out


def commands(files: dict[str, Path], test: Path, work: Path) -> list[tuple[str, list[str]]]:
    s, model, angles = work / "S", work / "model.json", work / "angles.parquet"
    return [
        (
            "session",
            [
                "session",
                str(s),
                "--subject",
                "S01",
                "--reference",
                str(files["reference"]),
                "--grasp",
                str(files["grasp"]),
                "--targets",
                str(files["targets"]),
                "--test",
                str(test),
                "--landmarks",
                str(files["landmarks"]),
                "--events",
                str(files["events"]),
                "-q",
            ],
        ),
        ("fit", ["fit", str(s), "-o", str(model), "-q"]),
        ("angles", ["angles", str(model), str(s / test.name), "-o", str(angles), "-q"]),
    ]


def run_commands(clock: IoClock, cmds) -> list[dict]:
    from typer.testing import CliRunner

    from fingerfit.cli import app

    results = []
    for label, args in cmds:
        clock.reset()
        t = time.perf_counter()
        res = CliRunner().invoke(app, args)
        wall = time.perf_counter() - t
        if res.exit_code != 0:
            raise SystemExit(f"{label} failed ({res.exit_code}): {res.output[-2000:]}")
        io = dict(clock.seconds)
        results.append(
            {"command": label, "seconds": wall, "io": io, "io_seconds": sum(io.values())}
        )
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=2_000_000)
    parser.add_argument("--repeat", type=int, default=2, help="runs of the three commands")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args()
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    clock = IoClock()
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="fingerfit-io-share-") as tmp:
        tmp = Path(tmp)
        files = make_inputs(tmp, args.rows)
        clock.install()
        warm = tmp / "warm"
        warm.mkdir()
        run_commands(clock, commands(files, files["short_test"], warm))
        runs = []
        for i in range(args.repeat):
            work = tmp / f"run{i}"
            work.mkdir()
            runs.append(run_commands(clock, commands(files, files["test"], work)))
    out = {"rows": args.rows, "runs": runs, "load_before": load_before,
           "load_after": os.getloadavg()[0]}  # fmt: skip
    print("| command | wall | reading and writing files | share | of which |")
    print("|---|---|---|---|---|")
    for label in ("session", "fit", "angles"):
        best = min((r for run in runs for r in run if r["command"] == label),
                   key=lambda r: r["seconds"])  # fmt: skip
        parts = ", ".join(
            f"{k} {v:.2f} s" for k, v in sorted(best["io"].items(), key=lambda x: -x[1])
        )
        print(f"| {label} | {best['seconds']:.2f} s | {best['io_seconds']:.2f} s | "
              f"{100 * best['io_seconds'] / best['seconds']:.0f} % | {parts} |")  # fmt: skip
    totals = [(sum(r["seconds"] for r in run), sum(r["io_seconds"] for r in run)) for run in runs]
    wall, io = min(totals)
    print(f"| the three | {wall:.2f} s | {io:.2f} s | {100 * io / wall:.0f} % | |")
    print(f"(load average {load_before:.1f} before, {out['load_after']:.1f} after)")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
