"""Plausibility checks (``fingerfit.estimate.plausibility``): bounds, causes, pivot residuals.

The false-positive guard: realistic simulated subjects (all four fingers, several seeds)
and the real Polhemus Liberty recordings are not refused, with the margins quoted in
``docs/plausibility.md``; ``bench/plausibility_conventions.py``, ``bench/plausibility_ranges.py``
and ``bench/plausibility_cost.py`` print those numbers.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.centre import centre_of_rotation
from fingerfit.estimate.fit import reference_poses
from fingerfit.estimate.plausibility import (
    CONVENTION_RATIO,
    PIVOT_FLOOR_MM,
    RECORDING_RESIDUAL_MM,
    Bound,
    PlausibilityError,
    check_model,
    check_session,
    convention_checks,
    convention_problems,
    pivot_residuals,
    recording_checks,
    segment_bound,
    unit_cause,
)
from fingerfit.transforms import matrix_from_quat_wxyz

from ._conventions import as_written
from ._shared_recordings import LIBERTY, LIBERTY_FILES, liberty_pivot_residuals
from .conftest import subject

ALL = ("index", "middle", "ring", "little")


def test_bounds_from_buchholz_fractions() -> None:
    b = segment_bound("index", "proximal")  # 0.245 of a 90-240 mm hand, x0.6 / x1.5
    assert b.lo == pytest.approx(0.6 * 0.245 * 90) and b.hi == pytest.approx(1.5 * 0.245 * 240)
    for digit, seg in (("thumb", "metacarpal"), ("thumb", "distal"), ("little", "middle")):
        assert 0 < segment_bound(digit, seg).lo < segment_bound(digit, seg).hi
    # X-ray mean index bones (39.8 / 22.4 / 15.8 mm) +- 3 SD lie inside.
    for seg, mean, sd in (("proximal", 39.8, 4.9), ("middle", 22.4, 2.5), ("distal", 15.8, 2.3)):
        assert segment_bound("index", seg).contains(mean - 3 * sd)
        assert segment_bound("index", seg).contains(mean + 3 * sd)


@pytest.mark.parametrize(
    ("value", "declared", "cause"),
    [
        (39_800.0, "m", "millimetres declared as metres"),
        (0.0398, "mm", "metres declared as millimetres"),
        (398.0, "cm", "millimetres declared as centimetres"),
        (4.0, "mm", "centimetres declared as millimetres"),
        (1011.0, "in", "millimetres declared as inches"),
        (1.57, "mm", "inches declared as millimetres"),
    ],
)
def test_unit_cause_from_the_ratio(value, declared, cause) -> None:
    assert unit_cause(value, segment_bound("index", "proximal"), declared).endswith(cause)


def test_unit_cause_says_when_no_unit_explains_it() -> None:
    assert "no unit mistake" in unit_cause(1e9, Bound(10, 20, ""), "mm")


def test_pivot_residual_of_a_known_centre() -> None:
    rng = np.random.default_rng(3)
    q = rng.normal(size=(300, 4))
    r = matrix_from_quat_wxyz(q)
    cp, cc = np.array([10.0, -5.0, 40.0]), np.array([-20.0, 3.0, 1.0])
    t = cp - r @ cc
    fit = centre_of_rotation(r, t + rng.normal(0, 0.2, t.shape))
    assert np.allclose(fit.parent_point, cp, atol=0.1)
    assert np.allclose(fit.child_point, cc, atol=0.1)
    assert fit.rms_mm == pytest.approx(0.2 * np.sqrt(3), rel=0.1)


@pytest.mark.parametrize("seed", [0, 2, 5])
def test_realistic_subjects_pass_every_check(seed: int) -> None:
    s = subject("realistic", seed, ALL).session
    ref = reference_poses(s)
    assert check_session(s, ALL, ref) == []
    checks = convention_checks(s, ALL)
    assert len(checks) == 12
    for c in checks:
        read = c.residual_mm["as read"]
        assert read < 1.0 < PIVOT_FLOOR_MM  # measured 0.30-0.89 mm on seeds 0-9
        others = [v for k, v in c.residual_mm.items() if k != "as read"]
        assert min(others) > 2.5 * read  # measured >= 6.8x on seeds 0-9


def test_realistic_four_fingers_fit_without_warnings() -> None:
    s = subject("realistic", 2, ALL).session
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no plausibility or quality warning
        model = fit_session(s)
    assert model.warnings == ()
    assert check_model(model, s) == []
    for rec in [*s.test, *s.targets]:
        for c in recording_checks(model, rec):
            assert c.residual_mm["as read"] < 0.5 * RECORDING_RESIDUAL_MM
            assert c.scale == pytest.approx(1.0, abs=0.06)


def test_landmark_to_centre_one_joint_is_a_fit_not_a_unit_mistake() -> None:
    """A fitted axis may pass at the skin; one far landmark is not a unit mistake; every
    landmark of a digit off by one unit ratio is."""
    from dataclasses import replace

    s = subject("realistic", 2, ("index", "ring")).session
    model = fit_session(s)
    ring = model.fingers["ring"].joints
    dip = ring["dip"].center

    def moved(landmarks: dict, session=s):
        return replace(session, landmarks={**session.landmarks, **landmarks})

    # 0.3 mm from the centre: a DIP axis located 4 mm dorsal of the true one (a simulated
    # 100-subject cohort had one, refused before as "centimetres declared as millimetres").
    at_skin = moved({"ring.dip": dip + np.array([0.0, 0.0, 0.3])})
    assert check_model(model, at_skin) == []
    far = moved({"ring.dip": dip + np.array([0.0, 40.0, 0.0])})
    (problem,) = check_model(model, far)
    assert problem.message == (
        "ring dip landmark-to-centre distance 40 mm (plausible < 30 mm): the landmark and "
        "the fitted axis disagree: check that the landmark was digitised on this joint, and "
        "the joint's axis quality"
    )
    # Every ring landmark 10x as far from its centre, in a session declared in centimetres
    # (read x10): millimetres declared as centimetres, named for each joint.
    ten = moved({f"ring.{j}": jm.center + 10 * (s.landmarks[f"ring.{j}"] - jm.center)
                 for j, jm in ring.items()})  # fmt: skip
    problems = check_model(replace(model, session_units="cm"), ten)
    assert [p.message.split(" mm ")[0].rsplit(" ", 1)[0] for p in problems] == [
        f"ring {j} landmark-to-centre distance" for j in ring
    ]
    assert all(p.message.endswith("millimetres declared as centimetres") for p in problems)


@pytest.mark.parametrize(("kind", "named"), [("conjugated", "conjugated"), ("xyzw", "xyzw")])
def test_wrong_convention_named_for_every_joint(kind: str, named: str) -> None:
    s = subject("realistic", 2).session
    for j, (p, c) in {
        "mp": ("hand", "index.proximal"),
        "dip": ("index.middle", "index.distal"),
    }.items():
        res, _ = pivot_residuals(
            as_written(s.grasp[0].pose(p), kind), as_written(s.grasp[0].pose(c), kind)
        )
        assert min(res, key=res.get) == named, (j, res)
        assert res[named] < CONVENTION_RATIO * res["as read"]


def test_forced_model_keeps_the_warning() -> None:
    s = subject("realistic", 2).session

    def broken(rec):
        poses = {k: as_written(v, "conjugated") for k, v in rec.poses.items()}
        return type(rec)(rec.name, rec.time, poses)

    bad = type(s)(
        **{**s.__dict__, "reference": broken(s.reference), "grasp": [broken(g) for g in s.grasp]}
    )
    with pytest.raises(
        PlausibilityError, match=r"index (mp|pip|dip): .*pivot residual .*conjugated"
    ):
        fit_session(bad)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        model = fit_session(bad, FitOptions(force=True))
    assert any("conjugated" in w for w in model.warnings)


@pytest.mark.skipif(
    not (LIBERTY / LIBERTY_FILES[0]).is_file(), reason=f"no Liberty data in {LIBERTY}"
)
def test_real_liberty_recordings_read_as_declared() -> None:
    """No other quaternion reading explains the real recordings better (no refusal)."""
    from fingerfit.estimate.plausibility import PivotCheck

    for name, res in liberty_pivot_residuals().items():
        assert min(res, key=res.get) == "as read", (name, res)
        # Pooled rule of convention_problems: no alternative below half the as-read residual.
        check = PivotCheck("index", "mp", res, float("nan"), 1)
        problems = convention_problems([check])
        assert all("look" not in p.message for p in problems), problems


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ("index.middle", "index.distal"),  # neighbours: plausible everywhere else
        ("thumb.proximal", "thumb.distal"),
        ("thumb.metacarpal", "thumb.proximal"),
    ],
)
def test_swapped_segment_sensors_are_named(a: str, b: str) -> None:
    from dataclasses import replace

    from fingerfit.session import Recording

    def swap(rec: Recording) -> Recording:
        poses = dict(rec.poses)
        poses[a], poses[b] = poses[b], poses[a]
        return Recording(rec.name, rec.time, poses, rec.notes)

    s = subject("realistic", 3, ("thumb", "index")).session
    wrong = replace(s, reference=swap(s.reference), grasp=[swap(r) for r in s.grasp])
    digit = a.split(".")[0]
    with pytest.raises(
        PlausibilityError, match=rf"^{digit} sensors look swapped: {a} on the .*{b} on the "
    ):
        fit_session(wrong)
