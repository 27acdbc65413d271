"""A session as a tracking device would have stored it: poses at the device's precision.

Devices (``docs/methods.md``, "Numerical stability"):

* ``liberty-ascii`` -- Polhemus Liberty ASCII output: positions printed with
  ``ASCII_DECIMALS["position"]`` (3) decimals in inches (the device default units),
  quaternions w,x,y,z with 4 decimals (about 0.01 deg), renormalised as the reader does;
* ``liberty-binary`` -- Liberty binary output: float32 inches and float32 quaternions;
* ``c3d`` -- C3D: float32 positions (mm) and float32 rotation matrices.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..io.liberty import ASCII_DECIMALS
from ..session import UNITS_TO_MM, PoseSeries, Recording, Session
from ..transforms import FloatArray, matrix_from_quat_wxyz, quat_wxyz_from_matrix
from .trackerfiles import TRACKER_FORMATS

DEVICES = TRACKER_FORMATS


def _f32(x: FloatArray) -> FloatArray:
    return x.astype(np.float32).astype(float)


def round_positions(position: FloatArray, device: str) -> FloatArray:
    """Positions ``(..., 3)`` (mm, tracker frame) at ``device`` precision, in mm."""
    inch = UNITS_TO_MM["in"]
    if device == "liberty-ascii":
        return np.round(position / inch, ASCII_DECIMALS["position"]) * inch
    if device == "liberty-binary":
        return _f32(position / inch) * inch
    if device == "c3d":
        return _f32(position)
    raise ValueError(f"unknown device '{device}' (have: {', '.join(DEVICES)})")


def round_rotations(rotation: FloatArray, device: str) -> FloatArray:
    """Rotations ``(n, 3, 3)`` (sensor -> tracker) at ``device`` precision.

    Liberty stores quaternions (w, x, y, z): ASCII rounds them to 4 decimals, binary to
    float32; they are renormalised as :func:`fingerfit.io.liberty.read_liberty_ascii`
    does. C3D stores float32 matrices.
    """
    if device == "c3d":
        return _f32(rotation)
    q = quat_wxyz_from_matrix(rotation)
    if device == "liberty-ascii":
        q = np.round(q, ASCII_DECIMALS["quaternion"])
    elif device == "liberty-binary":
        q = _f32(q)
    else:
        raise ValueError(f"unknown device '{device}' (have: {', '.join(DEVICES)})")
    return matrix_from_quat_wxyz(q)


def _recording(rec: Recording, device: str) -> Recording:
    poses = {}
    for name, ps in rec.poses.items():
        ok = ps.valid
        pos, rot = ps.position.copy(), ps.rotation.copy()
        pos[ok] = round_positions(ps.position[ok], device)
        rot[ok] = round_rotations(ps.rotation[ok], device)
        poses[name] = PoseSeries(pos, rot)
    return Recording(rec.name, rec.time, poses, list(rec.notes))


def device_rounded(session: Session, device: str) -> Session:
    """A copy of ``session`` with every pose and landmark at ``device`` precision.

    Parameters
    ----------
    session : Session
        Positions in mm, rotations sensor -> tracker (as loaded).
    device : {"liberty-ascii", "liberty-binary", "c3d"}

    Returns
    -------
    Session
    """
    return replace(
        session,
        reference=_recording(session.reference, device),
        grasp=[_recording(r, device) for r in session.grasp],
        targets=[_recording(r, device) for r in session.targets],
        test=[_recording(r, device) for r in session.test],
        landmarks={k: round_positions(v, device) for k, v in session.landmarks.items()},
    )


__all__ = ["DEVICES", "device_rounded", "round_positions", "round_rotations"]
