"""Reader and writer throughput and peak memory (issue 15, item 2).

Makes one simulated recording of ``--rows`` rows in each tracker format (pose CSV, wide
CSV, Liberty ASCII, Liberty binary), then reads each in a fresh process and reports rows
(or records) per second and the peak resident memory above the process's state just
before the read (``/proc/self/clear_refs`` resets the peak there), beside the bytes of the
arrays the returned recording keeps. Writers (pose CSV, wide CSV, the angles CSV) are
timed the same way, after a first write of 1,000 frames (the first call's imports are
not timed, as a reader's warm-up read): the pose writers write the pose recording
(``--rows`` rows), the wide writers the wide file's recording (``--rows`` frames of two
stations, the table the wide readers read), the angles writers the angles table of the
pose recording (one row per frame). With ``--before SRC`` (the
``src`` folder of another checkout, e.g. ``git worktree add /tmp/before <commit>``) every
measurement is repeated with that code in the same run, for ratios.

Beside rows per second the table gives MB/s of file and numbers per second (a wide row
holds 15 numbers, a pose-CSV row 8), and the speed of the library alone on the same file
as the floor: Arrow's CSV reader with the column types declared (all threads) for the
CSV files, ``np.fromfile`` and the float64 conversion of the values for Liberty binary,
and ``pyarrow.csv.write_csv`` of the written table (read back) for the writers; for
the Parquet writers ``pyarrow.parquet.write_table`` of the written table with pyarrow's
defaults (zstd) and with fingerfit's own options
(:func:`fingerfit.io.parquet.writer_options`, same row groups).

Every file is read without the hygiene check (``check=False``; the pose CSV reader has
none), so the formats compare like for like; the check itself
(:func:`fingerfit.io.hygiene.check_recording`: unit plausibility and jumps, which the
wide, Liberty and C3D readers run by default and ``convert`` runs on every format) is
timed apart on the recording read, and the table gives the rows per second with it.

Run by ``bench/speed.py`` (``make bench``) or alone::

    python bench/io_speed.py --rows 2000000 --before /tmp/before/src

``--tables pose,wide`` measures only those tables (CSV and Parquet).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: Child process: import, read or write, report JSON on stdout.
_CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
kind, path, out = sys.argv[2], sys.argv[3], sys.argv[4]

def status(key):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(key):
                return int(line.split()[1]) * 1024
    return 0

def start():
    # reset the peak (VmHWM) to the current size and return that size: the peak then
    # belongs to what follows, not to an earlier step of this process
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
    except OSError:
        pass
    return status("VmRSS:")

import numpy as np
import fingerfit.io.posecsv as posecsv, fingerfit.io.posewrite as posewrite, fingerfit.io.widecsv as widecsv
import fingerfit.io.liberty as liberty
from fingerfit.session import UNITS_TO_MM

def read_angles(p):
    # the angles table into float64 columns: Parquet through fingerfit.io.parquet, CSV
    # through the batched Arrow parser the readers use, into preallocated rows
    if p.endswith(".parquet"):
        from fingerfit.io.parquet import ANGLES, read_parquet
        return read_parquet(p, ANGLES).columns
    from fingerfit.io.fastcsv import RowArrays, csv_batches, estimate_rows
    from pathlib import Path
    with open(p) as fh:
        names = fh.readline().strip().split(",")
    rows = None
    for _, n_bytes, cols in csv_batches(Path(p), names):
        m = cols[names[0]].size
        if rows is None:
            rows = RowArrays(estimate_rows(Path(p), m, n_bytes), len(names))
        block = rows.reserve(m)
        for j, c in enumerate(names):
            block[:, j] = cols[c]
    return rows.array()

def read(p):
    if kind.startswith("angles"):
        return read_angles(p)
    if kind.startswith("pose"):
        return posecsv.read_pose_csv(p, units="mm", rate_hz=240.0)
    if kind.startswith("wide"):
        return widecsv.read_wide_csv(p, units="mm", rate_hz=240.0, check=False)
    if kind == "liberty-ascii":
        return liberty.read_liberty_ascii(p, items="pos,quat,frame", rate_hz=240.0, check=False)
    if kind == "liberty-binary":
        return liberty.read_liberty_binary(p, items="pos,quat,frame", rate_hz=240.0, check=False)
    raise SystemExit(kind)

def write(rec, p):
    if kind.startswith("write-pose"):
        posewrite.write_pose_csv(p, rec)
    elif kind.startswith("write-wide"):
        widecsv.write_wide_csv(p, rec)
    elif kind.startswith("write-angles"):
        from fingerfit.estimate import FitOptions, fit_session
        from fingerfit.kinematics import compute_kinematics, kinematics_table
        from fingerfit.simulate import SimConfig, simulate_subject
        model = fit_session(simulate_subject(SimConfig(fingers=("index",)), 0).session,
                            FitOptions(method="tang2018"))
        table = kinematics_table(compute_kinematics(model, rec))
        try:  # the code under test's own writer (code older than write_table: pandas)
            from fingerfit.io.fastcsv import write_table as writer
        except ImportError:
            writer = None

        def write_angles(t, q):
            if kind.endswith("-parquet"):
                from fingerfit.io.parquet import angles_meta, write_parquet
                write_parquet(q, t, angles_meta("mm"))
            elif writer is not None:
                writer(q, t)
            else:
                from fingerfit.io.atomic import atomic_write
                with atomic_write(q, newline="") as fh:
                    t.to_csv(fh, index=False, lineterminator="\n")

        write_angles(table.iloc[:1000], p + ".warm")  # first-call imports, not timed
        os.unlink(p + ".warm")
        base = start()
        t = time.perf_counter()
        write_angles(table, p)
        return time.perf_counter() - t, base, table.shape[0]

PARQUET = kind.endswith("-parquet")

if kind.startswith("write"):
    import os
    if kind.startswith("write-wide"):  # the wide recording read by the wide readers
        rec = widecsv.read_wide_csv(path, units="mm", rate_hz=240.0, check=False)
    else:
        rec = posecsv.read_pose_csv(path, units="mm", rate_hz=240.0)
    target = path + (".out.parquet" if PARQUET else ".out")
    if kind.startswith("write-angles"):
        seconds, base, rows = write(rec, target)
    else:
        write(rec.slice(slice(0, 1000)), target)  # first-call imports, not timed
        os.unlink(target)
        base = start()
        t = time.perf_counter()
        write(rec, target)
        seconds = time.perf_counter() - t
        rows = (sum(int(p.valid.sum()) for p in rec.poses.values())
                if kind.startswith("write-pose") else rec.n_frames)
    size = os.path.getsize(target)
    peak = status("VmHWM:") - base
    if PARQUET:
        import pyarrow.parquet as pq
        n_cols = len(pq.read_schema(target).names)
    else:
        with open(target) as fh:
            n_cols = len(fh.readline().split(","))
    numbers = rows * (n_cols - (1 if kind.startswith("write-pose") else 0))  # sensor: text
    floor = floor_options = None
    if PARQUET:  # pyarrow writing the same table (read back): the library alone, with its
        # defaults (zstd) and with the options of the code under test (when it has them)
        import pyarrow.parquet as pq
        table = pq.read_table(target)
        t = time.perf_counter()
        pq.write_table(table, target + ".floor", compression="zstd")
        floor = time.perf_counter() - t
        try:
            from fingerfit.io.parquet import ROW_GROUP_ROWS, writer_options
        except ImportError:  # older code
            pass
        else:
            t = time.perf_counter()
            pq.write_table(table, target + ".floor", row_group_size=ROW_GROUP_ROWS,
                           **writer_options(table.schema))
            floor_options = time.perf_counter() - t
        os.unlink(target + ".floor")
    elif out == "now":  # Arrow writing the same table (read back typed): the formatting floor
        import pyarrow.csv as pacsv
        table = pacsv.read_csv(target)
        t = time.perf_counter()
        pacsv.write_csv(table, target + ".floor",
                        pacsv.WriteOptions(quoting_style="none", quoting_header="none"))
        floor = time.perf_counter() - t
        os.unlink(target + ".floor")
    os.unlink(target)
    print(json.dumps({"seconds": seconds, "rows": rows, "bytes": size, "numbers": numbers,
                      "peak_above": peak, "floor_seconds": floor,
                      "floor_options_seconds": floor_options}))
    raise SystemExit(0)

if kind.startswith("floor"):
    # the raw speed of the library alone on the same file: Arrow's CSV reader with the
    # column types declared (all threads), or NumPy's structured view of the records
    t = time.perf_counter()
    if kind == "floor-parquet":
        import pyarrow.parquet as pq
        pq.read_table(path)
    elif kind == "floor-csv":
        import pyarrow as pa, pyarrow.csv as pacsv
        with open(path) as fh:
            names = fh.readline().strip().split(",")
        types = {n: (pa.string() if n == "sensor" else pa.float64()) for n in names}
        pacsv.read_csv(path, convert_options=pacsv.ConvertOptions(column_types=types))
    else:  # floor-binary: the records' values as float64
        dt = liberty._binary_dtype(liberty.parse_items("pos,quat,frame"))
        recs = np.fromfile(path, dtype=dt)
        vals = [recs[k].astype(float) for k in ("position", "quaternion", "frame")]
    print(json.dumps({"seconds": time.perf_counter() - t}))
    raise SystemExit(0)

# warm-up on a small file of the same kind (first-call imports and caches)
read(out)
base = start()
t = time.perf_counter()
rec = read(path)
seconds = time.perf_counter() - t
if kind.startswith("angles"):
    kept = (sum(v.nbytes for v in rec.values()) if isinstance(rec, dict) else rec.nbytes)
    peak = status("VmHWM:") - base
    print(json.dumps({"seconds": seconds, "peak_above": peak, "kept": kept,
                      "check_seconds": None}))
    raise SystemExit(0)
kept = rec.time.nbytes + sum(p.position.nbytes + p.rotation.nbytes for p in rec.poses.values())
peak = status("VmHWM:") - base
# The hygiene check (unit plausibility, jumps) that the wide, Liberty and C3D readers run
# by default and ``convert`` runs on every format: timed apart, after the peak is taken.
try:
    from fingerfit.io.hygiene import check_recording
except ImportError:  # older code
    check_seconds = None
else:
    t = time.perf_counter()
    check_recording(rec, path)
    check_seconds = time.perf_counter() - t
print(json.dumps({"seconds": seconds, "peak_above": peak, "kept": kept,
                  "frames": rec.n_frames, "sensors": len(rec.poses),
                  "check_seconds": check_seconds}))
"""

