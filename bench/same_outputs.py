"""Do two source trees write the same files? Runs the same commands with each and compares
every output byte for byte.

Usage::

    python bench/same_outputs.py --before /tmp/before/src --after src [--subjects 2]

Each tree runs in a subprocess of this Python with ``PYTHONPATH=<tree>`` (its
``fingerfit`` package is the one imported), in the same working folder (moved aside
afterwards, so paths written into files are equal), with the same commands:

1. ``fingerfit demo --out demo`` (simulate a cohort, fit every subject, run the study:
   models, angles, tables, figures, ``summary.json``, ``report.html``);
2. ``fingerfit simulate --format liberty-ascii`` and ``liberty-binary`` (the tracker file
   writers), then the commands they write to ``commands.sh``: ``fingerfit convert`` of
   every Liberty file (the readers), ``session`` and ``fit``;
3. ``fingerfit joint`` on a converted grasp recording, each kind (the joint API and its
   refusals);
4. ``fingerfit export`` of the demo's models as URDF and MJCF, both variants (the robot
   writers).

Every file below the working folder is compared, and so are each command's exit status
and its standard output and error (as written, after masking the durations listed in
:data:`MASKS`). The only other differences ignored are :data:`MASKS`' timestamps: the
``created`` field of ``summary.json`` (an ISO time, written when the study ran) and the
same time in ``report.html`` (``created <time>.``). Two runs of one tree differ only
there (checked with ``--before`` and ``--after`` the same tree).

Exit status 0 when everything is identical, 1 otherwise (each difference listed).
"""

from __future__ import annotations

import argparse
import filecmp
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

#: (file name pattern, regular expression, replacement): the only bytes not compared.
MASKS: list[tuple[str, bytes, bytes]] = [
    # the time the study ran
    (r"summary\.json$", rb'"created": "[^"]*"', b'"created": "<time>"'),
    (
        r"report\.html$",
        rb"created \d{4}-\d\d-\d\dT[\d:]+(?:[+-]\d\d:\d\d|Z)?\.",
        b"created <time>.",
    ),
    # durations printed by the commands (progress and timings), never in files
    (r"^_log/", rb"\d+(?:\.\d+)?\s?(?:s|ms|min)\b", b"<duration>"),
    (r"^_log/", rb"\d+(?:\.\d+)?/s\b", b"<rate>"),
]


def commands(subjects: int) -> list[list[str]]:
    """The commands both trees run, in order (``fingerfit`` arguments)."""
    sim = ["--subjects", "1", "--fingers", "index", "--seed", "3"]
    return [
        ["demo", "--out", "demo", "--subjects", str(subjects), "--quiet"],
        ["simulate", "ascii", *sim, "--format", "liberty-ascii"],
        ["simulate", "binary", *sim, "--format", "liberty-binary"],
    ]


def scripted(work: Path) -> list[list[str]]:
    """The commands the simulator wrote to each ``commands.sh``: convert every Liberty
    file, build the session, fit it."""
    out = []
    for script in sorted(work.glob("*/commands.sh")):
        for line in script.read_text(encoding="utf-8").splitlines():
            words = shlex.split(line)
            if words and words[0] == "fingerfit":
                out.append(words[1:])
    return out


def joints(work: Path) -> list[list[str]]:
    """``fingerfit joint`` of the first converted grasp recording, every kind."""
    grasp = sorted(work.glob("*/*/csv/grasp.csv"))
    if not grasp:
        return []
    rel = str(grasp[0].relative_to(work))
    return [
        ["joint", rel, "--parent", "index.proximal", "--child", "index.middle", "--kind", kind,
         "-o", f"joint-{kind}.json"]
        for kind in ("auto", "hinge", "two_axis", "ball")
    ]  # fmt: skip


