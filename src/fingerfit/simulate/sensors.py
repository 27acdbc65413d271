"""Simulated 6-DOF sensors: mounting, soft-tissue artefact and tracker errors.

A sensor is a rigid pose fixed to its segment at the reference posture,
displaced by a soft-tissue artefact that grows linearly with the angles of the
joints next to it, then seen through the tracker: a smooth position- and
orientation-distortion field (metal nearby) plus white noise. Magnitudes at
``noise = 1`` follow Polhemus Liberty figures (``docs/simulator.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..transforms import FloatArray

# Liberty-like error magnitudes at noise = 1.
POSITION_NOISE_MM = 0.12
ORIENTATION_NOISE_DEG = 0.05
DISTORTION_MM = 0.5
DISTORTION_DEG = 0.15
# Soft-tissue artefact per radian of the adjacent joints' flexion, at sta = 1.
STA_MM_PER_RAD = 0.8
STA_DEG_PER_RAD = 1.5


@dataclass(frozen=True)
class SensorMount:
    """Where a sensor sits at the reference posture and how its skin slides.

    Attributes
    ----------
    name : str
        Sensor name (``hand`` or ``<finger>.<segment>``).
    position : ndarray, shape (3,)
        Sensor origin, tracker coordinates at the reference posture (mm).
    rotation : ndarray, shape (3, 3)
        Sensor -> tracker rotation at the reference posture.
    sta_translation : ndarray, shape (2, 3)
        Displacement per radian of the proximal and distal adjacent joint (mm/rad).
    sta_rotation : ndarray, shape (2, 3)
        Rotation vector per radian of the same joints (rad/rad).
    """

    name: str
    position: FloatArray
    rotation: FloatArray
    sta_translation: FloatArray
    sta_rotation: FloatArray


def mount(
    rng: np.random.Generator,
    name: str,
    position: FloatArray,
    frame: FloatArray,
    *,
    offset_sd: FloatArray,
    sta: float,
) -> SensorMount:
    """Place a sensor near ``position`` with a random orientation and skin-slide gains.

    Parameters
    ----------
    position : ndarray, shape (3,)
        Nominal sensor site (mm).
    frame : ndarray, shape (3, 3)
        Segment anatomical frame (columns x distal, y, z dorsal).
    offset_sd : ndarray, shape (3,)
        SD of the individual placement offset along x, y, z of ``frame`` (mm).
    sta : float
        Soft-tissue artefact scale (0 = none).
    """
    pos = position + frame @ rng.normal(0, offset_sd)
    rot = Rotation.random(random_state=rng).as_matrix()
    # Skin slides mostly along the bone, and tilts the sensor about the flexion axis.
    tr = sta * STA_MM_PER_RAD * rng.normal(0, 1, (2, 3)) * np.array([1.0, 0.3, 0.4])
    rv = sta * np.radians(STA_DEG_PER_RAD) * rng.normal(0, 1, (2, 3)) * np.array([0.4, 1.0, 0.4])
    return SensorMount(name, pos, rot, tr @ frame.T, rv @ frame.T)


def sensor_poses(
    m: SensorMount,
    motion: tuple[FloatArray, FloatArray],
    adjacent: tuple[FloatArray, FloatArray],
) -> tuple[FloatArray, FloatArray]:
    """True sensor poses, soft-tissue artefact included.

    Parameters
    ----------
    m : SensorMount
    motion : (R (n, 3, 3), t (n, 3))
        Segment motion relative to the reference posture.
    adjacent : (ndarray (n,), ndarray (n,))
        Proximal and distal adjacent joint angles (rad) driving the artefact.

    Returns
    -------
    position : ndarray, shape (n, 3)
    rotation : ndarray, shape (n, 3, 3)
    """
    r_seg, t_seg = motion
    ang = np.column_stack(adjacent)
    d_pos = ang @ m.sta_translation
    d_rot = Rotation.from_rotvec(ang @ m.sta_rotation).as_matrix()
    pos_ref = m.position + d_pos
    rot_ref = d_rot @ m.rotation
    return np.einsum("nij,nj->ni", r_seg, pos_ref) + t_seg, r_seg @ rot_ref


@dataclass(frozen=True)
class TrackerErrors:
    """A tracker's errors for one session: a fixed distortion field plus white noise."""

    noise: float
    distortion: bool
    wave: FloatArray  # (6, 3) wave vectors (rad/mm) of the distortion field
    phase: FloatArray  # (6,)

    @classmethod
    def sample(cls, rng: np.random.Generator, noise: float, distortion: bool) -> TrackerErrors:
        """Draw a distortion field with wavelengths of 250-450 mm."""
        lam = rng.uniform(250.0, 450.0, 6)
        dirs = Rotation.random(6, random_state=rng).apply(np.array([1.0, 0.0, 0.0]))
        return cls(noise, distortion, 2 * np.pi * dirs / lam[:, None], rng.uniform(0, 2 * np.pi, 6))

    def apply(
        self, rng: np.random.Generator, position: FloatArray, rotation: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Measured poses ``(n, 3)``, ``(n, 3, 3)`` from true ones."""
        pos, rot = position.copy(), rotation.copy()
        if self.distortion and self.noise > 0:
            field = np.sin(position @ self.wave.T + self.phase)  # (n, 6)
            pos = pos + self.noise * DISTORTION_MM * field[:, :3]
            rv = self.noise * np.radians(DISTORTION_DEG) * field[:, 3:]
            rot = Rotation.from_rotvec(rv).as_matrix() @ rot
        if self.noise > 0:
            n = position.shape[0]
            pos = pos + rng.normal(0, self.noise * POSITION_NOISE_MM, (n, 3))
            rv = rng.normal(0, self.noise * np.radians(ORIENTATION_NOISE_DEG), (n, 3))
            rot = Rotation.from_rotvec(rv).as_matrix() @ rot
        return pos, rot
