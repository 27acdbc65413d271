"""Run a benchmark script on another revision's code: the before of a before/after."""

from __future__ import annotations

import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run_at_revision(rev: str, script: str, args: list[str]) -> dict:
    """``script`` (this checkout's benchmark) run with ``args`` on revision ``rev``'s ``src``
    (``git archive``) in a subprocess; the JSON it wrote to the ``--json`` path it is given.

    The script must accept ``--json PATH``; its standard output is dropped.
    """
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", rev, "src"], check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        out = Path(tmp) / "before.json"
        env = dict(os.environ, PYTHONPATH=str(Path(tmp) / "src"))
        cmd = [sys.executable, script, *args, "--json", str(out)]
        subprocess.run(cmd, check=True, env=env, stdout=subprocess.DEVNULL)
        return json.loads(out.read_text())


def run_meta(script: str, seconds: float, **extra: object) -> dict:
    """A benchmark run's ``meta``: date, the command as run (``python bench/<script> ...``),
    its seconds, Python's and NumPy's versions, and ``extra``."""
    import numpy as np

    return {
        "date": datetime.date.today().isoformat(),
        "command": (f"python bench/{script} " + " ".join(sys.argv[1:])).strip(),
        **extra,
        "seconds": seconds,
        "python": platform.python_version(),
        "numpy": np.__version__,
    }
