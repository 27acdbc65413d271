"""Names the command signatures show (choices, defaults), without importing NumPy.

``fingerfit --help`` builds every command's signature; importing the modules these
names come from would import NumPy, SciPy and pandas. ``tests/test_cli_startup.py``
checks that each name here equals the one it mirrors.
"""

from __future__ import annotations

#: :data:`fingerfit.estimate.fit.METHODS` (its keys, in order).
METHODS = ("tang2018", "pooled", "robust", "twoaxis", "rolling")
#: :attr:`fingerfit.estimate.FitOptions.method`.
DEFAULT_METHOD = "twoaxis"
#: :data:`fingerfit.model.VARIANTS`.
VARIANTS = ("user_axis", "orthogonal")
#: :data:`fingerfit.export.geometry.DEFAULT_MARGIN_DEG`.
DEFAULT_MARGIN_DEG = 10.0
#: :data:`fingerfit.retarget.METHODS`.
RETARGET_METHODS = ("tip", "joint")
#: :data:`fingerfit.retarget.maps.BUILTIN` (its keys).
RETARGET_ROBOTS = ("shadow", "allegro")
#: :data:`fingerfit.live.stream.DEFAULT_MAX_AGE_MS` (ms).
DEFAULT_MAX_AGE_MS = 20.0
#: :data:`fingerfit.live.stream.DEFAULT_SILENCE_MS` (ms).
DEFAULT_SILENCE_MS = 50.0
#: :data:`fingerfit.live.sources.DEFAULT_RECONNECT_S` (s).
DEFAULT_RECONNECT_S = 10.0
