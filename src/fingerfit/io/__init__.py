"""Readers and writers: files -> :class:`~fingerfit.session.Session` and back.

* :mod:`.posecsv` -- the canonical pose CSV of the session format (its Parquet form
  :mod:`.poseparquet`, both checked and placed by :mod:`.poserows`, written by
  :mod:`.posewrite`);
* :mod:`.sessiondir` -- whole session directories (``session.toml`` + CSVs);
* :mod:`.atomic` -- all-or-nothing file writes;
* :mod:`.liberty`, :mod:`.widecsv`, :mod:`.c3d` -- real tracker files (Polhemus
  Liberty/Patriot ASCII and binary, wide CSV logs, C3D markers and 6-DOF channels);
* :mod:`.hygiene` -- repeated samples, gaps, jumps (:mod:`.jumps`) and unit checks;
  :mod:`.rigid` -- segment poses from marker clusters.

The names below are imported on first use (:mod:`fingerfit._lazy`): reading a pose file
does not import the C3D reader's SciPy.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

_EXPORTS = {
    "read_c3d": ".c3d",
    "read_c3d_segments": ".c3d",
    "read_liberty_ascii": ".liberty",
    "read_liberty_binary": ".liberty",
    "read_pose_csv": ".posecsv",
    "write_pose_csv": ".posewrite",
    "load_session": ".sessiondir",
    "save_session": ".sessiondir",
    "read_wide_csv": ".widecsv",
}
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
__all__ = [
    "load_session",
    "read_c3d",
    "read_c3d_segments",
    "read_liberty_ascii",
    "read_liberty_binary",
    "read_pose_csv",
    "read_wide_csv",
    "save_session",
    "write_pose_csv",
]

if TYPE_CHECKING:
    from .c3d import read_c3d, read_c3d_segments
    from .liberty import read_liberty_ascii, read_liberty_binary
    from .posecsv import read_pose_csv
    from .posewrite import write_pose_csv
    from .sessiondir import load_session, save_session
    from .widecsv import read_wide_csv
