"""The rest ab/adduction test: does a two-axis joint's ab/adduction vary independently of
flexion between grasp cycles? Condition (4) of accepting a second axis in
:mod:`.twoaxis` (``TwoAxisFit.accepted``, the rule of :func:`.joint.fit_joint`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ..transforms import FloatArray

# The ab/adduction at zero flexion must vary between grasp cycles by more than this many
# times the RMS rotation off the two-axis model (SD over cycles, lower confidence bound).
REST_SPREAD_RATIO = 1.0
REST_SPREAD_CONFIDENCE = 0.95


@dataclass(frozen=True)
class RestAbductionTest:
    """Result of :func:`rest_abduction_test`.

    Attributes
    ----------
    spread_deg : float
        SD over the cycles of the ab/adduction at zero flexion (deg); NaN with fewer
        than two usable cycles.
    low_deg : float
        One-sided lower confidence bound of that SD (deg; NaN as above).
    cycles : int
        Usable cycles (at least three frames and a flexion range).
    passed : bool
        ``low_deg > REST_SPREAD_RATIO * rms_deg``.
    """

    spread_deg: float
    low_deg: float
    cycles: int
    passed: bool


def rest_abduction_test(
    beta: FloatArray,
    theta: FloatArray,
    groups: FloatArray,
    rms_rad: float,
    weights: FloatArray | None = None,
) -> RestAbductionTest:
    """Does the ab/adduction vary independently of flexion between grasp cycles?

    Per cycle ``c`` a weighted least-squares line ``beta = beta0_c + k_c theta`` gives
    ``beta0_c``, the ab/adduction at zero flexion. With ``s`` the SD of the ``G``
    values ``beta0_c`` (one number per cycle: a systematic error repeated within a
    cycle counts once), the one-sided lower confidence bound of the true SD is
    ``s sqrt((G - 1) / chi2_{p, G - 1})`` (normal cycles, ``p`` =
    ``REST_SPREAD_CONFIDENCE``); the test passes when it exceeds
    ``REST_SPREAD_RATIO * rms_rad``. Ab/adduction that follows flexion alike in every
    cycle (coupling, or soft-tissue artefact driven by the finger's flexion) gives
    ``beta0_c`` equal up to noise; without variation independent of flexion the flexion
    axis is not told apart from the hinge axis to first order (``docs/methods.md``).

    Parameters
    ----------
    beta, theta : ndarray, shape (n,)
        Ab/adduction and flexion angles (rad).
    groups : ndarray, shape (n,)
        Grasp cycle of each frame.
    rms_rad : float
        RMS rotation off the two-axis model per frame (rad).
    weights : ndarray, shape (n,), optional
        Frame weights.

    Returns
    -------
    RestAbductionTest
    """
    w = np.ones(beta.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    _, idx = np.unique(np.asarray(groups), return_inverse=True)
    sums = [np.bincount(idx, weights=w * v) for v in (np.ones_like(beta), theta, beta)]
    sw, st, sb = sums
    stt = np.bincount(idx, weights=w * theta * theta)
    stb = np.bincount(idx, weights=w * theta * beta)
    count = np.bincount(idx)
    det = sw * stt - st * st
    ok = (count >= 3) & (det > 1e-12 * np.maximum(sw * stt, 1e-300))
    g = int(ok.sum())
    if g < 2:
        return RestAbductionTest(float("nan"), float("nan"), g, False)
    beta0 = (stt[ok] * sb[ok] - st[ok] * stb[ok]) / det[ok]
    sd = float(np.std(beta0, ddof=1))
    low = sd * float(np.sqrt((g - 1) / chi2.ppf(REST_SPREAD_CONFIDENCE, g - 1)))
    return RestAbductionTest(
        float(np.degrees(sd)), float(np.degrees(low)), g, bool(low > REST_SPREAD_RATIO * rms_rad)
    )
