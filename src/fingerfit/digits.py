"""The hand's five digits: their segments, joints, second axes and landmarks.

One table (:data:`DIGITS`) says what every digit is made of; everything else
(session names, the model file, kinematics, simulator, export) reads it instead of
spelling out finger or thumb names. ``docs/conventions.md`` defines the frames and signs.

* A **finger** (``index``, ``middle``, ``ring``, ``little``): segments ``proximal``,
  ``middle``, ``distal``; joints ``mp`` (hand -> proximal), ``pip``, ``dip``; the MP may
  carry a second (ab/adduction) axis ``mp_abduction``, **proximal** to the flexion axis
  (fixed in the hand): ``Q = Rot(b, beta) Rot(a, theta)``.
* The **thumb**: segments ``metacarpal``, ``proximal``, ``distal``; joints ``cmc``
  (hand -> metacarpal), ``mcp``, ``ip``. The CMC always has a second axis,
  ``cmc_abduction``, and the MCP may have one, ``mcp_abduction``. In both the
  flexion-extension axis is **proximal** (in the trapezium, resp. the metacarpal head)
  and the ab/adduction axis distal (in the base of the metacarpal, resp. of the
  proximal phalanx; Hollister et al. 1992, 1995): ``Q = Rot(a, theta) Rot(b, beta)``.

Each joint's first axis carries the joint's name and is its flexion axis; the second
axis is ``<joint>_abduction``. :attr:`Digit.order` states, per two-axis joint, which of
the two is proximal; the model file stores it (``axis_order``).
"""

from __future__ import annotations

from dataclasses import dataclass

#: The sensor on the back of the hand: the parent of every digit's first segment.
HAND_SENSOR = "hand"
#: The order of a two-axis joint's axes, proximal first.
ABDUCTION_FIRST = "abduction_first"
FLEXION_FIRST = "flexion_first"


@dataclass(frozen=True)
class Digit:
    """What a digit is made of (names only; geometry lives in the model).

    Attributes
    ----------
    name : str
        ``thumb``, ``index``, ``middle``, ``ring`` or ``little``.
    segments : tuple of str
        The three tracked segments, proximal to distal.
    joints : tuple of str
        The three flexion joints, proximal to distal; joint ``k`` joins segment ``k - 1``
        (the hand for ``k = 0``) to segment ``k``.
    second_axes : tuple of str
        Joints that may carry a second (ab/adduction) axis.
    required_second : tuple of str
        Joints that always carry one (the thumb's CMC).
    order : dict[str, str]
        Joint -> :data:`ABDUCTION_FIRST` or :data:`FLEXION_FIRST`: which of its two
        axes is proximal (fixed in the parent segment).
    """

    name: str
    segments: tuple[str, str, str]
    joints: tuple[str, str, str]
    second_axes: tuple[str, ...]
    required_second: tuple[str, ...]
    order: dict[str, str]

    @property
    def landmarks(self) -> tuple[str, ...]:
        """Landmark suffixes: the dorsal joint points, then ``tip`` (nail edge)."""
        return (*self.joints, "tip")

    def sensor(self, segment: str) -> str:
        """Sensor name of a segment, e.g. ``thumb.metacarpal``."""
        return f"{self.name}.{segment}"

    @property
    def distal_sensor(self) -> str:
        """The sensor of the distal segment (the child of the last flexion joint), e.g.
        ``index.distal``: the one that carries the tip and the pad."""
        return self.sensor(self.segments[-1])

    def sensors(self) -> list[str]:
        """The hand sensor and the digit's three segment sensors, proximal to distal."""
        return [HAND_SENSOR, *(self.sensor(s) for s in self.segments)]

    def joint_sensors(self) -> dict[str, tuple[str, str]]:
        """Joint -> (parent sensor, child sensor); the first joint's parent is ``hand``."""
        chain = self.sensors()
        return {j: (chain[i], chain[i + 1]) for i, j in enumerate(self.joints)}

    def angle_names(self, two_axis: tuple[str, ...] = ()) -> tuple[str, ...]:
        """Angle (column) names: the flexion joints, then ``<joint>_abduction`` of each
        two-axis joint in ``two_axis``, in joint order."""
        return (*self.joints, *(second_axis(j) for j in self.joints if j in two_axis))


def second_axis(joint: str) -> str:
    """Name of a joint's second axis, e.g. ``mp_abduction``."""
    return f"{joint}_abduction"


FINGER_SEGMENTS = ("proximal", "middle", "distal")
FINGER_JOINTS = ("mp", "pip", "dip")
THUMB_SEGMENTS = ("metacarpal", "proximal", "distal")
THUMB_JOINTS = ("cmc", "mcp", "ip")

#: The four fingers, radial to ulnar.
FINGERS = ("index", "middle", "ring", "little")
#: Every digit, radial to ulnar.
DIGIT_NAMES = ("thumb", *FINGERS)

DIGITS: dict[str, Digit] = {
    "thumb": Digit(
        "thumb",
        THUMB_SEGMENTS,
        THUMB_JOINTS,
        ("cmc", "mcp"),
        ("cmc",),
        {"cmc": FLEXION_FIRST, "mcp": FLEXION_FIRST},
    ),
    **{
        f: Digit(f, FINGER_SEGMENTS, FINGER_JOINTS, ("mp",), (), {"mp": ABDUCTION_FIRST})
        for f in FINGERS
    },
}