def exports(work: Path) -> list[list[str]]:
    """``fingerfit export`` of every model written (the demo's and the fitted sessions'),
    URDF and MJCF, each variant."""
    models = sorted(work.glob("demo/study/models/*.json")) + sorted(work.glob("*/**/model.json"))
    out = []
    for m in models:
        rel = m.relative_to(work)
        stem = "-".join(rel.with_suffix("").parts)
        for v in ("user_axis", "orthogonal"):
            out.append(["export", str(rel), "--urdf", f"export/{stem}-{v}.urdf",
                        "--mjcf", f"export/{stem}-{v}.xml", "--variant", v])  # fmt: skip
    return out


def run(src: Path, work: Path, subjects: int) -> None:
    """Every command with the tree ``src``, in ``work``; logs in ``work/_log``."""
    env = {**os.environ, "PYTHONPATH": str(src.resolve()), "COLUMNS": "100"}
    log = work / "_log"
    log.mkdir(parents=True)
    k = 0

    def fingerfit(args: list[str]) -> None:
        nonlocal k
        proc = subprocess.run(
            [sys.executable, "-c", "import sys; from fingerfit.cli import main; sys.exit(main())",
             *args],
            cwd=work, env=env, capture_output=True, check=False,
        )  # fmt: skip
        (log / f"{k:02d}.txt").write_bytes(
            b"$ fingerfit " + " ".join(args).encode() + b"\n"
            + f"exit {proc.returncode}\n".encode()
            + b"--- stdout\n" + proc.stdout + b"--- stderr\n" + proc.stderr
        )  # fmt: skip
        k += 1

    for args in commands(subjects):
        fingerfit(args)
    for args in scripted(work):
        fingerfit(args)
    for args in joints(work):
        fingerfit(args)
    (work / "export").mkdir()
    for args in exports(work):
        fingerfit(args)


def masked(rel: str, data: bytes) -> bytes:
    for pattern, rx, repl in MASKS:
        if re.search(pattern, rel):
            data = re.sub(rx, repl, data)
    return data


def compare(a: Path, b: Path) -> list[str]:
    """Differences between two output folders (an empty list: identical)."""
    files_a = {p.relative_to(a).as_posix() for p in a.rglob("*") if p.is_file()}
    files_b = {p.relative_to(b).as_posix() for p in b.rglob("*") if p.is_file()}
    out = [f"only before: {f}" for f in sorted(files_a - files_b)]
    out += [f"only after: {f}" for f in sorted(files_b - files_a)]
    for rel in sorted(files_a & files_b):
        if filecmp.cmp(a / rel, b / rel, shallow=False):
            continue
        da, db = (masked(rel, (root / rel).read_bytes()) for root in (a, b))
        if da != db:
            at = next((i for i, (x, y) in enumerate(zip(da, db, strict=False)) if x != y), None)
            at = min(len(da), len(db)) if at is None else at
            out.append(
                f"differs: {rel} (byte {at}: {da[max(0, at - 40) : at + 40]!r} vs "
                f"{db[max(0, at - 40) : at + 40]!r})"
            )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", type=Path, required=True, help="source tree (its src folder)")
    ap.add_argument("--after", type=Path, required=True, help="source tree (its src folder)")
    ap.add_argument("--subjects", type=int, default=2, help="demo subjects (default 2)")
    ap.add_argument("--keep", type=Path, help="keep both outputs here (before/, after/)")
    args = ap.parse_args()
    for tree in (args.before, args.after):
        if not (tree / "fingerfit" / "__init__.py").is_file():
            ap.error(f"{tree} holds no fingerfit package")
    root = Path(tempfile.mkdtemp(prefix="same-outputs-"))
    try:
        for tag, tree in (("before", args.before), ("after", args.after)):
            run(tree, root / "run", args.subjects)
            (root / "run").rename(root / tag)
        diffs = compare(root / "before", root / "after")
        n = sum(1 for _ in (root / "before").rglob("*"))
        if args.keep:
            shutil.copytree(root, args.keep, dirs_exist_ok=True)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    for d in diffs:
        print(d)
    print(f"{'identical' if not diffs else f'{len(diffs)} differences'}: {n} paths compared")
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main())
