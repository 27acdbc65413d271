"""Every command block of README.md and docs/*.md runs, as written.

Fenced blocks marked ``sh`` are examples: each ``fingerfit`` command in them is run
in a sandbox folder that holds the files the documents name (a simulated subject
written as a Polhemus Liberty file and as CSVs, fitted sessions, ``../shared``), and
must exit 0; the ``python`` blocks of a document then run in the same folder. Blocks
marked ``text`` are synopses or printed output. An unmarked block holding a
``fingerfit`` command fails the suite, so no example can hide from this test.

Commands that are not fingerfit's are not run here, each for a stated reason
(:data:`NOT_RUN`).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.simulate.trackerfiles import write_tracker_subject

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```([\w-]*)\n(.*?)^```", re.M | re.S)

#: Leading words of commands the documents show but this test does not run, and why.
NOT_RUN = {
    "make": "make demo / make test build the environment this test runs in",
    "pip": "installs packages; the test environment has every extra",
    ".venv/bin/python": "benchmarks (make bench, make bench-accuracy), not tests",
}


def _blocks() -> list[tuple[Path, int, str, str]]:
    out = []
    for doc in DOCS:
        text = doc.read_text(encoding="utf-8")
        for m in FENCE.finditer(text):
            out.append((doc, text[: m.start()].count("\n") + 1, m.group(1), m.group(2)))
    return out


def _commands(block: str) -> list[list[str]]:
    joined = re.sub(r"\\\n", " ", block)
    return [shlex.split(line, comments=True) for line in joined.splitlines() if line.strip()]


def test_every_block_with_a_command_is_marked() -> None:
    for doc, line, lang, body in _blocks():
        if lang in ("", "console", "bash", "shell"):
            has_cmd = any(ln.lstrip().startswith("fingerfit ") for ln in body.splitlines())
            assert not has_cmd, (
                f"{doc.relative_to(ROOT)}:{line}: mark the block ```sh (an example, run by "
                "this test) or ```text (a synopsis or output)"
            )


def _sandbox_template(root: Path) -> Path:
    """The files the documents' examples name, built once."""
    t = root / "template"
    t.mkdir()
    index = SimConfig(fingers=("index",))
    p07 = simulate_subject(index, 7, "P07")
    liberty = write_tracker_subject(p07, root / "liberty", "liberty-ascii")
    shutil.copyfile(liberty.files["grasp.csv"], t / "liberty.txt")
    csv = write_subject(p07, root / "csv")
    for name in ("reference.csv", "landmarks.csv"):
        shutil.copyfile(csv / name, t / name)
    for seed, sid in ((8, "P08"), (9, "P09")):
        write_subject(simulate_subject(index, seed, sid), t / sid)
    s01 = write_subject(simulate_subject(index, 1, "S01"), t / "S01")
    res = CliRunner().invoke(app, ["fit", str(s01)])
    assert res.exit_code == 0, res.output
    if SHARED.is_dir():
        (root / "shared").symlink_to(SHARED)
    shutil.copytree(ROOT / "tests" / "data", t / "tests" / "data")  # real data kept in-repo
    return t


@pytest.fixture(scope="module")
def template(tmp_path_factory) -> Path:
    return _sandbox_template(tmp_path_factory.mktemp("docs"))


def _doc_ids() -> list[str]:
    """Documents with at least one ``sh`` or ``python`` block."""
    return sorted(
        {str(d.relative_to(ROOT)) for d, _, lang, _ in _blocks() if lang in ("sh", "python")}
    )


@pytest.mark.parametrize("doc", _doc_ids())
def test_examples_run_as_written(doc: str, template: Path, tmp_path: Path) -> None:
    blocks = [b for b in _blocks() if b[0] == ROOT / doc]
    shell = [b for b in blocks if b[2] == "sh"]
    python = [b for b in blocks if b[2] == "python"]
    work = tmp_path / "work"
    shutil.copytree(template, work, symlinks=True)
    if (template.parent / "shared").exists():
        (tmp_path / "shared").symlink_to(template.parent / "shared")
    runner = CliRunner()
    old = Path.cwd()
    os.chdir(work)
    try:
        for _, line, _, body in shell:
            for argv in _commands(body):
                where = f"{doc}:{line}: {shlex.join(argv)}"
                if argv[0] != "fingerfit":
                    assert argv[0] in NOT_RUN, f"{where}: not a fingerfit command"
                    continue
                if any("../shared" in a for a in argv) and not SHARED.is_dir():
                    continue  # the real-data examples need ../shared (absent here)
                res = runner.invoke(app, argv[1:])
                assert res.exit_code == 0, f"{where}\n{res.output}"
        for _, line, _, body in python:
            exec(compile(body, f"{doc}:{line}", "exec"), {})
    finally:
        os.chdir(old)
