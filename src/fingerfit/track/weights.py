"""The cost's weights of a model's chains, from the calibration statistics it carries."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import FingerfitError
from ..model import HandModel
from .chains import Chains
from .solver import Weights


@dataclass(frozen=True)
class TrackOptions:
    """Switches of the tracking cost (``docs/tracking.md``; the defaults are what the
    benchmark measured best out of sample).

    Attributes
    ----------
    bounds : bool
        Soft bounds outside each angle's calibration range.
    bound_fraction : float
        An angle outside its range by this fraction of the range costs as one standard
        deviation of a sensor.
    temporal : bool
        The prior linking consecutive frames: a joint moving ``v dt`` between frames
        ``dt`` apart costs as one standard deviation, ``v`` its calibration speed.
    margin_s : float
        Offline, frames within this many seconds of a frame solved by the model are
        solved with it (the temporal prior's anchors).
    """

    bounds: bool = True
    bound_fraction: float = 0.1
    temporal: bool = True
    margin_s: float = 0.25


def chain_weights(model: HandModel, chains: Chains, options: TrackOptions) -> Weights:
    """:class:`~fingerfit.track.solver.Weights` of ``chains`` from ``model.tracking``.

    Raises
    ------
    FingerfitError
        The model has no calibration statistics (a file written before they existed).
    """
    stats = model.tracking
    if stats is None:
        raise FingerfitError(
            "the model has no tracking statistics (written before fingerfit measured them): "
            "fit it again to solve frames with missing sensors"
        )
    n, L = chains.size, chains.L
    position = np.zeros((n, 3))
    orientation = np.zeros((n, 3))
    low = np.zeros((n, L))
    high = np.zeros((n, L))
    speed = np.full((n, L), np.inf)
    for i, (v, d) in enumerate(chains.keys):
        for s, name in enumerate(chains.sensors[i]):
            spread = stats.sensors[v][name]
            position[i, s] = 1.0 / spread.position_mm**2
            orientation[i, s] = 1.0 / np.radians(spread.orientation_deg) ** 2
        for k, name in enumerate(chains.names[i]):
            a = stats.angles[v][d][name]
            low[i, k], high[i, k] = np.radians(a.low_deg), np.radians(a.high_deg)
            speed[i, k] = np.radians(a.speed_deg_s)
    width = np.maximum(high - low, np.radians(1.0))
    bound = options.bound_fraction * width if options.bounds else np.full((n, L), np.inf)
    if not options.temporal:
        speed = np.full((n, L), np.inf)
    bound = np.where(chains.active, bound, np.inf)
    return Weights(position, orientation, low, high, bound, speed)
