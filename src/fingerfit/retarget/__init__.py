"""Retargeting the individual hand model onto robot hands (Shadow, Allegro, any URDF/MJCF).

* :mod:`.robots` -- robot kinematics from MJCF (MuJoCo) or URDF (Pinocchio);
* :mod:`.maps` -- the TOML map (shipped: ``maps/shadow.toml``, ``maps/allegro_*.toml``);
* :mod:`.palm` -- palm frames, digit anchors, per-digit scale;
* :mod:`.limits` -- joint limits and couplings;
* :mod:`.solve` -- the ``tip`` method; :mod:`.joint` -- the ``joint`` method;
* :mod:`.figure` -- the person and the robot side by side.

:mod:`.pipeline` ties them together (:func:`retarget` offline, :class:`Retargeter` block by block). ``docs/retargeting.md`` defines frames, scales and
the evaluation. MuJoCo, Pinocchio and the robot files are the extra ``retarget``.
"""

from .maps import parse_map
from .pipeline import (
    CONTACT_MM,
    METHODS,
    PINCH_FAR_MM,
    Retargeter,
    Retargeting,
    Setup,
    person_points,
    pinch_terms,
    resolve,
    retarget,
    robot_points,
    setup,
    targets,
)
from .robots import load_robot
from .solve import TipOptions

__all__ = [
    "CONTACT_MM",
    "METHODS",
    "PINCH_FAR_MM",
    "Retargeter",
    "Retargeting",
    "Setup",
    "TipOptions",
    "load_robot",
    "parse_map",
    "person_points",
    "pinch_terms",
    "resolve",
    "retarget",
    "robot_points",
    "setup",
    "targets",
]
