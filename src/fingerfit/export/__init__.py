"""Robot export: the individual finger model as URDF and MuJoCo MJCF, and recorded
motion as a joint-angle trajectory with the robot joint names.

* :mod:`.geometry` -- the finger chains in the hand sensor frame (m, rad, kg),
  shared by both writers;
* :mod:`.urdf` -- URDF via yourdfpy;
* :mod:`.mjcf` -- MJCF via ``mujoco.MjSpec``;
* :mod:`.trajectory` -- joint angles (rad) per frame, columns named like the joints.

yourdfpy and mujoco are the optional extra ``robot`` (``pip install fingerfit[robot]``);
they are imported only when a file is written. See ``docs/export.md``.
"""

from __future__ import annotations

from pathlib import Path

from ..io.atomic import write_files


def write_text(files: dict[Path, str], *, overwrite: bool = True) -> list[Path]:
    """Write several text files all-or-nothing (:func:`fingerfit.io.atomic.write_files`).

    Parameters
    ----------
    files : dict[Path, str]
        Path -> complete text (written UTF-8 with ``\n`` line ends).
    overwrite : bool
        Whether existing files may be replaced (``--overwrite``).

    Returns
    -------
    list of Path

    Raises
    ------
    FingerfitError
        Naming the path that could not or must not be written.
    """
    return write_files(files, overwrite=overwrite)


from .geometry import RobotHand, joint_names, robot_hand  # noqa: E402
from .mjcf import mjcf_string, write_mjcf  # noqa: E402
from .trajectory import trajectory_table, write_trajectory  # noqa: E402
from .urdf import urdf_string, write_urdf  # noqa: E402

__all__ = [
    "RobotHand",
    "joint_names",
    "mjcf_string",
    "robot_hand",
    "trajectory_table",
    "urdf_string",
    "write_mjcf",
    "write_trajectory",
    "write_urdf",
]
