"""Pad points from pinch holds: where two touching pulps meet.

During a pinch event (``events.csv`` row whose ``target`` names a digit) the pulps of the
two digits touch, so their contact points coincide in every frame of the hold. Each
digit's pad point ``p_d`` is a fixed point of its distal segment, expressed here in its
**distal sensor's frame** (mm). Every hold frame ``t`` of digits ``a`` and ``b`` gives

    R_a(t) p_a + t_a(t) = R_b(t) p_b + t_b(t)            (tracker frame, mm)

three equations linear in ``(p_a, p_b)``. One hold at a fixed posture fixes only where
``p_b`` lies given ``p_a`` (a 3-dimensional family of coinciding pairs); holds at
different postures (the same digit pinching several others, or pinching in several
postures) fix more. What the holds leave free is taken from each digit's **prior** pad
(the digitised ``<digit>.pad`` landmark, else the pulp geometry of
:func:`fingerfit.model.estimated_pad`) by a small ridge, so that for a single hold the
pads meet half-way between the two priors: two prior points equally deep in their pulps
(or equally far out) meet at the true contact point.

Each event weighs the same whatever its length (rows weighted by ``1/sqrt(frames)``);
the ridge weighs :data:`PRIOR_WEIGHT` per digit against that: small enough that any
direction the holds determine (relative orientations differing by more than a few
degrees) is the holds', large enough to settle what they leave free (tracker noise
turns the sensors by well under a degree).

A pad that ends up on the dorsal side of its distal segment (above the line from the
last joint centre to the nail-edge tip) is not a pulp: that digit keeps its prior, the
fit says so, and the other digits are fitted again to meet it where it is (else a partner
fitted to meet the discarded point stays apart from it by as much, 11 mm on a simulated
MyoHand hand).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..digits import DIGIT_NAMES, DIGITS
from ..kinematics import Kinematics, carry_by_hand, chain_points, compute_kinematics
from ..model import VARIANTS, HandModel, PinchContact
from ..session import HAND_SENSOR, Session, TargetEvent
from ..transforms import FloatArray

#: Candidate ridge weights of each digit's prior pad against one pinch event's mean
#: squared gap; the fit takes the one whose pads best coincide in held-out events.
PRIOR_WEIGHTS = tuple(10.0**k for k in range(-4, 4))
#: The percentile of the model's pad distance over one hold's frames that the hold
#: counts as touching (:class:`fingerfit.model.PinchContact`: the largest over the holds).
CONTACT_PERCENTILE = 95.0


@dataclass(frozen=True)
class PinchHolds:
    """The hold frames of one pair of digits' pinch events.

    Attributes
    ----------
    digits : tuple of (str, str)
        The two digits, in the order of :data:`fingerfit.digits.DIGIT_NAMES` (events
        naming them in either order are the same pair).
    events : int
        Pinch events of the pair with at least one complete frame.
    frames : int
        Hold frames used (both distal sensors present).
    """

    digits: tuple[str, str]
    events: int
    frames: int


@dataclass(frozen=True)
class PadFit:
    """Pads fitted from pinch holds.

    Attributes
    ----------
    local : dict[str, ndarray (3,)]
        Digit -> pad point in its distal sensor's frame (mm).
    pairs : list of PinchHolds
        The pairs of digits whose holds were used.
    gap_mm : dict[tuple[str, str], float]
        Pair -> mean distance between the two fitted pads over its hold frames, both
        carried by their distal sensors (mm): what a fixed point per digit cannot
        explain (the pulps roll, the sensors move on the skin).
    prior_weight : float
        The ridge weight chosen (one of :data:`PRIOR_WEIGHTS`).
    held_out_mm : dict[float, float]
        Candidate weight -> root mean squared gap (mm) of each event's hold when the
        pads are fitted without that event.
    kept_prior : list of str
        Digits whose holds put the pad on the dorsal side; they keep their prior.
    events : list of TargetEvent
        The pinch events used.
    held_out_local : list of dict[str, ndarray (3,)]
        Per event of :attr:`events`, the pads fitted without it at the chosen weight
        (distal sensor frames, mm; digits of :attr:`kept_prior` at their priors).
    """

    local: dict[str, FloatArray]
    pairs: list[PinchHolds]
    gap_mm: dict[tuple[str, str], float]
    prior_weight: float
    held_out_mm: dict[float, float]
    kept_prior: list[str] = field(default_factory=list)
    events: list[TargetEvent] = field(default_factory=list)
    held_out_local: list[dict[str, FloatArray]] = field(default_factory=list)


def _pair(a: str, b: str) -> tuple[str, str]:
    """Two digits in the order of :data:`DIGIT_NAMES`."""
    return (a, b) if DIGIT_NAMES.index(a) <= DIGIT_NAMES.index(b) else (b, a)


def _holds(
    session: Session, digits: set[str]
) -> dict[tuple[str, str], list[tuple[TargetEvent, tuple]]]:
    """Pair (:func:`_pair`) -> per event, the event and ``(R_a (k, 3, 3), t_a (k, 3),
    R_b, t_b)`` over its complete hold frames (tracker frame, mm)."""
    out: dict[tuple[str, str], list] = {}
    for ev in session.events:
        if not ev.is_pinch or ev.finger not in digits or ev.target not in digits:
            continue
        pair = _pair(ev.finger, ev.target)
        rec = session.recording(ev.recording)
        a, b = (rec.pose(DIGITS[d].distal_sensor) for d in pair)
        k = (rec.time >= ev.start) & (rec.time <= ev.end) & a.valid & b.valid
        if k.any():
            out.setdefault(pair, []).append(
                (ev, (a.rotation[k], a.position[k], b.rotation[k], b.position[k]))
            )
    return out


def fit_pads(
    session: Session, prior: dict[str, FloatArray], dorsal: dict[str, tuple[FloatArray, FloatArray]]
) -> PadFit | None:
    """Each pinching digit's pad point from the holds of the session's pinch events.

    Parameters
    ----------
    session : Session
        Its pinch events and their recordings.
    prior : dict[str, ndarray (3,)]
        Digit -> prior pad point in its distal sensor's frame (mm); digits without a prior
        are not fitted (their events are not used).
    dorsal : dict[str, tuple[ndarray (3,), ndarray (3,)]]
        Digit -> (a point on its distal segment's long axis, its dorsal unit direction),
        distal sensor frame (mm, unitless): a pad must lie on the palmar side,
        ``(p - point) . direction < 0``.

    Returns
    -------
    PadFit or None
        ``None`` when the session has no pinch event between two digits with priors.
    """
    holds = _holds(session, set(prior))
    if not holds:
        return None
    names = sorted({d for pair in holds for d in pair})
    col = {d: 3 * i for i, d in enumerate(names)}
    m = 3 * len(names)
    # Each event's mean squared gap as a quadratic form x^T N x - 2 c^T x + e in the
    # stacked pad points x: its frames summed once, the fits below are m x m solves.
    normal, linear, const = [], [], []
    for (a, b), events in holds.items():
        for _, (ra, ta, rb, tb) in events:
            rows = np.zeros((len(ta), 3, m))
            rows[:, :, col[a] : col[a] + 3] = ra
            rows[:, :, col[b] : col[b] + 3] = -rb
            rows = rows.reshape(-1, m)
            rhs = (tb - ta).reshape(-1)
            normal.append(rows.T @ rows / len(ta))
            linear.append(rows.T @ rhs / len(ta))
            const.append(rhs @ rhs / len(ta))
    q = np.concatenate([prior[d] for d in names])
    big_n, big_c = np.sum(normal, axis=0), np.sum(linear, axis=0)

    def solve(weight: float, skip: int | None = None, fixed: tuple[str, ...] = ()) -> FloatArray:
        """The pads minimising the events' gaps and the ridge (``skip``: without that
        event; ``fixed``: those digits held at their priors)."""
        n, c = big_n + weight * np.eye(m), big_c + weight * q
        if skip is not None:
            n, c = n - normal[skip], c - linear[skip]
        held = np.zeros(m, dtype=bool)
        for d in fixed:
            held[col[d] : col[d] + 3] = True
        x = q.copy()
        free = ~held
        x[free] = np.linalg.solve(n[np.ix_(free, free)], c[free] - n[np.ix_(free, held)] @ q[held])
        return x

    def held_out(weight: float) -> float:
        err = 0.0
        for e in range(len(normal)):
            x = solve(weight, e)
            err += x @ normal[e] @ x - 2 * linear[e] @ x + const[e]
        return err / len(normal)

    scores = [held_out(w) for w in PRIOR_WEIGHTS]
    # The strongest prior within rounding of the best held-out gap.
    best = min(scores)
    weight = max(w for w, sc in zip(PRIOR_WEIGHTS, scores, strict=True) if sc <= best + 1e-12)
    x, kept = solve(weight), []
    while True:  # a digit whose pad is dorsal keeps its prior; the others meet it there
        dorsal_now = [
            d
            for d in names
            if d not in kept and (x[col[d] : col[d] + 3] - dorsal[d][0]) @ dorsal[d][1] >= 0
        ]
        if not dorsal_now:
            break
        kept += dorsal_now
        if len(kept) == len(names):
            break
        x = solve(weight, fixed=tuple(kept))
    local = {d: x[col[d] : col[d] + 3] for d in names}
    for d in kept:
        local[d] = np.asarray(prior[d], dtype=float)
    gap = {
        pair: float(
            np.mean(
                np.concatenate(
                    [
                        np.linalg.norm(
                            ra @ local[pair[0]] + ta - (rb @ local[pair[1]] + tb), axis=1
                        )
                        for _, (ra, ta, rb, tb) in events
                    ]
                )
            )
        )
        for pair, events in holds.items()
    }
    pairs = [PinchHolds(p, len(ev), sum(len(e[1][1]) for e in ev)) for p, ev in holds.items()]
    held = {w: float(np.sqrt(max(sc, 0.0))) for w, sc in zip(PRIOR_WEIGHTS, scores, strict=True)}
    without = []
    for e in range(len(normal)):
        xe = solve(weight, e, tuple(kept))
        without.append({d: xe[col[d] : col[d] + 3] for d in names})
    events = [ev for evs in holds.values() for ev, _ in evs]
    return PadFit(local, pairs, gap, weight, held, kept, events, without)


def pinch_pads(session: Session, model: HandModel) -> HandModel:
    """The model with the pads of pinching digits fitted to the session's pinch holds.

    Parameters
    ----------
    session : Session
        Its pinch events (``events.csv``) and their recordings.
    model : HandModel
        The fitted model; its pads (landmark or geometry, ``pad_source``) are the prior.

    Returns
    -------
    HandModel
        The pads of the digits the holds place (:func:`fit_pads`, tracker coordinates at
        the reference posture, mm) with ``pad_source = "pinch"``, and per pair of digits
        a :class:`~fingerfit.model.PinchContact`, per variant: the largest over the pair's
        pinch events of the :data:`CONTACT_PERCENTILE`-th percentile of the model's pad
        distance over the event's frames, with the pads fitted to every event and with
        the pads fitted without that event (one event: the priors) -- how far apart the
        model puts touching pads in a hold the pads were not fitted to, which a recording
        retargeted later is. The model unchanged when the session has no pinch event.
    """
    prior, dorsal = {}, {}
    for d, fm in model.fingers.items():
        if fm.pad is None:
            continue
        p0, r0 = model.reference_poses[DIGITS[d].distal_sensor]
        prior[d] = r0.T @ (fm.pad - p0)
        centre = fm.joints[DIGITS[d].joints[-1]].center
        dorsal[d] = (r0.T @ (centre - p0), r0.T @ fm.frames[fm.segments[-1]].rotation[:, 2])
    fit = fit_pads(session, prior, dorsal)
    if fit is None:
        return model
    fingers = dict(model.fingers)
    for d, p in fit.local.items():
        if d not in fit.kept_prior:
            p0, r0 = model.reference_poses[DIGITS[d].distal_sensor]
            fingers[d] = replace(fingers[d], pad=r0 @ p + p0, pad_source="pinch")
    model = replace(model, fingers=fingers)
    kin_cache: dict[str, Kinematics] = {}
    per_event: dict[tuple[str, str], dict[str, list[float]]] = {}
    for ev, without in zip(fit.events, fit.held_out_local, strict=True):
        pair = _pair(ev.finger, ev.target)
        rec = session.recording(ev.recording)
        if ev.recording not in kin_cache:
            digits = [d for d in model.fingers if d in fit.local]
            kin_cache[ev.recording] = compute_kinematics(model, rec, fingers=digits)
        k = (rec.time >= ev.start) & (rec.time <= ev.end)
        hand = rec.pose(HAND_SENSOR)
        for v in VARIANTS:
            m = kin_cache[ev.recording].motions[v]
            pads = [m[d].pad[k] for d in pair]
            pads += [
                carry_by_hand(
                    model,
                    hand.rotation[k],
                    hand.position[k],
                    chain_points(
                        model.fingers[d],
                        v,
                        {n: x[k] for n, x in m[d].angles.items()},
                        _reference_point(model, d, without[d]),
                    ),
                )
                for d in pair
            ]
            for pa, pb in zip(pads[::2], pads[1::2], strict=True):
                g = np.linalg.norm(pa - pb, axis=1)
                g = g[np.isfinite(g)]
                if g.size:
                    figures = per_event.setdefault(pair, {w: [] for w in VARIANTS})
                    figures[v].append(float(np.percentile(g, CONTACT_PERCENTILE)))
    contacts = []
    for pair in fit.pairs:
        figures = per_event.get(pair.digits, {})
        contact = {v: max(figures.get(v, []), default=float("nan")) for v in VARIANTS}
        if all(np.isfinite(list(contact.values()))):
            contacts.append(PinchContact(pair.digits, pair.events, pair.frames, contact))
    return replace(model, pinch_contacts=tuple(contacts))


def _reference_point(model: HandModel, digit: str, local: FloatArray) -> FloatArray:
    """A point of ``digit``'s distal sensor frame (mm) in tracker coordinates at the
    reference posture."""
    p0, r0 = model.reference_poses[DIGITS[digit].distal_sensor]
    return r0 @ local + p0
