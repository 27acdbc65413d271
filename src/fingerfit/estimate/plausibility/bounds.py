"""What a hand can be: physiological length bounds (mm) and the thresholds of the
plausibility checks (``docs/plausibility.md``).
"""

from __future__ import annotations

from dataclasses import dataclass

from ...digits import DIGITS
from ...session import HAND_SENSOR, sensor_name

#: Segment (link) lengths as fractions of hand length (Buchholz, Armstrong & Goldstein
#: 1992, Ergonomics 35:261, table of link lengths). Fingers: metacarpal, proximal, middle,
#: distal; thumb: metacarpal, proximal, distal.
SEGMENT_FRACTION: dict[str, dict[str, float]] = {
    "thumb": {"metacarpal": 0.251, "proximal": 0.196, "distal": 0.158},
    "index": {"metacarpal": 0.463, "proximal": 0.245, "middle": 0.143, "distal": 0.097},
    "middle": {"metacarpal": 0.446, "proximal": 0.266, "middle": 0.170, "distal": 0.108},
    "ring": {"metacarpal": 0.421, "proximal": 0.244, "middle": 0.165, "distal": 0.107},
    "little": {"metacarpal": 0.414, "proximal": 0.204, "middle": 0.117, "distal": 0.094},
}
#: Hand length (wrist crease to the middle fingertip, mm) spanned by the bounds: from a
#: preschool child's hand to beyond the largest adult hands (``docs/plausibility.md``).
HAND_LENGTH_MM = (90.0, 240.0)
#: Margins on top of the hand-length range: individual proportions, landmark placement and
#: fit error (lower bound x 0.6, upper bound x 1.5).
MARGIN = (0.6, 1.5)
#: Dorsal joint landmark (skin) to the fitted joint centre (inside the finger), at most
#: this (mm). There is no lower bound: the fitted axis passes up to ~5 mm from the true one
#: (95th percentile 3.45 mm, 400 DIPs of a simulated cohort), as far as a small DIP is deep,
#: so a fitted centre may lie at the skin on correct data (``docs/plausibility.md``).
LANDMARK_TO_CENTRE_MAX_MM = 30.0
#: A segment's sensor sits on the skin of its segment: extra distance allowed beyond the
#: segment's own length (sensor height, soft tissue), mm.
SENSOR_HEIGHT_MM = 20.0
#: A joint's pivot residual (RMS, mm) on correct data is below this floor (or, when the
#: tracker is noisier, below ``PIVOT_NOISE_FACTOR`` x the static noise of the reference).
PIVOT_FLOOR_MM = 5.0
PIVOT_NOISE_FACTOR = 5.0
#: An alternative quaternion convention is named when its pooled pivot residual is below
#: this fraction of the as-read one (and the as-read one above ``PIVOT_MIN_MM``).
CONVENTION_RATIO = 0.5
PIVOT_MIN_MM = 1.0
#: ``fingerfit angles``: a recording whose pivot residual against the model's joint centre
#: exceeds this (mm, RMS) does not belong to the model.
RECORDING_RESIDUAL_MM = 10.0
#: Relative tolerance when matching a scale factor to a unit ratio.
SCALE_TOLERANCE = 0.2
#: Any joint between two tracked segments (``fingerfit joint``): plausible distance (mm)
#: from the joint centre to the *farther* of the two segment origins. Measured: 15 mm
#: (index DIP of the simulated hand, sensors mid-phalanx), 23 and 46 mm (PIP, MP),
#: 53-89 mm (hand-turned real Liberty logs), 152 mm (real upper-arm/forearm marker
#: clusters), 250 mm (a real mechanical hinge). A tracked body's sensor or cluster cannot
#: sit within 10 mm of the joint on both sides; 2 m is beyond any limb.
JOINT_REACH_MM = (10.0, 2000.0)

UNIT_NAMES = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches"}


@dataclass(frozen=True)
class Bound:
    """A plausible range ``[lo, hi]`` (mm) and what it is based on."""

    lo: float
    hi: float
    basis: str

    def contains(self, value: float) -> bool:
        """Whether ``value`` (mm) lies in the range (NaN does not)."""
        return bool(self.lo <= value <= self.hi)


def segment_bound(digit: str, segment: str) -> Bound:
    """Plausible length (mm) of one segment of a digit (``SEGMENT_FRACTION`` x hand length).

    Parameters
    ----------
    digit : str
        ``thumb``, ``index``, ``middle``, ``ring`` or ``little``.
    segment : str
        ``metacarpal``, ``proximal``, ``middle`` (fingers only) or ``distal``.
    """
    f = SEGMENT_FRACTION[digit][segment]
    return Bound(
        MARGIN[0] * f * HAND_LENGTH_MM[0],
        MARGIN[1] * f * HAND_LENGTH_MM[1],
        f"Buchholz 1992 fraction {f:.3f} of a {HAND_LENGTH_MM[0]:g}-{HAND_LENGTH_MM[1]:g} mm "
        f"hand, margins x{MARGIN[0]:g}/x{MARGIN[1]:g}",
    )


def finger_length_bound(finger: str) -> Bound:
    """Plausible length (mm) of a digit from its first joint's centre (a finger's MP, the
    thumb's CMC) to its tip: the hand-size check."""
    f = sum(SEGMENT_FRACTION[finger][s] for s in DIGITS[finger].segments)
    return Bound(
        MARGIN[0] * f * HAND_LENGTH_MM[0],
        MARGIN[1] * f * HAND_LENGTH_MM[1],
        f"fraction {f:.3f} of hand length",
    )


def neighbour_bound(finger: str, parent: str, child: str) -> Bound:
    """Plausible median distance (mm) between neighbouring sensor origins.

    Each sensor sits on its own segment, so the distance is at most the two segments'
    lengths plus the sensor heights, and at least a fraction of their mean length.
    """
    kind = {HAND_SENSOR: "metacarpal"} | {
        sensor_name(finger, s): s for s in DIGITS[finger].segments
    }
    fa = SEGMENT_FRACTION[finger][kind[parent]]
    fb = SEGMENT_FRACTION[finger][kind[child]]
    return Bound(
        0.5 * MARGIN[0] * 0.5 * (fa + fb) * HAND_LENGTH_MM[0],
        MARGIN[1] * (fa + fb) * HAND_LENGTH_MM[1] + 2 * SENSOR_HEIGHT_MM,
        "sensors on neighbouring segments",
    )
