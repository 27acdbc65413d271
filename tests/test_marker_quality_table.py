"""`fingerfit fit`'s table for a model fitted from markers: what the bundle adjustment
has (range of motion, residual, the axis direction's SD and 95 % half-angle), not the
grasp cycles' figures it does not have."""

from __future__ import annotations

import functools
import io
import math

import numpy as np
from rich.console import Console

from fingerfit.cli.fit import MARKER_LEGEND, TABLE_LEGEND, quality_table
from fingerfit.estimate.markers.fit import fit_marker_session
from fingerfit.simulate.markers import simulate_markers
from fingerfit.simulate.study import SimConfig, simulate_subject
from fingerfit.simulate.truthmodel import truth_model


@functools.cache
def two_axis_fit():
    """A noisy simulated index finger (Todorov's layout, 0.3 mm noise, no skin slide)
    fitted with a two-axis MP, and its truth."""
    sim = simulate_subject(SimConfig(targets=False, test=False, cycles=4), 5)
    ms = simulate_markers(sim, "todorov", seed=1, slide=0.0)
    return fit_marker_session(ms.session, mp_axes="two"), sim


def _cells(table) -> list[list[str]]:
    cols = [list(c.cells) for c in table.columns]
    return [list(row) for row in zip(*cols, strict=True)]


def test_a_marker_models_table_shows_the_adjustments_figures() -> None:
    fit, sim = two_axis_fit()
    table = quality_table(fit.model)
    header = [c.header for c in table.columns]
    assert header == list(MARKER_LEGEND)
    for gone in ("cycles", "c→axis mm", "s5/s6", "vs cycles°"):
        assert gone in TABLE_LEGEND and gone not in header
    rows = _cells(table)
    # one row per axis: the MP's ab/adduction axis beside its flexion
    assert [r[1] for r in rows] == ["mp", "mp_abduction", "pip", "dip"]
    digit = fit.digits["index"]
    fm = fit.model.fingers["index"]
    truth = truth_model(sim, two_axis=False).fingers["index"]
    for row in rows:
        level = digit.layout.names.index(row[1])
        rom = math.degrees(float(np.ptp(digit.result.q[level])))
        assert row[2] == f"{rom:.0f}" and rom > 20
        assert row[3] == f"{digit.result.rms_mm:.2f}"
        assert 0.2 < digit.result.rms_mm < 0.35  # the camera noise: 0.3 mm
        assert row[4] == f"{digit.axis_sd_deg(level):.2f}"
        assert row[5] == f"{digit.axis_ci_deg(level):.1f}"
        if row[1] in truth.joints:  # a flexion axis: its bone and its true direction
            assert (
                row[6]
                == f"{fm.segment_lengths[fm.segments[('mp', 'pip', 'dip').index(row[1])]]:.1f}"
            )
            axis = fm.joints[row[1]].axis
            err = math.degrees(math.acos(min(1.0, abs(float(axis @ truth.joints[row[1]].axis)))))
            assert err < 3 * digit.axis_ci_deg(level), (row[1], err)
        else:
            assert row[6] == "–"
    text = _render(table)
    assert "grasp cycles" not in text and "95 % half-angle" in text


def _render(table) -> str:
    console = Console(width=160, record=True, file=io.StringIO())
    console.print(table)
    return console.export_text()
