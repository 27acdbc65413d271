"""The evidence of a joint so far: what ``fingerfit fit`` needs of it, computed by the
fit's own functions on everything the fit will pool -- a session's calibration
(``grasp``) recordings, one of them perhaps still being recorded
(:func:`fingerfit.estimate.fit.digit_data`). ``fingerfit capture`` shows it while it
records, and ``fingerfit.view.evidence`` draws it.

* grasp cycles and their median range of motion (:func:`fingerfit.estimate.cycles.
  extract_cycles`), against ``FitOptions.min_cycles`` and ``min_rom_deg``;
* the flexion axis's 95 % confidence half-angle from the spread over the cycles
  (:func:`fingerfit.estimate.fit.axis_ci_deg`), against ``FitOptions.max_axis_ci_deg``;
* for a joint with a second axis, whether the data identify it: a finger's MP and the
  thumb's MCP by the fit's held-out choice (:func:`fingerfit.estimate.methods.
  second_axis_choice`: two axes chosen, or one), the thumb's CMC by the saddle fit
  itself (:func:`fingerfit.estimate.fit.saddle_estimate`: both axes turned far enough,
  or the fit's refusal).

A joint is *enough* when it has the cycles without which ``fingerfit fit`` refuses a
joint, the range of motion below which the fit warns (weak evidence) and the axis
confidence bound above which the fit warns; the
thumb's CMC, which the fit takes without the cycle rules, when its saddle fit succeeds and
its axis confidence passes (``docs/capture.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..digits import DIGITS
from ..errors import FingerfitError
from ..session import Session
from .choice import TWO_AXIS
from .fit import (
    FitOptions,
    axis_ci_deg,
    digit_data,
    digit_direction,
    reference_poses,
    saddle_estimate,
)
from .methods import JointData, second_axis_choice


def thresholds(options: FitOptions | None = None) -> tuple[int, float, float]:
    """``(cycles, range of motion deg, axis confidence half-angle deg)`` a joint needs:
    the fit's own (``FitOptions``).

    The fit refuses a joint with fewer than ``max(min_cycles, 2)`` cycles (or a median
    range of motion under ``rom_floor_deg``), and warns (keeping the joint) when the median
    range of motion is under ``min_rom_deg`` or its axis confidence half-angle over
    ``max_axis_ci_deg`` (``fingerfit.estimate.fit``).
    """
    options = options or FitOptions()
    return max(options.min_cycles, 2), float(options.min_rom_deg), float(options.max_axis_ci_deg)


@dataclass(frozen=True)
class JointEvidence:
    """What the fit needs of one joint, so far.

    Attributes
    ----------
    digit, joint : str
    cycles : int
        Movement cycles found over the pooled recordings.
    rom_deg : float
        Median range of motion of those cycles (deg; NaN without a cycle).
    axis_ci_deg : float
        95 % confidence half-angle of the flexion axis (deg; NaN below two cycles or
        when the saddle fit refuses).
    second : bool or None
        None for a joint with one axis (PIP, DIP, IP); else whether the data identify the
        second axis: a finger's MP or the thumb's MCP when the held-out choice takes two
        axes, the thumb's CMC when its saddle fit succeeds.
    second_note : str
        What decided ``second``, in a few words: the ab/adduction range (deg) and the
        choice, or the saddle fit's ranges (deg).
    enough : bool
        The joint passes the fit's rules (module docstring).
    advice : str
        The fit's own refusal of the second axis when it refuses it (one line), else "";
        a refused joint is not enough.
    """

    digit: str
    joint: str
    cycles: int
    rom_deg: float
    axis_ci_deg: float
    second: bool | None
    second_note: str
    enough: bool
    advice: str = ""


def _second(data: JointData, required: bool) -> tuple[bool, str, str, float]:
    """``(identified, note, advice, axis CI deg)`` of a joint with a second axis (module
    docstring)."""
    if required:
        try:
            est = saddle_estimate(data, None, None)
        except FingerfitError as exc:
            return False, "refused by the saddle fit", exc.reason, math.nan
        sf = est.abduction
        note = f"flexion {sf.flexion_range_deg:.0f}, ab/ad {sf.abduction_range_deg:.0f} deg"
        return True, note, "", axis_ci_deg(data, sf)
    if len(data.periods) < 2:
        return False, "needs 2 cycles", "", math.nan
    try:
        tf, choice = second_axis_choice(data)
    except FingerfitError as exc:
        return False, "refused by the two-axis fit", exc.reason, math.nan
    two = choice.chosen == TWO_AXIS
    note = f"ab/ad {tf.abduction_range_deg:.1f} deg, {'two axes' if two else 'one axis'}"
    return two, note, "", axis_ci_deg(data, None, choice)


def evidence(
    session: Session,
    digits: list[str],
    options: FitOptions | None = None,
    *,
    second: bool = True,
) -> list[JointEvidence]:
    """The evidence of every joint of ``digits`` over the session's ``grasp`` recordings.

    Parameters
    ----------
    session : Session
        The reference recording, every calibration recording so far in ``grasp`` (mm,
        tracker frame) and the landmarks when there are any (they start the MP's second
        axis as in the fit; without them the fit's landmark-free starts are used).
    digits : list of str
        Digits whose joints to report.
    options : FitOptions, optional
        The thresholds (default: the fit's defaults).
    second : bool
        Evaluate the second axes (the held-out choice, the saddle fit: tenths of a
        second to seconds); without it ``second`` is None and a joint's axis confidence is
        that of its SARA hinge axis.

    Returns
    -------
    list of JointEvidence
        Proximal to distal per digit.
    """
    options = options or FitOptions()
    need_cycles, need_rom, max_ci = thresholds(options)
    reference = reference_poses(session)
    out = []
    for d in digits:
        digit = DIGITS[d]
        if any(s not in reference for s in digit.sensors()) or not session.grasp:
            out += [
                JointEvidence(d, j, 0, math.nan, math.nan, None, "", False) for j in digit.joints
            ]
            continue
        try:
            along = digit_direction(session, d)
        except FingerfitError:  # no landmarks yet
            along = None
        for j, data in digit_data(session, d, reference, along).items():
            n = len(data.periods)
            rom = float(np.degrees(np.median(data.rom))) if n else math.nan
            required = j in digit.required_second
            ident, note, advice = None, "", ""
            if second and j in digit.second_axes:
                ident, note, advice, ci = _second(data, required)
            else:
                ci = axis_ci_deg(data)
            ci_ok = not ci > max_ci  # NaN: the cycle rule decides
            if required:
                ok = bool(ident) and ci_ok if second else False
            else:
                ok = n >= need_cycles and rom >= need_rom and ci_ok and not math.isnan(ci)
                ok = ok and not advice
            out.append(JointEvidence(d, j, n, rom, ci, ident, note, bool(ok), advice))
    return out
