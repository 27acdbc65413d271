"""Robot export: the individual finger model as URDF and MuJoCo MJCF, and recorded
motion as a joint-angle trajectory with the robot joint names.

* :mod:`.geometry` -- the finger chains in the hand sensor frame (m, rad, kg),
  shared by both writers;
* :mod:`.urdf` -- URDF via yourdfpy;
* :mod:`.mjcf` -- MJCF via ``mujoco.MjSpec``;
* :mod:`.trajectory` -- joint angles (rad) per frame, columns named like the joints;
* :mod:`.files` -- the text files written all-or-nothing.

yourdfpy and mujoco are the optional extra ``robot`` (``pip install fingerfit[robot]``);
they are imported only when a file is written. See ``docs/export.md``.
"""

from __future__ import annotations

from .files import write_text
from .geometry import RobotHand, joint_names, robot_hand
from .mjcf import mjcf_string, write_mjcf
from .trajectory import trajectory_table, write_trajectory
from .urdf import urdf_string, write_urdf

__all__ = [
    "RobotHand",
    "joint_names",
    "mjcf_string",
    "robot_hand",
    "trajectory_table",
    "urdf_string",
    "write_mjcf",
    "write_text",
    "write_trajectory",
    "write_urdf",
]
