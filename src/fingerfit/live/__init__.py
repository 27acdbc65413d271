"""Live streaming: sensor poses in, the fitted model's joint angles and fingertips out.

* :mod:`.sources` -- ``replay:FILE[@SPEED]``, ``liberty:PORT[@BAUD]``, ``lsl:NAME``: blocks
  of frames (sensor poses) with their arrival time;
* :mod:`.liberty_serial` -- the Polhemus Liberty serial protocol (commands, binary
  records, resynchronisation);
* :mod:`.outputs` -- LSL outlets, a ROS 2 ``JointState`` publisher over DDS, a rosbag2
  writer and the angles CSV;
* :mod:`.markers` -- a model fitted from skin markers: marker sources, each block's
  angles by the bundle adjustment's inner step;
* :mod:`.stream` -- the loop: source -> :func:`fingerfit.kinematics.compute_kinematics`
  (-> :class:`fingerfit.retarget.Retargeter` with ``--retarget ROBOT``) -> outputs, in two
  lanes (the live outputs latest-wins and never older than ``--max-age``; the files every
  frame), with missing-sensor hold, the ``valid`` channel, the silence watchdog and the
  status line.

pylsl, cyclonedds, rosbags and pyserial are the optional extra ``live``
(``pip install fingerfit[live]``). See ``docs/streaming.md``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from types import ModuleType

#: liblsl's log level unless ``--verbose`` (its loguru levels: 0 info, -1 warnings,
#: -2 errors, -3 fatal errors only).
LSL_LOG_LEVEL = -3


def require(module: str) -> ModuleType:
    """Import an optional dependency of the ``live`` extra (:func:`fingerfit.extras.require`)."""
    from ..extras import require as require_extra

    return require_extra(module, "live", "streaming")


def lsl_config_file() -> Path | None:
    """The configuration file liblsl reads, found as liblsl searches: ``LSLAPICFG``,
    ``lsl_api.cfg`` in the working directory, ``~/lsl_api/lsl_api.cfg``,
    ``/etc/lsl_api/lsl_api.cfg`` (the first readable one); None when there is none."""
    candidates = [os.environ.get("LSLAPICFG") or ""]
    candidates += ["lsl_api.cfg", "~/lsl_api/lsl_api.cfg", "/etc/lsl_api/lsl_api.cfg"]
    for name in candidates:
        if name and os.access(Path(name).expanduser(), os.R_OK):
            return Path(name).expanduser()
    return None


def quiet_lsl(level: int = LSL_LOG_LEVEL) -> bool:
    """Lower liblsl's log level (its ``INFO|`` lines on stderr) before it starts.

    The configuration liblsl would read (:func:`lsl_config_file`) is handed to it as
    content with ``[log] level = level`` added, so its other settings (``[multicast]``,
    ``[lab]``) still apply; a file with its own ``[log]`` section is left alone. Must run
    before any other LSL call (liblsl reads its configuration once).

    Returns
    -------
    bool
        Whether the level was set (False: the file sets its own, or liblsl is too old
        for ``lsl_set_config_content``, < 1.17.7).
    """
    pylsl = require("pylsl")
    path = lsl_config_file()
    try:
        text = path.read_text(errors="replace") if path is not None else ""
    except OSError:
        text = ""
    if re.search(r"^\s*\[log\]", text, re.MULTILINE | re.IGNORECASE):
        return False
    try:
        pylsl.set_config_content(f"{text}\n[log]\nlevel = {level}\n")
    except (NotImplementedError, AttributeError):
        return False
    return True
