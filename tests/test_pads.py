"""Pads from pinch holds (fingerfit.estimate.pads): where two touching pulps meet.

The truth is known in two ways: synthetic holds of two rigid bodies whose chosen points
coincide (the fit must find those points), and simulated thumb + index subjects whose
``<digit>.pad`` landmarks were not digitised (the fit starts from the pulp geometry, which
puts touching pads 6-8 mm apart).
"""

from __future__ import annotations

import functools
import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.digits import DIGITS
from fingerfit.errors import FingerfitError
from fingerfit.estimate import fit_session
from fingerfit.estimate.pads import fit_pads
from fingerfit.evaluate.pinch import evaluate_pinches
from fingerfit.evaluate.truth import load_truth
from fingerfit.io.sessiondir import load_session
from fingerfit.model import load_model, save_model
from fingerfit.session import PoseSeries, Recording, Session, TargetEvent
from fingerfit.simulate import write_subject

from .conftest import subject

THUMB, INDEX = DIGITS["thumb"].distal_sensor, DIGITS["index"].distal_sensor


def _holds_session(rotations: list[Rotation], pa: np.ndarray, pb: np.ndarray) -> Session:
    """One recording, one pinch event per relative orientation: the index's distal sensor
    turned by ``rotations[e]`` against the thumb's, placed so that the thumb's point
    ``pa`` and the index's point ``pb`` (sensor frames, mm) coincide; 20 frames per hold,
    the whole hand drifting."""
    rng = np.random.default_rng(4)
    pos = {THUMB: [], INDEX: []}
    rot = {THUMB: [], INDEX: []}
    events = []
    for e, rel in enumerate(rotations):
        for _ in range(20):
            base = Rotation.random(random_state=rng)
            ra, rb = base, base * rel
            ta = rng.normal(0, 50, 3)
            tb = ra.apply(pa) + ta - rb.apply(pb)
            pos[THUMB].append(ta), pos[INDEX].append(tb)
            rot[THUMB].append(ra.as_matrix()), rot[INDEX].append(rb.as_matrix())
        events.append(TargetEvent("pinch.csv", "thumb", "index", e * 20 / 100, (e * 20 + 19) / 100))
    n = 20 * len(rotations)
    rec = Recording(
        "pinch.csv",
        np.arange(n) / 100,
        {s: PoseSeries(np.array(pos[s]), np.array(rot[s])) for s in (THUMB, INDEX)},
    )
    return Session(
        "S", "right", "mm", 100.0, ["thumb", "index"], rec, [], {}, targets=[rec], events=events
    )


DORSAL = {d: (np.zeros(3), np.array([0.0, 0.0, 1.0])) for d in ("thumb", "index")}


def test_holds_in_several_postures_find_the_touching_points() -> None:
    pa, pb = np.array([3.0, -2.0, -8.0]), np.array([-4.0, 1.0, -6.0])
    rels = [Rotation.from_rotvec(v) for v in ([0, 0, 0], [0.5, 0, 0], [0, 0.6, 0.2])]
    session = _holds_session(rels, pa, pb)
    prior = {"thumb": pa + np.array([4.0, -3.0, 2.0]), "index": pb + np.array([-3.0, 3.0, -2.0])}
    fit = fit_pads(session, prior, DORSAL)
    assert fit is not None
    np.testing.assert_allclose(fit.local["thumb"], pa, atol=0.05)
    np.testing.assert_allclose(fit.local["index"], pb, atol=0.05)
    assert fit.gap_mm[("thumb", "index")] < 0.01
    assert fit.pairs[0].events == 3 and fit.pairs[0].frames == 60
    assert fit.prior_weight == min(fit.held_out_mm)  # exact holds: the weakest prior


def test_one_hold_meets_half_way_between_the_priors() -> None:
    """One posture fixes only where one pad lies given the other: the pads then meet
    half-way between the two priors (two pulp points equally deep meet at the contact)."""
    pa, pb = np.array([0.0, 0.0, -8.0]), np.array([0.0, 0.0, -8.0])
    rel = Rotation.from_rotvec([np.pi, 0, 0])  # pulps facing each other
    session = _holds_session([rel], pa, pb)
    deep = np.array([0.0, 0.0, 3.0])  # both priors 3 mm inside their pulps
    fit = fit_pads(session, {"thumb": pa + deep, "index": pb + deep}, DORSAL)
    assert fit is not None
    np.testing.assert_allclose(fit.local["thumb"], pa, atol=0.05)
    np.testing.assert_allclose(fit.local["index"], pb, atol=0.05)


