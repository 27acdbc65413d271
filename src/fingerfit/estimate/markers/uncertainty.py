"""How far a marker fit's lines may be from the truth: the camera's noise and the skin's slide.

A fit of fixed marker places (:func:`.bundle.adjust` without slides) reads a marker's
slide over the bone as motion of the bone: the lines tilt and shift toward what absorbs
it. That error does not shrink with more frames (every cycle repeats it), and it is far
larger than the noise's, so ``sigma^2 S^-1`` alone (:func:`.bundle.line_covariance`)
is no honest uncertainty.

The slide is modelled as each marker's place moving linearly with the flexion angle of
its segment's proximal joint, ``u + s theta`` (:func:`.chain.places`; the hand's
markers with the digit's first joint), with ``s`` a random effect: in each marker's
segment frame (along the bone, across it along the joint's axis, and dorsal; the hand's
markers in the first segment's) its three components have variances ``tau^2``
(mm^2/rad^2), one set for the digit's markers and one for the hand's. Near the fit
(``s = 0``) the markers are linear in the unknowns, ``r = J_g dg + J_s s + e`` with
``e`` the camera noise (variance ``sigma^2`` per coordinate, the fit's residual
variance), and with the frames' unknowns eliminated (:func:`.normal.reduced`, the
information ``S`` over the lines and places ``g`` and the slides ``s``):

1. ``tau^2`` is the maximum of the marginal likelihood, by expectation-maximisation:
   with the posterior of ``s`` (mean ``m``, covariance ``V``, precision
   ``S / sigma^2 + T^-1`` reduced to ``s``) the update is ``tau_k^2 = mean_i (m_ik^2 +
   V_ikk)`` over the components of variance ``k``. What the slide leaves in the
   residuals is the evidence; what the fit absorbed is inferred from it through the
   same variances.
2. Where the recording determines a variance poorly, a larger one is used: its mean
   under the likelihood (:func:`_expected_variance`, the spread from the Fisher
   information, :func:`_scale_covariance`).
3. The fit's error is the noise's and the slide's, ``dg = S_gg^-1 (b_noise - S_gs s)``,
   so its covariance is ``S_gg^-1 (sigma^2 S_gg + S_gs T S_sg) S_gg^-1``.

So the slide's scale comes from the recording itself, not from a constant: a hand whose
skin slides little gets narrow intervals, one whose skin slides much wide ones. What
the linear law does not hold (a slide with the joint beyond the segment, or with the
angle's square) is measured, not modelled (``docs/markers.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import ndtr

from ...transforms import FloatArray, unit
from .bundle import BundleResult
from .chain import SLIDE_PRIOR, HandFrames, Structure, observed
from .normal import Normal, frame_columns, normal_equations, reduced, symmetric_pinv
from .observe import DigitMarkers

#: EM iterations of the slide's variances stop when none changes by more than this
#: fraction, or after :data:`EM_MAX_ITER`.
EM_TOL = 1e-6
EM_MAX_ITER = 500


@dataclass(frozen=True)
class SlideUncertainty:
    """The lines' uncertainty with the skin's slide.

    Attributes
    ----------
    covariance : ndarray, shape (L, 4, 4)
        Each line's two direction (rad) and two point (mm) unknowns (as
        :func:`.bundle.line_covariance`): the camera noise and the slide. NaN where the
        line was held.
    slide_sd : ndarray, shape (6,)
        The slide's SD along the bone, across it and dorsal (mm/rad) of the digit's
        markers, then of the hand's (in the first segment's frame): the maximum of the
        marginal likelihood.
    used_sd : ndarray, shape (6,)
        The SD the covariance assumes (mm/rad): the slide's variance expected given the
        recording (:func:`_expected_variance`), at least ``slide_sd``; larger where the
        recording determines the slide's scale poorly.
    iterations : int
        EM iterations.
    """

    covariance: FloatArray
    slide_sd: FloatArray
    used_sd: FloatArray
    iterations: int


def marker_frames(data: DigitMarkers, structure: Structure, result: BundleResult) -> FloatArray:
    """Each marker's segment frame ``(M, 3, 3)`` (columns: along the bone, along its
    proximal flexion axis, dorsal), tracker coordinates at the reference posture.

    The bone runs from the segment's proximal flexion line to the next one (the distal
    segment: its parent's direction), perpendicular to the axis.
    """
    assert structure.flexion is not None
    axes, centres = result.lines.axis, result.lines.centre
    n_seg = int(data.segment.max()) + 1
    frames = np.zeros((n_seg, 3, 3))
    bone = None
    for s in range(n_seg):
        k = structure.flexion[s]
        a = axes[k]
        if s + 1 < n_seg:
            bone = centres[structure.flexion[s + 1]] - centres[k]
        assert bone is not None
        x = unit(bone - (bone @ a) * a)
        frames[s] = np.column_stack([x, a, np.cross(x, a)])
    return frames[data.segment]


def slide_uncertainty(
    data: DigitMarkers, structure: Structure, result: BundleResult
) -> SlideUncertainty:
    """The uncertainty of a fixed-place fit's lines with its markers' slide.

    Parameters
    ----------
    data : DigitMarkers
    structure : Structure
        With ``flexion`` (each segment's proximal flexion level).
    result : BundleResult
        A converged fit without slides (``result.slide is None``).

    Returns
    -------
    SlideUncertainty
    """
    assert result.slide is None and structure.flexion is not None
    M, H = len(data.labels), len(data.hand_shape)
    L = structure.levels
    G = result.free.size  # 4 L + 3 M
    free = np.concatenate([result.free, np.ones(3 * M, dtype=bool)])
    sliding = replace(result.point, slide=np.zeros((M, 3)))
    normal, _ = normal_equations(data, structure, sliding, free)
    ng = int(result.free.sum())
    normal.gg[np.arange(ng, ng + 3 * M), np.arange(ng, ng + 3 * M)] -= 1.0 / SLIDE_PRIOR**2
    theta = result.q[structure.flexion[0]]  # the hand's markers slide with the first joint
    normal = _with_hand_slides(normal, data, result.hand, theta)
    s, wqg = reduced(normal)
    nk = normal.bq.size
    b = normal.bg - wqg.reshape(nk, -1).T @ normal.bq.reshape(nk)
    n, k = normal.qq.shape[:2]
    dof = max(normal.count - n * k - ng, 1)
    sigma2 = result.cost / dof
    # The slides in each marker's frame (the hand's: the first segment's): s = R s_local.
    rot = marker_frames(data, structure, result)  # (M, 3, 3)
    rot = np.concatenate([rot, np.broadcast_to(rot[0], (H, 3, 3))])
    tr = np.eye(ng + 3 * (M + H))
    for i in range(M + H):
        tr[ng + 3 * i : ng + 3 * i + 3, ng + 3 * i : ng + 3 * i + 3] = rot[i]
    info = tr.T @ s @ tr / sigma2
    grad = tr.T @ b / sigma2
    group = np.repeat(np.r_[np.zeros(M, int), np.ones(H, int)], 3) * 3 + np.tile(
        np.arange(3), M + H
    )
    tau2 = np.ones(6)
    it = 0
    for it in range(1, EM_MAX_ITER + 1):  # noqa: B007 (the count is returned)
        prec = info.copy()
        prec[ng:, ng:] += np.diag(1.0 / tau2[group])
        cov = symmetric_pinv(prec)[0]
        mean = cov @ grad
        second = mean[ng:] ** 2 + np.diag(cov)[ng:]
        new = np.maximum(np.bincount(group, second, 6) / np.bincount(group, minlength=6), 1e-12)
        done = np.all(np.abs(new - tau2) <= EM_TOL * tau2)
        tau2 = new
        if done:
            break
    sgg, sgs = s[:ng, :ng], s[:ng, ng:]
    inv = symmetric_pinv(sgg)[0]
    # The slides' information with the lines and places eliminated (units of sigma^2).
    w = info[ng:, ng:] - info[ng:, :ng] @ (sigma2 * inv) @ info[:ng, ng:]
    sd = np.sqrt(np.diag(_scale_covariance((w + w.T) / 2, tau2, group)))
    used = _expected_variance(tau2, sd)
    slide_cov = tr[ng:, ng:] @ np.diag(used[group]) @ tr[ng:, ng:].T
    cov_g = inv @ (sigma2 * sgg + sgs @ slide_cov @ sgs.T) @ inv
    full = np.full((G, G), np.nan)
    idx = np.flatnonzero(result.free)
    full[np.ix_(idx, idx)] = cov_g
    lines = np.stack([full[4 * j : 4 * j + 4, 4 * j : 4 * j + 4] for j in range(L)])
    return SlideUncertainty(lines, np.sqrt(tau2), np.sqrt(used), it)


def _with_hand_slides(
    normal: Normal, data: DigitMarkers, hand: HandFrames, theta: FloatArray
) -> Normal:
    """``normal`` with each hand marker's slide ``(H, 3)`` (mm/rad) appended to the global
    unknowns: the marker's place in the hand moves by ``s theta`` (``theta (n,)`` rad), so
    its column in frame ``t`` is ``theta_t I`` where it is seen."""
    H, n = len(data.hand_shape), data.frames
    _, yh, pivot = observed(data, hand)
    seen = np.repeat(data.hand_present.T, 3, axis=1)  # (n, 3 H)
    col = seen * theta[:, None]  # the diagonal of each frame's (3 H, 3 H) block
    jh = frame_columns(yh, pivot).reshape(n, 3 * H, 6)  # the frame unknowns' columns
    K = normal.qq.shape[1]
    qh = np.zeros((n, K, 3 * H))
    qh[:, K - 6 :, :] = (jh * col[..., None]).transpose(0, 2, 1)
    rh = (yh - data.hand_shape[..., None]) * data.hand_present[:, None]
    rh = rh.transpose(2, 0, 1).reshape(n, 3 * H)
    G = normal.gg.shape[0]
    gg = np.zeros((G + 3 * H, G + 3 * H))
    gg[:G, :G] = normal.gg
    gg[G:, G:] = np.diag((col * col).sum(axis=0))
    return Normal(
        normal.qq,
        np.concatenate([normal.qg, qh], axis=2),
        gg,
        normal.bq,
        np.concatenate([normal.bg, (col * rh).sum(axis=0)]),
        normal.cost,
        normal.count,
    )


def _scale_covariance(w: FloatArray, tau2: FloatArray, group: np.ndarray) -> FloatArray:
    """The covariance ``(6, 6)`` of the estimated variances ``tau2`` (mm^4/rad^4): the
    inverse Fisher information of the marginal likelihood.

    With the lines and places eliminated, the slides' information is ``W`` and their
    gradient ``b ~ N(0, W + W D W)`` (``D`` the slides' prior covariance, all in units of
    ``sigma^2``); ``I_kl = tr(P W E_k W P W E_l W) / 2``, ``P`` the pseudo-inverse of that
    covariance and ``E_k`` the selector of the components of variance ``k`` (``group``).
    """
    cov = w + w @ np.diag(tau2[group]) @ w
    p = symmetric_pinv(cov)[0]
    grads = [p @ w @ np.diag((group == k).astype(float)) @ w for k in range(tau2.size)]
    fisher = np.array([[np.trace(a @ b) / 2 for b in grads] for a in grads])
    return symmetric_pinv(fisher)[0]


def _expected_variance(tau2: FloatArray, sd: FloatArray) -> FloatArray:
    """The slide's variances ``(6,)`` expected given the recording: the mean of a normal
    likelihood about the estimate ``tau2`` with SD ``sd``, truncated to positive
    variances (a flat prior on the variance). ``tau2`` where the recording determines
    it well, above it where it does not."""
    a = tau2 / np.maximum(sd, 1e-300)
    pdf = np.exp(-0.5 * a * a) / np.sqrt(2 * np.pi)
    return tau2 + sd * pdf / np.maximum(ndtr(a), 1e-300)
