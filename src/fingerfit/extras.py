"""Optional dependencies: import one, or end in one line naming the extra that installs it.

Extras (``pyproject.toml``): ``c3d`` (ezc3d), ``robot`` (yourdfpy, mujoco), ``myohand``
(myo-sim, mujoco: the MyoHand simulator world), ``live``
(pylsl, cyclonedds, rosbags, pyserial), ``retarget`` (mujoco, pinocchio and the robot
hands' wheels), ``view`` (rerun-sdk: ``fingerfit view``), ``stats``, ``cluster``; ``all``
installs every one. Each is imported only when a command needs it.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import FingerfitError


def require(module: str, extra: str, purpose: str, *, field: str | None = None) -> ModuleType:
    """Import an optional dependency.

    Parameters
    ----------
    module : str
        Module name (``mujoco``, ``pylsl``, ``ezc3d``, ...).
    extra : str
        The extra that installs it (``robot``, ``live``, ``c3d``, ``retarget``).
    purpose : str
        What needs it, for the message (``robot export``, ``streaming``, ...).
    field : str, optional
        The option that asked for it, for the message.

    Returns
    -------
    module

    Raises
    ------
    FingerfitError
        ``<purpose> needs the Python package '<module>': pip install fingerfit[<extra>]``.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise FingerfitError(
            f"{purpose} needs the Python package '{module}': pip install fingerfit[{extra}]",
            field=field,
        ) from None
