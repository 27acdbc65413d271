"""``fingerfit capture --view`` / ``--view-save``: the capture's evidence in Rerun.

Logged by the capture's evidence process (:class:`fingerfit.capture.EvidenceProcess`)
each time it has evaluated the recording so far (at most every
``fingerfit.capture.UPDATE_S``), and once more with the evidence the capture prints at
the end; so the recording loop never waits on the view. Each update is one row on the
time lines ``frame`` (0-based, the newest frame the evidence covers) and ``time`` (the
recording's seconds at that frame).

Entities (``docs/view.md``, *Capture*):

* ``evidence/axis_deg/<digit>/<joint>``: the flexion axis's 95 % confidence
  half-angle (deg), beside ``evidence/axis_deg/bound`` (the fit's largest, a line);
* ``evidence/cycles/<digit>/<joint>`` beside ``evidence/cycles/needed``;
* ``evidence/rom_deg/<digit>/<joint>`` (median range of motion, deg) beside
  ``evidence/rom_deg/needed``;
* ``evidence/table``: the capture's table (Markdown), every joint ``enough`` or ``more``;
* ``sensors``: each sensor's x, y, z axes at the newest frame (mm, tracker frame), as
  ``fingerfit view`` draws them.

A value not known yet (the axis below two cycles, the ROM without a cycle) is logged as
NaN, which the viewer leaves out of its line.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .rerunlog import _arrows, _indexes, _static, close_view, open_view
from .scene import _SENSOR_AXIS_COLOURS, SENSOR_AXIS_MM, require_rerun

if TYPE_CHECKING:
    from ..estimate.evidence import JointEvidence
    from ..session import Recording

#: The series of the evidence: ``(entity under evidence/, title, the threshold's name)``.
SERIES = (
    ("axis_deg", "axis +/- (deg, 95 %)", "bound"),
    ("cycles", "cycles", "needed"),
    ("rom_deg", "median ROM (deg)", "needed"),
)


def evidence_blueprint():
    """The layout: the sensors in 3D and the table beside the three series."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(
                    origin="/", contents=["/sensors/**"], name="sensors (mm, tracker frame)"
                ),
                rrb.TextDocumentView(origin="evidence/table", name="evidence"),
                row_shares=[3, 2],
            ),
            rrb.Vertical(
                *(rrb.TimeSeriesView(origin=f"evidence/{e}", name=t) for e, t, _ in SERIES)
            ),
            column_shares=[1, 1],
        ),
        collapse_panels=False,
    )


class EvidenceView:
    """The Rerun stream of a capture's evidence (module docstring).

    Parameters
    ----------
    sensors : list of str
        The recording's sensors, drawn in this order.
    need : tuple of (int, float, float)
        The thresholds the series are drawn against: cycles, median range of motion
        (deg), axis confidence half-angle (deg) (:func:`fingerfit.estimate.evidence.thresholds`).
    table : callable
        ``table(rows, frames)``: the evidence table of an update as Markdown (the
        capture's own, :func:`fingerfit.capture.markdown_table`).
    save : Path, optional
        Write a Rerun file (atomically, kept by :meth:`close` with ``ok``); otherwise the
        native viewer is spawned, its usage reporting off.

    Raises
    ------
    ModuleNotFoundError
        Rerun (the extra ``view``) is not installed.
    """

    def __init__(
        self,
        sensors: list[str],
        need: tuple[int, float, float],
        table: Callable[[list[JointEvidence], int], str],
        save: Path | None = None,
    ) -> None:
        rr = require_rerun()
        self.sensors = list(sensors)
        self.need = need
        self.table = table
        self.updates = 0
        self.stream, self.stack = open_view(save, evidence_blueprint())
        _static(rr, self.stream, "/", rr.ViewCoordinates.RIGHT_HAND_Z_UP)
        colours = list(_SENSOR_AXIS_COLOURS) * len(self.sensors)
        _static(rr, self.stream, "sensors", rr.Arrows3D.from_fields(colors=colours, radii=[0.6]))
        for entity, _, limit in SERIES:
            _static(
                rr,
                self.stream,
                f"evidence/{entity}/{limit}",
                rr.SeriesLines(colors=[(160, 160, 160)], widths=[1.0], names=[limit]),
            )

    def log(self, rows: list[JointEvidence], recording: Recording, frames: int) -> None:
        """Log one update: the evidence ``rows`` of the first ``frames`` frames of
        ``recording`` (mm, tracker frame), at its frame ``frames - 1``.

        Parameters
        ----------
        rows : list of JointEvidence
        recording : Recording
            The recording so far (at least ``frames`` frames).
        frames : int
            Frames the evidence covers (> 0).
        """
        rr = require_rerun()
        last = frames - 1
        idx = _indexes(rr, recording.time[last : last + 1], np.array([last]))
        values = {
            "axis_deg": ([r.axis_ci_deg for r in rows], self.need[2]),
            "cycles": ([float(r.cycles) for r in rows], float(self.need[0])),
            "rom_deg": ([r.rom_deg for r in rows], self.need[1]),
        }
        for entity, _, limit in SERIES:
            got, needed = values[entity]
            for r, v in zip(rows, got, strict=True):
                self._scalar(rr, f"evidence/{entity}/{r.digit}/{r.joint}", idx, v)
            self._scalar(rr, f"evidence/{entity}/{limit}", idx, needed)
        table = self.table(rows, frames)
        rr.send_columns(
            "evidence/table",
            indexes=idx,
            columns=rr.TextDocument.columns(text=[table], media_type=["text/markdown"]),
            recording=self.stream,
        )
        have = [s for s in self.sensors if s in recording.poses]
        if have:
            pos = np.stack([recording.poses[s].position[last] for s in have])  # (s, 3) mm
            rot = np.stack([recording.poses[s].rotation[last] for s in have])  # (s, 3, 3)
            vectors = SENSOR_AXIS_MM * np.swapaxes(rot, 1, 2).reshape(-1, 3)
            origins = np.repeat(pos, 3, axis=0)
            _arrows(rr, self.stream, "sensors", idx, origins[None], vectors[None])
        self.updates += 1

    def _scalar(self, rr, entity: str, idx: list, value: float) -> None:
        rr.send_columns(
            entity,
            indexes=idx,
            columns=rr.Scalars.columns(scalars=np.array([value], dtype=float)),
            recording=self.stream,
        )

    def close(self, ok: bool) -> None:
        """Flush the stream; the file (``save``) is kept when ``ok``, else removed."""
        close_view(self.stream, self.stack, ok)
