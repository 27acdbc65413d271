"""Export: the individual hand model as URDF, MuJoCo MJCF and OpenSim, and recorded
motion as a joint-angle trajectory with the joint names.

* :mod:`.geometry` -- the digit chains in the hand sensor frame (m, rad, kg), the one
  description every writer reads;
* :mod:`.urdf` -- URDF via yourdfpy;
* :mod:`.mjcf` -- MJCF via ``mujoco.MjSpec``;
* :mod:`.osim` -- the OpenSim model (``.osim``), written as XML;
* :mod:`.trajectory` -- joint angles (rad) per frame, columns named like the joints, and
  the OpenSim motion (``.mot``) of every coordinate;
* :mod:`.files` -- the text files written all-or-nothing.

yourdfpy and mujoco are the optional extra ``robot`` (``pip install fingerfit[robot]``);
they are imported only when a file is written. The OpenSim files need no extra to be
written; ``opensim`` (``pip install fingerfit[opensim]``) is OpenSim itself, to load and
check them. See ``docs/export.md``.
"""

from __future__ import annotations

from .files import write_text
from .geometry import RobotHand, joint_names, robot_hand
from .mjcf import mjcf_string, write_mjcf
from .osim import osim_string, write_osim
from .trajectory import coordinate_table, trajectory_table, write_coordinates, write_trajectory
from .urdf import urdf_string, write_urdf

__all__ = [
    "RobotHand",
    "coordinate_table",
    "joint_names",
    "mjcf_string",
    "osim_string",
    "robot_hand",
    "trajectory_table",
    "urdf_string",
    "write_coordinates",
    "write_mjcf",
    "write_osim",
    "write_text",
    "write_trajectory",
    "write_urdf",
]
