"""Which sensors determine which joints: the layout of a recording against a model.

A digit's joint angles are the unknowns of its chain; a 6-DOF sensor on a segment gives
six equations for every axis proximal to it (its pose relative to the hand sensor). So:

* without the hand sensor nothing is determined (every pose is taken relative to it);
* a joint is determined when a sensor sits on its child segment or on one distal to it.
  The digit's distal sensor therefore determines every joint of the digit (a finger: 4
  unknowns from 6 equations; how well each is determined is each frame's covariance,
  ``docs/tracking.md``); a digit without its distal sensor leaves the joints distal to its
  last sensor undetermined; a digit without any sensor leaves all.

:func:`check_layout` refuses a recording whose layout cannot determine a joint, in one line
naming the joint and the sensor that would determine it.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import FingerfitError
from ..model import HandModel
from ..session import HAND_SENSOR


@dataclass(frozen=True)
class DigitLayout:
    """The sensors of one digit that a recording has.

    Attributes
    ----------
    digit : str
    sensors : tuple of str
        The digit's segment sensors, proximal to distal.
    present : tuple of bool
        Whether each is in the recording (and allowed by ``--sensors``).
    """

    digit: str
    sensors: tuple[str, ...]
    present: tuple[bool, ...]

    @property
    def complete(self) -> bool:
        """Every sensor of the digit is there: its angles come from the sensors directly
        wherever a frame has them all."""
        return all(self.present)

    @property
    def missing(self) -> tuple[str, ...]:
        return tuple(s for s, p in zip(self.sensors, self.present, strict=True) if not p)


def digit_layout(model: HandModel, digit: str, sensors: set[str]) -> DigitLayout:
    """The layout of ``digit`` given the sensor names ``sensors`` a recording has."""
    names = tuple(jm.child for jm in model.fingers[digit].joints.values())
    return DigitLayout(digit, names, tuple(s in sensors for s in names))


def check_layout(
    model: HandModel,
    sensors: set[str],
    digits: list[str],
    where: str | None = None,
    field: str | None = None,
    skip: str | None = None,
) -> dict[str, DigitLayout]:
    """Each digit's layout, or the one-line refusal of a layout that determines too little.

    Parameters
    ----------
    model : HandModel
    sensors : set of str
        Sensor names the recording has (after ``--sensors``).
    digits : list of str
        The digits to compute.
    where : str, optional
        The recording's file, for the message.
    field : str, optional
        The option that chose the sensors (``--sensors``, ``--stations``), for the message.
    skip : str, optional
        The option that leaves a digit out (``angles``' ``--fingers``), named in the
        message of a digit without any sensor.

    Returns
    -------
    dict
        Digit -> :class:`DigitLayout`.

    Raises
    ------
    FingerfitError
        No hand sensor; a digit without any sensor (``--fingers`` leaves it out); a digit
        whose distal sensor is missing, naming the first joint distal to its last sensor.
    """
    if HAND_SENSOR not in sensors:
        raise FingerfitError(
            f"no '{HAND_SENSOR}' sensor: every joint angle is taken relative to it",
            path=where,
            field=field,
        )
    out = {}
    for d in digits:
        lay = digit_layout(model, d, sensors)
        if not any(lay.present):
            raise FingerfitError(
                f"{d}: no sensor on the digit ({lay.sensors[-1]} would determine every joint"
                + (f"; {skip} leaves the digit out)" if skip else ")"),
                path=where,
                field=field,
            )
        if not lay.present[-1]:
            last = max(i for i, p in enumerate(lay.present) if p)
            joint = list(model.fingers[d].joints)[last + 1]
            have = ", ".join([HAND_SENSOR, *(s for s in lay.sensors if s in sensors)])
            raise FingerfitError(
                f"{d} {joint}: not determined by {have} ({lay.sensors[-1]} would determine it)",
                path=where,
                field=field,
            )
        out[d] = lay
    return out