FORMATS = ("pose", "wide", "angles", "liberty-ascii", "liberty-binary")
#: The same tables as Parquet files (``fingerfit.io.parquet``), read and written in the
#: same run beside the CSV path.
PARQUET_READS = ("pose-parquet", "wide-parquet", "angles-parquet")
#: Numbers per row (record) of each file read: pose CSV time, x, y, z, qw, qx, qy, qz (and
#: a sensor name); wide CSV time and 7 per station (2 stations); Liberty position (3),
#: quaternion (4) and frame count (and a station number); the angles table: its columns
#: (set by :func:`make_files`).
NUMBERS_PER_ROW = {"pose": 8, "wide": 15, "liberty-ascii": 8, "liberty-binary": 8}
WRITERS = ("write-pose", "write-wide", "write-angles")
PARQUET_WRITERS = ("write-pose-parquet", "write-wide-parquet", "write-angles-parquet")


def make_files(directory: Path, rows: int) -> dict[str, tuple[Path, Path, int]]:
    """Simulated files of about ``rows`` rows per format, and a small one of each.

    Returns
    -------
    dict
        Format -> (big file, small file, rows or records in the big file).
    """
    import numpy as np

    from fingerfit.estimate import FitOptions, fit_session
    from fingerfit.io.liberty import write_liberty_ascii, write_liberty_binary
    from fingerfit.io.parquet import angles_meta, write_table_file
    from fingerfit.io.posewrite import write_pose_csv
    from fingerfit.io.widecsv import write_wide_csv
    from fingerfit.kinematics import compute_kinematics, kinematics_table
    from fingerfit.session import PoseSeries, Recording
    from fingerfit.simulate import SimConfig, simulate_subject
    from fingerfit.simulate.trackerfiles import liberty_records

    session = simulate_subject(SimConfig(fingers=("index",)), 0).session
    rec = session.test[0]
    model = fit_session(session, FitOptions(method="tang2018"))
    n_sensors = len(rec.poses)

    def tiled(n_frames: int) -> Recording:
        reps = -(-n_frames // rec.n_frames)
        poses = {
            k: PoseSeries(
                np.tile(v.position, (reps, 1))[:n_frames],
                np.tile(v.rotation, (reps, 1, 1))[:n_frames],
            )
            for k, v in rec.poses.items()
        }
        return Recording("long", np.arange(n_frames) / 240.0, poses)

    out: dict[str, tuple[Path, Path, int]] = {}
    stations = {i + 1: name for i, name in enumerate(rec.poses)}
    for size, tag in ((rows, "big"), (2000, "small")):
        long = tiled(size // n_sensors)
        write_pose_csv(directory / f"pose-{tag}.csv", long)
        write_pose_csv(directory / f"pose-{tag}.parquet", long)
        angles = kinematics_table(compute_kinematics(model, long))
        NUMBERS_PER_ROW["angles"] = NUMBERS_PER_ROW["angles-parquet"] = angles.shape[1]
        for ext in ("csv", "parquet"):
            write_table_file(directory / f"angles-{tag}.{ext}", angles, angles_meta("mm"))
        del angles
        # wide CSV: one row per frame of two stations (hand and one phalanx), the layout
        # of the real Liberty logs in shared/data
        two = tiled(size)
        two = Recording("two", two.time, {k: two.poses[k] for k in list(two.poses)[:2]})
        write_wide_csv(directory / f"wide-{tag}.csv", two)
        write_wide_csv(directory / f"wide-{tag}.parquet", two)
        recs = liberty_records(long, stations, 240.0)
        write_liberty_ascii(directory / f"liberty-{tag}.txt", recs)
        write_liberty_binary(directory / f"liberty-{tag}.bin", recs)
    n_frames = rows // n_sensors
    for kind, name, count in (
        ("pose", "pose-{}.csv", n_frames * n_sensors),
        ("pose-parquet", "pose-{}.parquet", n_frames * n_sensors),
        ("wide", "wide-{}.csv", rows),
        ("wide-parquet", "wide-{}.parquet", rows),
        ("angles", "angles-{}.csv", n_frames),
        ("angles-parquet", "angles-{}.parquet", n_frames),
        ("liberty-ascii", "liberty-{}.txt", n_frames * n_sensors),
        ("liberty-binary", "liberty-{}.bin", n_frames * n_sensors),
    ):
        out[kind] = (directory / name.format("big"), directory / name.format("small"), count)
    return out


def child(src: Path, kind: str, path: Path, extra: str) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    res = subprocess.run(
        [sys.executable, "-c", _CHILD, str(src), kind, str(path), extra],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if res.returncode != 0:
        raise RuntimeError(f"{kind} with {src}: {res.stderr.strip().splitlines()[-1:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def best_of(jobs: dict[str, tuple], repeat: int) -> dict[str, dict]:
    """Each job's fastest of ``repeat`` fresh processes (:func:`child` of its arguments),
    the jobs taking turns, so that a load coming and going on the shared cores falls on
    the current and the older code alike."""
    runs: dict[str, list[dict]] = {label: [] for label in jobs}
    for _ in range(repeat):
        for label, args in jobs.items():
            runs[label].append(child(*args))
    return {label: min(r, key=lambda x: x["seconds"]) for label, r in runs.items()}


def run(
    rows: int, before: Path | None = None, repeat: int = 2, tables: tuple[str, ...] | None = None
) -> dict:
    """Measure every reader and writer (best of ``repeat`` fresh processes); with
    ``tables`` (e.g. ``("pose", "wide")``) only those tables, CSV and Parquet."""

    def wanted(kind: str) -> bool:
        base = kind.removeprefix("write-").removesuffix("-parquet")
        return tables is None or base in tables

    src_now = Path(__file__).resolve().parents[1] / "src"
    codes = {"now": src_now} | ({"before": before} if before is not None else {})
    results: dict = {"rows": rows, "read": {}, "write": {}, "load_before": os.getloadavg()[0]}
    with tempfile.TemporaryDirectory(prefix="fingerfit-io-bench-") as tmp:
        files = make_files(Path(tmp), rows)
        for kind in filter(wanted, FORMATS + PARQUET_READS):
            big, small, count = files[kind]
            entry = {"rows": count, "file_bytes": big.stat().st_size}
            new = kind == "angles"  # no older reader to compare
            jobs = {
                label: (src, kind, big, str(small))
                for label, src in codes.items()
                if not new or label == "now"
            }
            for label, best in best_of(jobs, repeat).items():
                entry[label] = best | {"rows_per_s": count / best["seconds"]}
            floor_kind = {
                "pose": "floor-csv",
                "wide": "floor-csv",
                "angles": "floor-csv",
                "liberty-binary": "floor-binary",
            } | dict.fromkeys(PARQUET_READS, "floor-parquet")
            if kind in floor_kind:
                entry["floor_seconds"] = min(
                    child(src_now, floor_kind[kind], big, str(small))["seconds"]
                    for _ in range(repeat)
                )
            results["read"][kind] = entry
        for kind in filter(wanted, WRITERS + PARQUET_WRITERS):
            entry = {}
            # each table's recording: the pose CSV's (the angles table's too), the wide CSV's
            source = files["wide" if kind.startswith("write-wide") else "pose"][0]
            jobs = {label: (src, kind, source, label) for label, src in codes.items()}
            for label, best in best_of(jobs, repeat).items():
                entry[label] = best | {"rows_per_s": best["rows"] / best["seconds"]}
            results["write"][kind.removeprefix("write-")] = entry
    results["load_after"] = os.getloadavg()[0]
    return results


def table(res: dict) -> str:
    """The results as a Markdown table."""
    has_before = any("before" in e for e in res["read"].values())
    head = (
        "| measurement | rows (file) | now | MB/s | M numbers/s | with the hygiene check |"
        " library alone, same file | peak above start / arrays kept |"
    )
    if has_before:
        head += " before | before peak / kept | speed-up |"
    lines = [head, "|---" * (head.count("|") - 1) + "|"]

    def row(label: str, e: dict, unit: str, numbers: int | None) -> str:
        now = e["now"]
        n = e.get("rows", now.get("rows"))
        size = e.get("file_bytes", now.get("bytes"))
        numbers = numbers if numbers is not None else now.get("numbers", 0)
        kept = now.get("kept")
        mem = (
            f"{now['peak_above'] / 1e6:.0f} MB / {kept / 1e6:.0f} MB "
            f"({now['peak_above'] / kept:.2f}x)"
            if kept
            else f"{now['peak_above'] / 1e6:.0f} MB"
        )
        floor = e.get("floor_seconds", now.get("floor_seconds"))
        fl = f"{n / floor / 1e6:.2f} M {unit}/s ({floor:.2f} s)" if floor else "n/a (not CSV)"
        check = now.get("check_seconds")
        ck = (
            f"{n / (now['seconds'] + check) / 1e6:.2f} M {unit}/s (check {check:.2f} s)"
            if check is not None
            else "n/a (a writer, or code without the check)"
        )
        s = (
            f"| {label} | {n:,} ({size / 1e6:.0f} MB) | {now['rows_per_s'] / 1e6:.2f} M {unit}/s "
            f"({now['seconds']:.2f} s) | {size / now['seconds'] / 1e6:.0f} | "
            f"{numbers / now['seconds'] / 1e6:.1f} | {ck} | {fl} | {mem} |"
        )
        if "before" in e:
            b = e["before"]
            bm = f"{b['peak_above'] / 1e6:.0f} MB" + (
                f" ({b['peak_above'] / b['kept']:.2f}x)" if b.get("kept") else ""
            )
            s += (
                f" {b['rows_per_s'] / 1e6:.2f} M {unit}/s ({b['seconds']:.2f} s) | {bm} | "
                f"{b['seconds'] / now['seconds']:.2f}x |"
            )
        elif has_before:
            s += " | | |"
        return s

    names = {
        "pose": "read pose CSV",
        "wide": "read wide CSV",
        "liberty-ascii": "read Liberty ASCII",
        "liberty-binary": "read Liberty binary",
        "angles": "read angles CSV (batched Arrow parser, float64 columns)",
    }
    for kind, e in res["read"].items():
        if kind.endswith("-parquet"):
            continue
        unit = "records" if kind == "liberty-binary" else "rows"
        lines.append(row(names[kind], e, unit, e["rows"] * NUMBERS_PER_ROW[kind]))
    for kind, e in res["write"].items():
        if not kind.endswith("-parquet"):
            lines.append(row(f"write {kind} CSV", e, "rows", None))
    lines.append(
        f"(load average {res.get('load_before', 0):.1f} before, "
        f"{res.get('load_after', 0):.1f} after: the machine's 2 cores are shared)"
    )
    return "\n".join(lines)


def parquet_table(res: dict) -> str:
    """Parquet beside CSV in the same run, as a Markdown table."""
    head = (
        "| table | operation | rows | CSV | Parquet | Parquet / CSV | file CSV / Parquet |"
        " Parquet peak above start / arrays kept | pyarrow alone |"
        " pyarrow alone, fingerfit's writer options |"
    )
    has_before = any(
        "before" in e for op in ("read", "write") for k, e in res[op].items() if "parquet" in k
    )
    if has_before:
        head += " Parquet before | before peak / kept | speed-up |"
    lines = [head, "|---" * (head.count("|") - 1) + "|"]
    for name in ("pose", "wide", "angles"):
        for op in ("read", "write"):
            c, p = res[op].get(name), res[op].get(f"{name}-parquet")
            if c is None or p is None:
                continue
            cn, pn = c["now"], p["now"]
            rows = c.get("rows", cn.get("rows"))
            csv_bytes = c.get("file_bytes", cn.get("bytes"))
            pq_bytes = p.get("file_bytes", pn.get("bytes"))
            kept = pn.get("kept")
            if kept:
                mem = (
                    f"{pn['peak_above'] / 1e6:.0f} MB / {kept / 1e6:.0f} MB "
                    f"({pn['peak_above'] / kept:.2f}x)"
                )
            else:
                mem = f"{pn['peak_above'] / 1e6:.0f} MB (a writer)"
            floor = p.get("floor_seconds", pn.get("floor_seconds"))
            same = pn.get("floor_options_seconds")
            lines.append(
                f"| {name} | {op} | {rows:,} | {cn['rows_per_s'] / 1e6:.2f} M rows/s "
                f"({cn['seconds']:.2f} s) | {pn['rows_per_s'] / 1e6:.2f} M rows/s "
                f"({pn['seconds']:.2f} s) | {pn['rows_per_s'] / cn['rows_per_s']:.1f}x | "
                f"{csv_bytes / 1e6:.0f} MB / {pq_bytes / 1e6:.0f} MB | {mem} | "
                + (f"{rows / floor / 1e6:.2f} M rows/s |" if floor else "n/a |")
                + (f" {rows / same / 1e6:.2f} M rows/s |" if same else " n/a |")
            )
            if "before" in p:
                b = p["before"]
                bm = f"{b['peak_above'] / 1e6:.0f} MB" + (
                    f" ({b['peak_above'] / b['kept']:.2f}x)" if b.get("kept") else ""
                )
                lines[-1] += (
                    f" {b['rows_per_s'] / 1e6:.2f} M rows/s ({b['seconds']:.2f} s) | {bm} | "
                    f"{b['seconds'] / pn['seconds']:.2f}x |"
                )
            elif has_before:
                lines[-1] += " | | |"
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--rows", type=int, default=2_000_000)
    ap.add_argument("--before", type=Path, default=None, help="src folder of older code")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument(
        "--tables", default=None, help="only these tables, e.g. pose,wide,angles (CSV and Parquet)"
    )
    args = ap.parse_args()
    t = time.perf_counter()
    tables = tuple(args.tables.split(",")) if args.tables else None
    res = run(args.rows, args.before, args.repeat, tables)
    print(table(res))
    print()
    print(parquet_table(res))
    print(f"({time.perf_counter() - t:.0f} s)")
    if args.json:
        args.json.write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
