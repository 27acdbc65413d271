"""The landmark protocol: the stylus placed on each landmark in turn, each take found
(the stylus held still, or a key press) and averaged (``docs/lab.md``, *Landmarks*).

:class:`LandmarkTaker` is fed the source's blocks as they arrive. It keeps the stylus tip
of every frame in the tracker frame and in the frame of the segment the current landmark
rides on, and looks for the next take (:func:`fingerfit.stylus.landmarks.next_take`,
vectorised over the frames since the last take): the tip still in the segment's frame,
after it has been lifted from the last take (tracker frame: whatever landmark that was).
What it says (prompts, each take, a shaky window refused) comes back as lines for the
terminal. Where each landmark sits at the reference posture is :meth:`LandmarkTaker.result`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..session import Recording
from ..stylus.file import StylusCalibration
from ..stylus.landmarks import (
    MAX_SPREAD_MM,
    TAKES,
    WINDOW_S,
    Landmark,
    landmark_segment,
    next_take,
    tip_points,
    window_spread,
)
from ..transforms import FloatArray

#: What each kind of landmark is, for the prompt.
_WHAT = {
    "mp": "the dorsal midpoint of the MP joint",
    "pip": "the dorsal midpoint of the PIP joint",
    "dip": "the dorsal midpoint of the DIP joint",
    "cmc": "the dorsal midpoint of the CMC joint",
    "mcp": "the dorsal midpoint of the MCP joint",
    "ip": "the dorsal midpoint of the IP joint",
    "tip": "the middle of the nail's distal edge",
    "pad": "the centre of the pulp's contact area",
}


def describe(name: str) -> str:
    """A landmark's name with what to touch, for the prompt."""
    if name.startswith("target."):
        return f"{name} (the target's point)"
    digit, what = name.split(".", 1)
    return f"{name} ({_WHAT[what]} of the {digit})"


@dataclass
class LandmarkTaker:
    """Takes landmarks from a stream of blocks (module docstring).

    Parameters
    ----------
    names : list of str
        The landmarks, in order (``landmarks.csv``'s names).
    stylus : StylusCalibration
    rate_hz : float
    takes : int
        Placements averaged per landmark.
    still : bool
        A still stylus makes a take (else only :meth:`press`).
    """

    names: list[str]
    stylus: StylusCalibration
    rate_hz: float
    takes: int = TAKES
    still: bool = True
    done: list[Landmark] = field(default_factory=list)
    rejected: int = 0
    _blocks: list[Recording] = field(default_factory=list)
    _world: list[FloatArray] = field(default_factory=list)
    _local: list[FloatArray] = field(default_factory=list)
    _start: int = 0
    _takes: list[FloatArray] = field(default_factory=list)
    _spreads: list[float] = field(default_factory=list)
    _lifted_from: FloatArray | None = None

    @property
    def current(self) -> str | None:
        """The landmark being taken (None: all done)."""
        return self.names[len(self.done)] if len(self.done) < len(self.names) else None

    @property
    def finished(self) -> bool:
        return self.current is None

    def prompt(self) -> str:
        """What to do now."""
        name = self.current
        if name is None:
            return "every landmark taken"
        return f"place the stylus on {describe(name)}: take {len(self._takes) + 1} of {self.takes}"

    def add(self, block: Recording) -> list[str]:
        """Take what the block completes; the lines to show."""
        lines: list[str] = []
        if self.finished or block.n_frames == 0:
            return lines
        self._blocks.append(block)
        self._world.append(self._tip(block, None))
        self._local.append(self._tip(block, landmark_segment(self.current or "")))
        while self.still and not self.finished:
            world, local = _joined(self._world), _joined(self._local)
            self._world, self._local = [world], [local]
            found = next_take(
                local,
                self.rate_hz,
                start=self._start,
                lifted_from=self._lifted_from,
                lift_points=world,
            )
            if found is None:
                break
            first, end = found
            lines += self._take(local[first:end], world[first:end])
            self._start = end
        return lines

    def press(self) -> list[str]:
        """A key press (or the stylus button): take the last :data:`WINDOW_S` seconds,
        refused when shaky."""
        if self.finished:
            return []
        world, local = _joined(self._world), _joined(self._local)
        self._world, self._local = [world], [local]
        k = max(3, round(WINDOW_S * self.rate_hz))
        if local.shape[0] - self._start < k:
            return ["too soon after the last take: hold the stylus still and press again"]
        spread = window_spread(local[-k:])
        if not (spread <= MAX_SPREAD_MM):
            self.rejected += 1
            what = "no stylus" if np.isnan(spread) else f"{spread:.2f} mm"
            return [
                f"{self.current}: shaky ({what} spread, over {MAX_SPREAD_MM} mm): hold the "
                "stylus still and press again"
            ]
        lines = self._take(local[-k:], world[-k:])
        self._start = local.shape[0]
        return lines

    def _tip(self, block: Recording, segment: str | None) -> FloatArray:
        """The stylus tip ``(n, 3)`` mm in ``segment``'s sensor frame (None: tracker)."""
        n = block.n_frames
        missing = (np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan))
        s = block.poses.get(self.stylus.sensor)
        if s is None:
            return missing[0]
        frame = None
        if segment is not None:
            p = block.poses.get(segment)
            frame = missing if p is None else (p.position, p.rotation)
        return tip_points(s.position, s.rotation, self.stylus.tip_offset_mm, frame)

    def _take(self, local: FloatArray, world: FloatArray) -> list[str]:
        name = self.current
        assert name is not None
        segment = landmark_segment(name)
        point = np.nanmean(local, axis=0)
        spread = window_spread(local)
        self._takes.append(point)
        self._spreads.append(spread)
        self._lifted_from = np.nanmean(world, axis=0)
        lines = [
            f"{name} take {len(self._takes)}/{self.takes}: "
            f"({', '.join(f'{v:.1f}' for v in point)}) mm in the {segment or 'tracker'} "
            f"frame, spread {spread:.2f} mm"
        ]
        if len(self._takes) < self.takes:
            return [*lines, "lift the stylus and place it again"]
        lm = Landmark(name, segment, np.array(self._takes), np.array(self._spreads))
        self.done.append(lm)
        self._takes, self._spreads = [], []
        sd = "" if np.isnan(lm.sd_mm) else f", uncertainty {lm.sd_mm:.2f} mm"
        lines.append(f"{name}: {self.takes} takes {lm.spread_mm:.2f} mm apart{sd}")
        if lm.spread_mm > 2.0:
            lines.append(
                f"{name}: the takes are {lm.spread_mm:.1f} mm apart -- was the stylus on the "
                "same point each time? (--only to take it again)"
            )
        if not self.finished:
            # The next landmark rides on another segment: its frames from the blocks kept.
            seg = landmark_segment(self.current or "")
            self._local = [_joined([self._tip(b, seg) for b in self._blocks])]
            lines.append(self.prompt())
        return lines

    def result(
        self, reference: dict[str, tuple[FloatArray, FloatArray]]
    ) -> tuple[dict[str, FloatArray], dict[str, float]]:
        """The landmarks taken, at the reference posture (tracker frame, mm) and their
        uncertainties (mm), given each sensor's mean reference pose (position ``(3,)``
        mm, rotation ``(3, 3)``)."""
        return (
            {lm.name: lm.at_reference(reference) for lm in self.done},
            {lm.name: lm.sd_mm for lm in self.done},
        )


def _joined(parts: list[FloatArray]) -> FloatArray:
    if not parts:
        return np.zeros((0, 3))
    return parts[0] if len(parts) == 1 else np.concatenate(parts)
