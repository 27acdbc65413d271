"""Start-up: ``fingerfit --help`` and ``--version`` import no heavy module.

Run in a subprocess so this process's own imports do not count. The wall time is
measured by ``bench/speed.py`` (docs/performance.md), not asserted here.
"""

from __future__ import annotations

import itertools
import json
import subprocess
import sys

import pytest

HEAVY = (
    "numpy",
    "scipy",
    "pandas",
    "matplotlib",
    "statsmodels",
    "ezc3d",
    "mujoco",
    "pinocchio",
    "yourdfpy",
    "dask",
    "distributed",
)

_PROBE = """
import json, sys
from fingerfit.cli import main
sys.argv = ["fingerfit", *{args!r}]
try:
    main()
except SystemExit as exc:
    code = exc.code
else:
    code = 0
heavy = [m for m in {heavy!r} if m in sys.modules]
print("\\n" + json.dumps({{"code": code, "heavy": heavy}}))
"""


@pytest.mark.parametrize("args", [["--help"], ["--version"], [], ["study", "--help"]])
def test_no_heavy_module_at_help_or_version(args) -> None:
    res = subprocess.run(
        [sys.executable, "-c", _PROBE.format(args=args, heavy=HEAVY)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    found = json.loads(res.stdout.strip().splitlines()[-1])
    assert found["heavy"] == [], found
    assert found["code"] in (0, 2, None), res.stderr  # no arguments: help, exit 2 (click)
    if args in (["--help"], []):
        for command in ("convert", "session", "fit", "angles", "study", "demo", "simulate"):
            assert command in res.stdout + res.stderr


def test_the_probe_sees_a_command_import_numpy(tmp_path) -> None:
    """The check can fail: a command that runs does import NumPy, and the probe sees it."""
    args = ["simulate", str(tmp_path / "sim"), "--subjects", "1", "--exact"]
    res = subprocess.run(
        [sys.executable, "-c", _PROBE.format(args=args, heavy=HEAVY)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    found = json.loads(res.stdout.strip().splitlines()[-1])
    assert found["code"] in (0, None), res.stderr
    assert "numpy" in found["heavy"] and (tmp_path / "sim" / "S01" / "session.toml").is_file()


def test_angles_of_a_complete_recording_imports_no_scipy(tmp_path) -> None:
    """``angles`` on a recording with every sensor reads, computes and writes with NumPy,
    pandas and Arrow alone: SciPy (the fit's signal and stats, the C3D reader, rotations
    by scipy, the tracking smoother) costs 0.5-1 s of imports it does not need
    (docs/performance.md, *angles from Parquet and CSV*)."""
    import warnings

    from fingerfit.estimate import fit_session
    from fingerfit.io import write_pose_csv
    from fingerfit.model import save_model

    from .conftest import subject

    sim = subject("realistic", 2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = save_model(fit_session(sim.session), tmp_path / "model.json")
    out = {}
    for ext in ("csv", "parquet"):
        rec = write_pose_csv(tmp_path / f"test.{ext}", sim.session.test[0])
        args = ["angles", str(model), str(rec), "-o", str(tmp_path / f"angles.{ext}"), "-q"]
        res = subprocess.run(
            [sys.executable, "-c", _PROBE.format(args=args, heavy=HEAVY)],
            capture_output=True,
            text=True,
            timeout=120,
        )
        out[ext] = json.loads(res.stdout.strip().splitlines()[-1])
        assert out[ext]["code"] in (0, None), res.stderr
        assert (tmp_path / f"angles.{ext}").is_file()
    for ext, found in out.items():
        assert "numpy" in found["heavy"] and "pandas" in found["heavy"], (ext, found)
        assert not {"scipy", "ezc3d", "matplotlib", "statsmodels"} & set(found["heavy"]), (
            ext,
            found,
        )


def test_signature_names_mirror_the_real_ones() -> None:
    from fingerfit.cli import _names
    from fingerfit.estimate import FitOptions
    from fingerfit.estimate.fit import METHODS
    from fingerfit.export.geometry import DEFAULT_MARGIN_DEG
    from fingerfit.model import VARIANTS

    assert _names.METHODS == tuple(METHODS)
    assert FitOptions.method == _names.DEFAULT_METHOD
    assert _names.VARIANTS == VARIANTS
    assert _names.DEFAULT_MARGIN_DEG == DEFAULT_MARGIN_DEG
    from fingerfit.live import stream

    assert _names.DEFAULT_MAX_AGE_MS == stream.DEFAULT_MAX_AGE_MS
    assert _names.DEFAULT_SILENCE_MS == stream.DEFAULT_SILENCE_MS
    from fingerfit.live import sources

    assert _names.DEFAULT_RECONNECT_S == sources.DEFAULT_RECONNECT_S


@pytest.mark.parametrize("columns", [80, 120])
def test_help_wraps_each_description_only_where_the_line_is_full(columns) -> None:
    """``fingerfit --help``: each command's description is its docstring's first
    paragraph, broken only where the next word would not fit."""
    import os
    import re

    from fingerfit.cli import app

    env = {**os.environ, "COLUMNS": str(columns), "TERMINAL_WIDTH": str(columns)}
    res = subprocess.run(
        [sys.executable, "-c", "from fingerfit.cli import main; main()", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
    )
    rows = [ln for ln in res.stdout.splitlines() if ln.startswith("│")]
    start = rows.index(next(r for r in rows if re.match(r"│ capture ", r)))
    cell = re.match(r"│ capture +", rows[start]).end() - 1  # where descriptions start
    described: dict[str, list[str]] = {}
    name = None
    for r in rows[start:]:
        head, text = r[1:cell].strip(), r[cell:-1].rstrip()
        name = head or name
        described.setdefault(name, []).append(text.strip())
    docs = {i.name or i.callback.__name__: i.callback.__doc__ for i in app.registered_commands}
    room = max(len(line) for lines in described.values() for line in lines)  # <= the column's
    for name, lines in described.items():
        want = " ".join(docs[name].strip().split("\n\n")[0].split())
        assert " ".join(lines) == want, (name, lines)
        for line, after in itertools.pairwise(lines):
            assert len(line) + 1 + len(after.split()[0]) > room, (name, line, after)
