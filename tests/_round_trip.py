"""The round trip of ``fingerfit simulate --format``: tracker files -> the printed
commands -> a model, compared with the model fitted from the CSV session of the same seed
(``tests/test_simulate_formats.py`` asserts it, ``bench/simulate_round_trip.py`` prints it).
"""

from __future__ import annotations

import shlex
from pathlib import Path

import numpy as np

from fingerfit.model import HandModel, load_model
from fingerfit.session import JOINTS, SEGMENTS

from .bad_inputs._cli import run

#: The seed of the simulated subjects.
SEED = 4
#: The tracker formats of ``fingerfit simulate --format``.
FORMATS = ("liberty-ascii", "liberty-binary", "c3d")
#: The fit methods compared (the default first).
METHODS = ("twoaxis", "robust")


def printed_commands(output: str) -> list[str]:
    """The ``fingerfit ...`` command lines of ``simulate``'s output, in order."""
    return [ln for ln in output.splitlines() if ln.startswith("fingerfit ")]


def run_printed(commands: list[str], cwd: Path) -> list[str]:
    """Run each printed command exactly (shell-split, in ``cwd``); return their outputs."""
    outputs = []
    for cmd in commands:
        args = shlex.split(cmd)
        assert args[0] == "fingerfit"
        res = run(*args[1:], cwd=cwd)
        assert res.exit_code == 0, f"{cmd}\n{res.output}"
        outputs.append(res.output)
    return outputs


def simulate_and_fit(
    work: Path, fmt: str, seed: int = SEED, subjects: int = 1
) -> dict[str, list[HandModel]]:
    """Simulate via the CLI in ``work/<fmt>``; fit every method; models per method, per subject.

    ``csv``: ``fingerfit fit OUT/Sxx``; tracker formats: the printed commands, then
    ``fingerfit fit`` again for the other methods.
    """
    res = run("simulate", fmt, "--subjects", subjects, "--seed", seed, "--format", fmt, cwd=work)
    assert res.exit_code == 0, res.output
    sessions = [Path(fmt) / f"S{i + 1:02d}" for i in range(subjects)]
    if fmt != "csv":
        commands = printed_commands(res.output)
        assert len(commands) == subjects * 6  # 4 convert, session, fit
        run_printed(commands, work)
        sessions = [s / "session" for s in sessions]
    models: dict[str, list[HandModel]] = {m: [] for m in METHODS}
    for s in sessions:
        for m in METHODS:
            path = s / f"model-{m}.json"
            if fmt != "csv" and m == "twoaxis":  # the printed `fingerfit fit` (default method)
                path = s / "model.json"
            else:
                r = run("fit", s, "--method", m, "-o", path, cwd=work)
                assert r.exit_code == 0, r.output
            models[m].append(load_model(work / path))
    return models


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(abs(float(a @ b)), -1.0, 1.0))))


def model_differences(a: HandModel, b: HandModel) -> dict[str, dict[str, float]]:
    """Per joint (and ``mp_abduction``, two-axis models): axis deg, centre mm, segment mm."""
    out: dict[str, dict[str, float]] = {}
    for f, fa in a.fingers.items():
        fb = b.fingers[f]
        for j, seg in zip(JOINTS, SEGMENTS, strict=True):
            ja, jb = fa.joints[j], fb.joints[j]
            out[j] = {
                "axis_deg": _angle_deg(ja.axis, jb.axis),
                "centre_mm": float(np.linalg.norm(ja.center - jb.center)),
                "length_mm": abs(fa.segment_lengths[seg] - fb.segment_lengths[seg]),
            }
        if fa.second_axes.get("mp") is not None and fb.second_axes.get("mp") is not None:
            out["mp_abduction"] = {
                "axis_deg": _angle_deg(
                    fa.second_axes.get("mp").axis, fb.second_axes.get("mp").axis
                ),
                "centre_mm": float(
                    np.linalg.norm(
                        fa.second_axes.get("mp").center - fb.second_axes.get("mp").center
                    )
                ),
                "length_mm": 0.0,
            }
    return out
