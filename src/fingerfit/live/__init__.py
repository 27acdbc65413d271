"""Live streaming: sensor poses in, the fitted model's joint angles and fingertips out.

* :mod:`.sources` -- ``replay:FILE[@SPEED]``, ``liberty:PORT[@BAUD]``, ``lsl:NAME``: blocks
  of frames (sensor poses) with their arrival time;
* :mod:`.liberty_serial` -- the Polhemus Liberty serial protocol (commands, binary
  records, resynchronisation);
* :mod:`.outputs` -- LSL outlets, a ROS 2 ``JointState`` publisher over DDS, a rosbag2
  writer and the angles CSV;
* :mod:`.stream` -- the loop: source -> :func:`fingerfit.kinematics.compute_kinematics`
  (-> :class:`fingerfit.retarget.Retargeter` with ``--retarget ROBOT``) -> outputs, with
  missing-sensor hold, the ``valid`` channel and the status line.

pylsl, cyclonedds, rosbags and pyserial are the optional extra ``live``
(``pip install fingerfit[live]``). See ``docs/streaming.md``.
"""

from __future__ import annotations

from types import ModuleType


def require(module: str) -> ModuleType:
    """Import an optional dependency of the ``live`` extra (:func:`fingerfit.extras.require`)."""
    from ..extras import require as require_extra

    return require_extra(module, "live", "streaming")
