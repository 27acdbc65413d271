"""Readers and writers: files -> :class:`~fingerfit.session.Session` and back.

* :mod:`.posecsv` -- the canonical pose CSV of the session format;
* :mod:`.sessiondir` -- whole session directories (``session.toml`` + CSVs);
* :mod:`.atomic` -- all-or-nothing file writes.
"""

from .posecsv import read_pose_csv, write_pose_csv
from .sessiondir import load_session, save_session

__all__ = ["load_session", "read_pose_csv", "save_session", "write_pose_csv"]
