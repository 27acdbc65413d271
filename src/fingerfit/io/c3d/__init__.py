"""C3D motion files (via the optional ``ezc3d`` package): 6-DOF channels and marker clusters.

Two sources of segment poses:

* **ROTATION channels** (C3D ``ROTATION`` group): one 4x4 homogeneous transform per
  channel and frame, segment -> lab; translations in ``POINT:UNITS``.
* **Marker clusters**: three or more markers on one segment. By default every group
  of markers named ``<segment><number>`` with at least three members is a cluster
  (``ArmR1, ArmR2, ArmR3`` -> ``ArmR``). Each frame's pose is the least-squares rigid
  fit of the cluster's shape (:mod:`fingerfit.io.rigid`), with the RMS residual per
  frame reported. The shape comes from the same file or from a static trial.

Positions are returned in mm (lab = tracker coordinates), rotations map segment into
lab coordinates (``docs/conventions.md``). Install with ``pip install fingerfit[c3d]``.

Modules: :mod:`.header` (the raw header, checked first), :mod:`.markers` (trajectories,
clusters by name), :mod:`.segments` (poses from ROTATION channels or clusters); every
name is importable from here.
"""

from .header import C3DHeader, read_c3d_header
from .markers import (
    C3DMarkers,
    c3d_point_units,
    find_clusters,
    parse_clusters,
    read_c3d_markers,
)
from .markers import _ezc3d as _ezc3d
from .markers import _param as _param
from .segments import (
    MAX_RESIDUAL_MM,
    ORTHONORMAL_TOLERANCE,
    C3DSegments,
    read_c3d,
    read_c3d_segments,
)

__all__ = [
    "MAX_RESIDUAL_MM",
    "ORTHONORMAL_TOLERANCE",
    "C3DHeader",
    "C3DMarkers",
    "C3DSegments",
    "c3d_point_units",
    "find_clusters",
    "parse_clusters",
    "read_c3d",
    "read_c3d_header",
    "read_c3d_markers",
    "read_c3d_segments",
]
