"""Ground truth of simulated sessions (``truth.json``, ``truth/<recording>.csv``).

Real sessions have none; the study then reports only what the paper could measure.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import FingerfitError, shown
from ..model import HandModel
from ..session import Session
from ..transforms import FloatArray, angle_between_axes, distance_point_to_line


@dataclass(frozen=True)
class Truth:
    """True joint geometry (parent sensor frames) and true trajectories per recording.

    Attributes
    ----------
    document : dict
        ``truth.json``.
    tips : dict[str, dict[str, ndarray]]
        Recording -> digit -> true tip ``(n, 3)`` mm, tracker frame.
    pads : dict[str, dict[str, ndarray]]
        Recording -> digit -> true pad point (the pulp's skin point) ``(n, 3)`` mm,
        for the digits whose truth has pads.
    angles : dict[str, dict[str, dict[str, ndarray]]]
        Recording -> digit -> angle name (``mp``, ``mp_abduction``, ..., the thumb's
        ``cmc``, ``cmc_abduction``, ...) -> true angle ``(n,)`` rad.
    contacts : dict[str, dict[tuple[str, str], ndarray]]
        Recording -> (digit, digit) -> where their pulps touch ``(n, 3)`` mm, tracker
        frame (``<a>.contact.<b>.x|y|z`` columns; meaningful during the pair's pad-to-pad
        events).
    """

    document: dict
    tips: dict[str, dict[str, FloatArray]]  # recording -> finger -> (n, 3)
    pads: dict[str, dict[str, FloatArray]] = field(default_factory=dict)
    angles: dict[str, dict[str, dict[str, FloatArray]]] = field(default_factory=dict)
    contacts: dict[str, dict[tuple[str, str], FloatArray]] = field(default_factory=dict)

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
    pads: dict[str, dict[str, FloatArray]] = {}
    angles: dict[str, dict[str, dict[str, FloatArray]]] = {}
    contacts: dict[str, dict[tuple[str, str], FloatArray]] = {}
    for f in sorted((session_dir / "truth").glob("*.csv")):
        try:
            # Blank lines kept (as empty rows), so a row's line in the file is its index + 2.
            table = pd.read_csv(f, skip_blank_lines=False)
        except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
            raise FingerfitError(f"not a valid CSV ({str(exc).splitlines()[0]})", path=f) from None
        names = [str(c) for c in table.columns]
        at = {c: k for k, c in enumerate(names)}
        cols = [f"{finger}.tip.{c}" for finger in doc["fingers"] for c in "xyz"]
        missing = [c for c in cols if c not in at]
        if missing:
            raise FingerfitError(f"missing column '{missing[0]}'", path=f, line=1)
        # One float array, its columns picked by position (not one pandas selection each).
        values = _numbers(table, f)

        def xyz(finger: str, part: str, values=values, at=at) -> FloatArray:
            return values[:, [at[f"{finger}.{part}.{c}"] for c in "xyz"]]

        tips[f.name] = {finger: xyz(finger, "tip") for finger in doc["fingers"]}
        pads[f.name] = {
            finger: xyz(finger, "pad") for finger in doc["fingers"] if f"{finger}.pad.x" in at
        }
        contacts[f.name] = {
            (a, b): xyz(a, f"contact.{b}")
            for a in doc["fingers"]
            for b in doc["fingers"]
            if f"{a}.contact.{b}.x" in at
        }
        angles[f.name] = {
            finger: {
                c.split(".", 1)[1]: np.radians(values[:, k])
                for k, c in enumerate(names)
                if c.startswith(f"{finger}.") and c.count(".") == 1 and "distance" not in c
            }
            for finger in doc["fingers"]
        }
    return Truth(doc, tips, pads, angles, contacts)


def _numbers(table: pd.DataFrame, path: Path) -> FloatArray:
    """The table as one float array ``(n_rows, n_columns)``; a value that is not a number
    is refused naming its column and line (header line 1)."""
    for c, dtype in table.dtypes.items():
        if pd.api.types.is_numeric_dtype(dtype):
            continue
        bad = np.flatnonzero(
            (pd.to_numeric(table[c], errors="coerce").isna() & table[c].notna()).to_numpy()
        )
        if not bad.size:
            continue
        row = int(bad[0])
        raise FingerfitError(
            f"'{shown(table[c].iloc[row])}' is not a number",
            path=path,
            line=row + 2,
            field=str(c),
        )
    try:
        return table.to_numpy(dtype=float)
    except (TypeError, ValueError) as exc:
        raise FingerfitError(f"holds values that are not numbers ({exc})", path=path) from None


def axis_errors(model: HandModel, truth: Truth, finger: str) -> pd.DataFrame:
    """Per axis: angle to the true axis (deg) and distance of the fitted centre to the true axis (mm).

    Every axis of the digit, proximal first (the thumb's ``cmc``, ``cmc_abduction``,
    ``mcp``, ``mcp_abduction`` where fitted, ``ip``), whose truth is stored under the
    digit's ``joints`` in ``truth.json``; a finger's ``mp_abduction`` line is stored
    elsewhere there and is not scored (the fingers' rows are ``mp``, ``pip``, ``dip``).
    Both in the joint's parent sensor frame.
    """
    rows = []
    fm = model.fingers[finger]
    known = truth.document["fingers"][finger]["joints"]
    names = [a.name for a in fm.chain()]
    for joint in [n for n in names if n in known]:
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


def check_truth_frames(truth: Truth, session: Session) -> None:
    """Refuse a truth file whose rows do not match its recording's frames.

    Every ``truth/<recording>.csv`` of a recording the session has must hold one row per
    frame (the truth is compared frame by frame).

    Raises
    ------
    FingerfitError
        Naming the truth file, its row count and the recording's frame count.
    """
    frames = {rec.name: rec.n_frames for rec in session.recordings()}
    for name, tips in truth.tips.items():
        if name not in frames or not tips:
            continue
        rows = next(iter(tips.values())).shape[0]
        if rows != frames[name]:
            raise FingerfitError(
                f"has {rows} rows but the recording '{name}' has {frames[name]} frames "
                "(a truth file must hold one row per frame)",
                path=None if session.path is None else Path(session.path) / "truth" / name,
            )
