"""Shared by the streaming tests: a fitted model and a short recording (built once)."""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.io import write_pose_csv
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import write_subject

from .conftest import subject


@functools.cache
def fitted() -> tuple[Path, Path]:
    """``(session_dir, model.json)`` of the cached realistic subject 2 (index finger)."""
    root = Path(tempfile.mkdtemp(prefix="fingerfit-live-"))
    d = write_subject(subject("realistic", 2), root / "S")
    model = root / "model.json"
    res = CliRunner().invoke(app, ["fit", str(d), "-o", str(model), "-q"])
    assert res.exit_code == 0, (res.output, repr(res.exception))
    return d, model


def short_recording(n: int = 240, holes: tuple[tuple[int, str], ...] = ()) -> Recording:
    """The first ``n`` frames of the subject's free-motion test recording (mm, tracker),
    with the sensor of each ``(frame, sensor)`` in ``holes`` missing (NaN)."""
    rec = subject("realistic", 2).session.test[0].slice(slice(0, n))
    poses = {k: PoseSeries(v.position.copy(), v.rotation.copy()) for k, v in rec.poses.items()}
    for i, s in holes:
        poses[s].position[i] = np.nan
        poses[s].rotation[i] = np.nan
    return Recording(rec.name, rec.time.copy(), poses)


def write_recording(path: Path, n: int = 240, holes: tuple[tuple[int, str], ...] = ()) -> Path:
    """:func:`short_recording` as a pose CSV (missing samples are absent rows)."""
    write_pose_csv(path, short_recording(n, holes))
    return path


def resolve_prefix(prefix: str, n: int, timeout: float = 20.0) -> dict:
    """The LSL streams named ``<prefix>-*`` by name, once at least ``n`` are seen (or the
    timeout). Find every stream before opening any: ``fingerfit stream --wait`` starts 1 s
    after its first consumer, and a second search can take longer on a loaded machine."""
    import pylsl

    found = pylsl.resolve_bypred(f"starts-with(name,'{prefix}-')", minimum=n, timeout=timeout)
    return {i.name(): i for i in found}
