"""Guided capture: a protocol recording taken into a session folder, with the evidence
the fit needs shown per joint while it is recorded (``fingerfit capture``).

The evidence is the fit's own: grasp cycles by :func:`fingerfit.estimate.cycles.extract_cycles`
on each joint's child-in-parent rotation (from the reference posture), and a joint is
*enough* when it has at least ``FitOptions.min_cycles`` cycles and their median range of
motion is at least ``FitOptions.min_rom_deg`` -- the thresholds and the rule below which
``fingerfit fit`` refuses a joint (:class:`fingerfit.estimate.FitOptions`;
``docs/capture.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .estimate.cycles import extract_cycles
from .estimate.fit import FitOptions
from .session import PoseSeries, Recording, joint_sensors
from .transforms import FloatArray, relative_pose

#: The protocols ``fingerfit capture`` guides (the recording each one takes).
PROTOCOLS = ("grasp",)


def thresholds(options: FitOptions | None = None) -> tuple[int, float]:
    """``(cycles, range of motion deg)`` a joint needs: the fit's own (``FitOptions``).

    The fit refuses a joint with fewer than ``max(min_cycles, 2)`` cycles or a median range
    of motion under ``min_rom_deg`` (``fingerfit.estimate.fit``).
    """
    options = options or FitOptions()
    return max(options.min_cycles, 2), float(options.min_rom_deg)


@dataclass(frozen=True)
class JointEvidence:
    """What the fit needs of one joint, so far.

    Attributes
    ----------
    digit, joint : str
    cycles : int
        Grasp cycles found.
    rom_deg : float
        Median range of motion of those cycles (deg; NaN without a cycle).
    enough : bool
        ``cycles`` and ``rom_deg`` meet :func:`thresholds`.
    """

    digit: str
    joint: str
    cycles: int
    rom_deg: float
    enough: bool


def reference_rotations(
    reference: Recording, digits: list[str]
) -> dict[tuple[str, str], FloatArray]:
    """Each joint's child-in-parent rotation at the reference posture, from the mean sensor
    poses of the reference recording (as the fit computes them)."""
    out = {}
    for d in digits:
        for j, (parent, child) in joint_sensors(d).items():
            _, pr = reference.pose(parent).mean()
            _, cr = reference.pose(child).mean()
            out[(d, j)] = pr.T @ cr
    return out


def evidence(
    recording: Recording,
    references: dict[tuple[str, str], FloatArray],
    rate_hz: float,
    options: FitOptions | None = None,
) -> list[JointEvidence]:
    """The evidence of every joint in ``recording`` (one grasp recording), as the fit sees it.

    Parameters
    ----------
    recording : Recording
        What has been recorded so far (mm, tracker frame).
    references : dict
        :func:`reference_rotations`.
    rate_hz : float
        The session's sampling rate.
    """
    need_cycles, need_rom = thresholds(options)
    out = []
    for (d, j), ref in references.items():
        parent, child = joint_sensors(d)[j]
        if parent not in recording.poses or child not in recording.poses:
            out.append(JointEvidence(d, j, 0, float("nan"), False))
            continue
        p, c = recording.poses[parent], recording.poses[child]
        r, _ = relative_pose(p.rotation, p.position, c.rotation, c.position)
        cyc = extract_cycles(r, ref, rate_hz)
        rom = float(np.degrees(np.median(cyc.rom))) if cyc.count else float("nan")
        ok = cyc.count >= need_cycles and rom >= need_rom
        out.append(JointEvidence(d, j, cyc.count, rom, bool(ok)))
    return out


class Accumulator:
    """Blocks of frames joined into one recording as they arrive.

    Parameters
    ----------
    name : str
        File name of the recording (``grasp.csv``).
    sensors : list of str
        Sensors kept (others a source sends are dropped); every one is in the result,
        NaN where a block lacks it.
    """

    def __init__(self, name: str, sensors: list[str]) -> None:
        self.name = name
        self.sensors = list(sensors)
        self._time: list[FloatArray] = []
        self._pos: dict[str, list[FloatArray]] = {s: [] for s in self.sensors}
        self._rot: dict[str, list[FloatArray]] = {s: [] for s in self.sensors}
        self.n_frames = 0

    def add(self, block: Recording) -> None:
        n = block.n_frames
        if n == 0:
            return
        self._time.append(np.asarray(block.time, dtype=float))
        for s in self.sensors:
            if s in block.poses:
                self._pos[s].append(block.poses[s].position)
                self._rot[s].append(block.poses[s].rotation)
            else:
                self._pos[s].append(np.full((n, 3), np.nan))
                self._rot[s].append(np.full((n, 3, 3), np.nan))
        self.n_frames += n

    def recording(self) -> Recording:
        """Everything so far as one :class:`~fingerfit.session.Recording`."""
        if not self._time:
            empty = {s: PoseSeries(np.zeros((0, 3)), np.zeros((0, 3, 3))) for s in self.sensors}
            return Recording(self.name, np.zeros(0), empty)
        poses = {
            s: PoseSeries(np.concatenate(self._pos[s]), np.concatenate(self._rot[s]))
            for s in self.sensors
        }
        return Recording(self.name, np.concatenate(self._time), poses)
