"""Smooth weighting of weakly determined parameters against their prior mean.

Some parameters of the two-axis MP joint are seen by the data only at second order
(the tilt of the ab/adduction axis towards the flexion axis, the offset between the
two axes). With realistic errors their least-squares values wander along a nearly
flat valley (``docs/methods.md``, "Numerical stability"). Each is given the data's
share ``1 / (1 + (sd / half)^6)`` of the weight, ``sd`` being its cluster-robust
(per grasp cycle) SD from the data alone: exact data (``sd = 0``) determine it fully,
data that do not see it hold it at the prior mean (perpendicular, intersecting axes),
with a smooth passage in between instead of a threshold that rounding could cross.
"""

from __future__ import annotations

import numpy as np

MIN_DATA_SHARE = 1e-6  # below this share the prior mean is used exactly


def data_share(sd: float, half: float) -> float:
    """Weight ``1 / (1 + (sd / half)^6)`` (0-1) of the data against the prior mean.

    Parameters
    ----------
    sd : float
        Cluster-robust SD of a weakly determined parameter from the data alone.
    half : float
        The SD at which data and prior weigh equally (same units as ``sd``).

    Returns
    -------
    float
        1 for ``sd = 0``, 0.5 at ``sd = half``, 0 for a non-finite ``sd``.
    """
    if not np.isfinite(sd):
        return 0.0
    return float(1.0 / (1.0 + (sd / half) ** 6))


__all__ = ["MIN_DATA_SHARE", "data_share"]
