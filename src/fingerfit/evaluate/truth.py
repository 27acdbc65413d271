"""Ground truth of simulated sessions (``truth.json``, ``truth/<recording>.csv``).

Real sessions have none; the study then reports only what the paper could measure.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError
from ..model import HandModel
from ..transforms import FloatArray, angle_between_axes, distance_point_to_line


@dataclass(frozen=True)
class Truth:
    """True joint geometry (parent sensor frames) and true fingertips per recording (mm)."""

    document: dict
    tips: dict[str, dict[str, FloatArray]]  # recording -> finger -> (n, 3)

    def joint(self, finger: str, joint: str) -> tuple[FloatArray, FloatArray]:
        """True centre (mm) and axis in the parent sensor frame at the reference posture."""
        j = self.document["fingers"][finger]["joints"][joint]
        return np.array(j["center_in_parent"]), np.array(j["axis_in_parent"])


def load_truth(session_dir: Path | None) -> Truth | None:
    """The truth written by ``fingerfit simulate`` beside a session, or None.

    Raises
    ------
    FingerfitError
        ``truth.json`` or a ``truth/<recording>.csv`` that cannot be read, named.
    """
    if session_dir is None or not (session_dir / "truth.json").is_file():
        return None
    path = session_dir / "truth.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FingerfitError(f"not valid JSON ({exc})", path=path) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("fingers"), dict):
        raise FingerfitError("must be an object with 'fingers'", path=path, field="fingers")
    tips: dict[str, dict[str, FloatArray]] = {}
    for f in sorted((session_dir / "truth").glob("*.csv")):
        try:
            table = pd.read_csv(f)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            raise FingerfitError(f"not a valid CSV ({str(exc).splitlines()[0]})", path=f) from None
        cols = [f"{finger}.tip.{c}" for finger in doc["fingers"] for c in "xyz"]
        missing = [c for c in cols if c not in table.columns]
        if missing:
            raise FingerfitError(f"missing column '{missing[0]}'", path=f, line=1)
        tips[f.name] = {
            finger: table[[f"{finger}.tip.{c}" for c in "xyz"]].to_numpy(dtype=float)
            for finger in doc["fingers"]
        }
    return Truth(doc, tips)


def axis_errors(model: HandModel, truth: Truth, finger: str) -> pd.DataFrame:
    """Per joint: angle to the true axis (deg) and distance of the fitted centre to the true axis (mm)."""
    rows = []
    for joint in model.fingers[finger].joints:
        c, a = model.in_parent(finger, joint)
        ct, at = truth.joint(finger, joint)
        rows.append(
            (
                finger,
                joint,
                float(np.degrees(angle_between_axes(a, at))),
                float(distance_point_to_line(c, ct, at)),
            )
        )
    return pd.DataFrame(rows, columns=["finger", "joint", "axis_error_deg", "centre_to_axis_mm"])