def test_a_pad_on_the_dorsal_side_keeps_its_prior_and_its_partner_meets_it() -> None:
    """The holds put the thumb's point on its nail side: the thumb keeps its prior, and the
    index is fitted again to meet that prior (mean gap 4.5 mm over the three postures),
    not left where it met the discarded point (13 mm from the thumb's prior in every
    frame)."""
    pa, pb = np.array([0.0, 0.0, 8.0]), np.array([0.0, 0.0, -8.0])  # thumb's above: nail
    rels = [Rotation.from_rotvec(v) for v in ([0, 0, 0], [0.5, 0, 0], [0, 0.6, 0.2])]
    prior = {"thumb": np.array([0.0, 0.0, -5.0]), "index": pb}
    fit = fit_pads(_holds_session(rels, pa, pb), prior, DORSAL)
    assert fit is not None and fit.kept_prior == ["thumb"]
    np.testing.assert_array_equal(fit.local["thumb"], prior["thumb"])
    assert fit.gap_mm[("thumb", "index")] < 5.0, fit.gap_mm


def test_no_pinch_event_no_fit() -> None:
    session = _holds_session([Rotation.identity()], np.zeros(3), np.zeros(3))
    session.events = [replace(e, target="t1") for e in session.events]
    assert fit_pads(session, {"thumb": np.zeros(3), "index": np.zeros(3)}, DORSAL) is None


@functools.cache
def _without_pad_landmarks(seed: int, root: str):
    path = write_subject(subject("realistic", seed, ("thumb", "index")), Path(root) / str(seed))
    session, truth = load_session(path), load_truth(path)
    session.landmarks = {k: v for k, v in session.landmarks.items() if not k.endswith(".pad")}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(session)
    return session, truth, model


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> str:
    return str(tmp_path_factory.mktemp("pads"))


def test_pads_from_pinch_holds_touch_where_the_geometry_pads_do_not(root) -> None:
    """Without digitised pads the pulp geometry puts the model's touching pads 6-8 mm
    apart (measured 6.3-7.8 mm mean on seeds 2-4); fitted to the pinch holds they are
    1.7-2.9 mm apart, the rest being the fitted model's own error (the pads carried by
    the distal sensors meet to < 1 mm)."""
    session, truth, model = _without_pad_landmarks(3, root)
    for d in ("thumb", "index"):
        assert model.fingers[d].pad_source == "pinch"
    contact = model.pinch_contact("index", "thumb")
    assert contact is not None and contact.events == 4
    pin = evaluate_pinches(model, session, truth)
    got = pin.groupby("source")["pad_gap_mm"].mean()
    assert got["reference"] < 1.0
    assert got["user_axis"] < 2.5
    geometry = replace(
        model,
        fingers={
            d: replace(f, pad=_geometry_pad(model, session, d)) for d, f in model.fingers.items()
        },
        pinch_contacts=(),
    )
    before = evaluate_pinches(geometry, session, truth).groupby("source")["pad_gap_mm"].mean()
    assert before["user_axis"] > 5.0 and got["user_axis"] < 0.4 * before["user_axis"]
    # The pinch term engages at the distance the person's own holds show.
    assert contact.contact_mm["user_axis"] < 4.0


def _geometry_pad(model, session, digit: str) -> np.ndarray:
    """The pad ``fit_session`` gives without pinch events and without a pad landmark."""
    from fingerfit.model import estimated_pad

    fm = model.fingers[digit]
    last = list(fm.joints)[-1]
    depth = float(np.linalg.norm(session.landmark(f"{digit}.{last}") - fm.joints[last].center))
    return estimated_pad(fm, 2.0 * depth)


def test_model_file_keeps_pad_sources_and_pinch_contacts(root, tmp_path) -> None:
    _session, _truth, model = _without_pad_landmarks(3, root)
    path = save_model(model, tmp_path / "model.json")
    back = load_model(path)
    assert back.pinch_contacts == model.pinch_contacts
    assert {d: f.pad_source for d, f in back.fingers.items()} == {
        "thumb": "pinch",
        "index": "pinch",
    }
    doc = json.loads(path.read_text())
    doc["pinch_contacts"][0]["contact_mm"]["user_axis"] = -1
    path.write_text(json.dumps(doc))
    with pytest.raises(FingerfitError, match=r"pinch_contacts\[0\]\.contact_mm\.user_axis"):
        load_model(path)
    doc["pinch_contacts"][0]["contact_mm"]["user_axis"] = 1.0
    doc["pinch_contacts"][0]["digits"] = ["thumb", "ring"]
    path.write_text(json.dumps(doc))
    with pytest.raises(FingerfitError, match=r"pinch_contacts\[0\]\.digits"):
        load_model(path)
    doc["pinch_contacts"][0]["digits"] = ["thumb", "index"]
    doc["fingers"]["thumb"]["pad_source"] = "guess"
    path.write_text(json.dumps(doc))
    with pytest.raises(FingerfitError, match=r"fingers\.thumb\.pad_source"):
        load_model(path)
