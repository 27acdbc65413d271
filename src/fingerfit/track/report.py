"""What tracking says about a recording: the angles table's extra columns and the summary
lines of ``fingerfit angles`` (``docs/tracking.md``)."""

from __future__ import annotations

import numpy as np

from ..transforms import FloatArray
from .recording import Tracked


def tracking_columns(tracked: Tracked, uncertainty: bool = False) -> dict[str, FloatArray]:
    """The angles table's columns about the model's solution, when it solved any frame.

    Parameters
    ----------
    tracked : Tracked
    uncertainty : bool
        Also each angle's standard deviation (``--uncertainty``).

    Returns
    -------
    dict
        Empty for a model without calibration statistics (it cannot solve a frame; the
        table is then as before they existed). Else, per digit of the table:
        ``<digit>.ik_rms_mm`` (the RMS position residual of the frame's sensors about the
        model, mm; empty where the digit was computed directly or not at all) and, with
        ``uncertainty``, ``<digit>.<angle>.sd`` (deg, from the frame's sensors alone;
        ``inf`` where they do not determine the angle, empty elsewhere).
    """
    if not tracked.can_solve:
        return {}
    n = tracked.kinematics.time.shape[0]
    out: dict[str, FloatArray] = {}
    for d in tracked.kinematics.motions[next(iter(tracked.kinematics.motions))]:
        t = tracked.digits.get(d)
        out[f"{d}.ik_rms_mm"] = t.rms_mm if t is not None else np.full(n, np.nan)
    if uncertainty:
        for d, m in tracked.kinematics.motions[next(iter(tracked.kinematics.motions))].items():
            t = tracked.digits.get(d)
            for name in m.angles:
                sd = t.sd.get(name) if t is not None else None
                out[f"{d}.{name}.sd"] = np.full(n, np.nan) if sd is None else np.degrees(sd)
    return out


def tracking_lines(tracked: Tracked) -> list[str]:
    """Plain-text lines for the summary: the frames solved by the model and how well each
    joint was determined there (median standard deviation, deg), the frames left empty."""
    lines = []
    solved = tracked.frames_solved()
    if solved:
        digits = [d for d, t in tracked.digits.items() if t.model.any()]
        carried = tracked.frames_carried()
        line = f"{solved} frames solved by the model ({', '.join(digits)})"
        if carried:
            line += (
                f"; in {carried} of them a joint not determined by the frame's sensors was "
                "carried from the frames around it"
            )
        lines.append(line)
        for d in digits:
            t = tracked.digits[d]
            parts = []
            for name, sd in t.sd.items():
                x = sd[t.model & ~t.carried]
                x = x[np.isfinite(x)]
                if x.size:
                    parts.append(f"{name} {np.degrees(np.median(x)):.2g}")
            rms = t.rms_mm[t.model]
            rms = rms[np.isfinite(rms)]
            if parts:
                lines.append(
                    f"  {d}: median SD (deg) "
                    + ", ".join(parts)
                    + (f"; residual {np.median(rms):.2g} mm" if rms.size else "")
                )
    empty = tracked.frames_empty()
    if empty:
        lines.append(
            f"{empty} frames left empty (the hand sensor or every sensor of a digit missing)"
        )
    return lines
