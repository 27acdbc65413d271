"""The evidence table: one row per joint, as the terminal shows it (``fingerfit
capture``) and as Markdown for the view's panel (``fingerfit.view.evidence``)."""

from __future__ import annotations

import math

from ..estimate.evidence import JointEvidence

#: The evidence table's columns (``fingerfit capture``'s table, the view's panel); the
#: numeric ones are right-aligned.
TABLE_COLUMNS = ("digit", "joint", "cycles", "ROM (deg)", "axis +/- (deg)", "2nd axis", "")
NUMERIC_COLUMNS = ("cycles", "ROM (deg)", "axis +/- (deg)")


def table_title(need: tuple[int, float, float], frames: int, rate_hz: float) -> str:
    """The evidence table's title: the frames (and seconds at ``rate_hz`` Hz) it covers
    and what the fit needs (:func:`thresholds`)."""
    return (
        f"{frames} frames ({frames / rate_hz:.1f} s); the fit needs {need[0]} cycles, "
        f"{need[1]:g} deg median range of motion and the axis within +/-{need[2]:g} deg "
        "(95 %) per joint"
    )


def table_cells(r: JointEvidence) -> list[str]:
    """One joint's row of the evidence table (:data:`TABLE_COLUMNS`), as printed: the ROM
    to the degree, the axis confidence to a tenth of a degree (``<0.1`` below), ``-``
    for what is not known, ``enough`` or ``more``."""
    rom = "-" if math.isnan(r.rom_deg) else f"{r.rom_deg:.0f}"
    ci = "-" if math.isnan(r.axis_ci_deg) else f"{max(r.axis_ci_deg, 0.1):.1f}"
    ci = "<" + ci if r.axis_ci_deg < 0.05 else ci
    second = "-" if r.second is None else ("yes: " if r.second else "no: ") + r.second_note
    return [r.digit, r.joint, str(r.cycles), rom, ci, second, "enough" if r.enough else "more"]


def markdown_table(
    rows: list[JointEvidence], frames: int, need: tuple[int, float, float], rate_hz: float
) -> str:
    """The evidence table as Markdown (the view's panel): :func:`table_title`, then one
    row per joint with the cells the terminal shows (:func:`table_cells`)."""
    head = [c or "fit" for c in TABLE_COLUMNS]
    align = ["---:" if c in NUMERIC_COLUMNS else "---" for c in TABLE_COLUMNS]
    lines = [f"**{table_title(need, frames, rate_hz)}**", ""]
    for cells in (head, align, *(table_cells(r) for r in rows)):
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"
