"""The landmark protocol in the 3D view (``fingerfit capture --protocol landmarks --view``):
the stylus tip as it moves, each take, and each landmark once taken, at the reference
posture (tracker frame, mm), labelled with its name and uncertainty."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..transforms import FloatArray
from .rerunlog import _indexes, close_view, open_view
from .scene import require_rerun

#: Colours (RGB) of the stylus tip, a take and a landmark.
TIP, TAKE, LANDMARK = (255, 215, 0), (255, 140, 0), (40, 220, 90)


class LandmarkView:
    """A Rerun stream (a window, or the file ``save`` written when the capture ends).

    Parameters
    ----------
    save : Path, optional
        Write the view to this ``.rrd`` file instead of a window.
    reference : dict[str, (ndarray (3,), ndarray (3, 3))]
        The reference posture's sensor poses (mm; sensor -> tracker), shown as points.
    """

    def __init__(self, save: Path | None, reference: dict[str, tuple[FloatArray, FloatArray]]):
        self.rr = require_rerun()
        self.stream, self._stack = open_view(save, None)
        self._frames = 0
        names = list(reference)
        self.rr.log(
            "reference/sensors",
            self.rr.Points3D(np.array([reference[s][0] for s in names]), labels=names, radii=1.5),
            static=True,
            recording=self.stream,
        )

    def tip(self, time: FloatArray, points: FloatArray) -> None:
        """The stylus tip ``(n, 3)`` (tracker frame, mm) at ``time`` ``(n,)`` s."""
        n = points.shape[0]
        if n == 0:
            return
        rr = self.rr
        idx = _indexes(rr, time, np.arange(self._frames, self._frames + n))
        self._frames += n
        cols = rr.Points3D.columns(positions=points, colors=np.tile(TIP, (n, 1))).partition(
            np.ones(n, dtype=int)
        )
        rr.send_columns("stylus/tip", indexes=idx, columns=cols, recording=self.stream)

    def landmark(self, name: str, point: FloatArray, sd_mm: float) -> None:
        """A landmark taken: ``point`` ``(3,)`` at the reference posture (mm)."""
        label = name if not np.isfinite(sd_mm) else f"{name} +/-{sd_mm:.2f} mm"
        self.rr.log(
            f"landmarks/{name}",
            self.rr.Points3D([point], labels=[label], colors=[LANDMARK], radii=2.0),
            static=True,
            recording=self.stream,
        )

    def close(self, ok: bool) -> None:
        """End the stream; its file is kept when ``ok``."""
        close_view(self.stream, self._stack, ok)
