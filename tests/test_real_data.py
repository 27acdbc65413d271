"""Real-data validation of the readers (``../shared/data``; skipped when absent).

* Polhemus Liberty wide-CSV logs: repeated rows found and dropped; the hinge axis of
  sensor 2 about sensor 1 is the same in both halves of each recording and agrees
  with the dominant axis of the relative rotations.
* Optotrak C3D arm trials: segment poses from marker clusters; the medial epicondyle
  probed in one trial reappears where the file's own reconstruction puts it; elbow
  axes (single hinge and two-axis model) compared with the epicondyle line.

``bench/liberty_hinge.py`` and ``bench/elbow_axes.py`` print the numbers quoted in
``docs/readers.md`` (from ``tests/_shared_recordings.py``, shared with these tests).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.io.hygiene import find_jumps

from ._axes import axis_angle_deg, dominant_axis, relative_rotations, sara_axis, two_axis_fit, unit
from ._shared_recordings import LIBERTY, LIBERTY_FILES, OPTOTRAK, elbow, liberty

needs_liberty = pytest.mark.skipif(
    not all((LIBERTY / f).is_file() for f in LIBERTY_FILES),
    reason=f"real Polhemus Liberty recordings not found in {LIBERTY}",
)
needs_optotrak = pytest.mark.skipif(
    not (OPTOTRAK / "kinematics_racing_propulsion.c3d").is_file(),
    reason=f"real Optotrak C3D trials not found in {OPTOTRAK}",
)

#: The hand-held rotations are not a jig: the axis may wander this much between halves.
HALVES_TOLERANCE_DEG = 6.0
#: SARA-style axis vs dominant rotation direction of the relative rotations.
DOMINANT_TOLERANCE_DEG = 0.5
#: Rows repeated exactly, per file (measured; about one in three).
DUPLICATES = {"rotate-90deg-x.csv": 1020, "rotate-90deg-y.csv": 858, "rotate-90deg-z.csv": 906}


@needs_liberty
@pytest.mark.parametrize("name", LIBERTY_FILES)
def test_liberty_repeated_rows_dropped(name) -> None:
    r = liberty(name)
    assert r["duplicates"] == DUPLICATES[name]
    assert 0.30 < r["duplicates"] / r["rows"] < 0.36  # about one row in three
    rec = r["recording"]
    # Each remaining row updates one sensor: frames = rows / 3 (+1 for the first row).
    assert rec.n_frames == (r["rows"] - r["duplicates"]) // 2 + 1
    assert rec.poses["index.proximal"].valid.all()


@needs_liberty
@pytest.mark.parametrize("name", LIBERTY_FILES)
def test_liberty_hinge_axis_agrees_between_halves(name) -> None:
    r = liberty(name)
    assert r["range_deg"] > 70  # the recording really turns by roughly 80-95 deg
    assert r["halves_deg"] < HALVES_TOLERANCE_DEG
    assert r["dominant_deg"] < DOMINANT_TOLERANCE_DEG


@needs_liberty
def test_liberty_x_orientation_agrees_with_positions_and_flips_flagged() -> None:
    """The orientation axis must be normal to the arc the sensor's origin travels.

    A wrongly ordered quaternion gives 6-89 deg here (measured); the correct order 2.6.
    The frames between the two hemisphere flips (position mirrored through the source)
    are left out.
    """
    r = liberty("rotate-90deg-x.csv")
    rec = r["recording"]
    flips = [j for j in find_jumps(rec) if j.hemisphere]
    assert [j.frame for j in flips] == [343, 579]
    p, c = rec.poses["hand"], rec.poses["index.proximal"]
    ok = p.valid & c.valid
    ok[flips[0].frame - 1 : flips[1].frame + 1] = False
    rel = relative_rotations(p.rotation[ok], c.rotation[ok])
    t = np.einsum("nji,nj->ni", p.rotation[ok], c.position[ok] - p.position[ok])
    normal = np.linalg.svd(t - t.mean(axis=0), full_matrices=False)[2][2]
    assert axis_angle_deg(sara_axis(rel)[0], normal) < 4.0


@needs_liberty
def test_convert_real_liberty_files_prints_repeat_counts(tmp_path) -> None:
    for name in LIBERTY_FILES:
        res = CliRunner().invoke(
            app,
            ["convert", str(LIBERTY / name), "-o", str(tmp_path / name), "--from", "wide-csv",
             "--units", "cm", "--rate", "120", "--map", "1=hand,2=index.proximal"],
        )  # fmt: skip
        assert res.exit_code == 0, res.output
        assert f"note: {DUPLICATES[name]} exactly repeated rows dropped" in res.output
        assert (tmp_path / name).is_file()


def test_axis_helpers_recover_known_joints() -> None:
    """The helpers behind the numbers above, on synthetic joints with known axes."""
    rng = np.random.default_rng(0)
    n = 200
    a1 = unit(np.array([0.1, 0.2, 1.0]))
    a2 = unit(np.array([1.0, -0.2, 0.1]))
    r0 = Rotation.from_rotvec([0.3, -0.2, 0.5])
    t = np.linspace(0, 4 * np.pi, n)
    th1 = np.radians(50 + 45 * np.sin(t))
    th2 = np.radians(30 * np.sin(1.7 * t + 0.5))
    noise = Rotation.from_rotvec(rng.normal(scale=np.radians(1.0), size=(n, 3)))
    hinge = (Rotation.from_rotvec(th1[:, None] * a1) * r0 * noise).as_matrix()
    assert axis_angle_deg(sara_axis(hinge)[0], a1) < 1.0
    assert axis_angle_deg(dominant_axis(hinge), a1) < 1.0
    assert axis_angle_deg(sara_axis(hinge)[1], r0.inv().apply(a1)) < 1.0
    two = Rotation.from_rotvec(th1[:, None] * a1) * r0 * Rotation.from_rotvec(th2[:, None] * a2)
    rel = (two * noise).as_matrix()
    fit = two_axis_fit(rel, dominant_axis(rel), n_starts=2)
    assert axis_angle_deg(fit["a1"], a1) < 1.0
    assert axis_angle_deg(fit["a2"], a2) < 3.0
    assert 0.8 < fit["rms_deg"] < 2.0  # the 1 deg per-axis noise
    assert axis_angle_deg(sara_axis(rel)[0], a1) > 5.0  # one hinge cannot absorb a2


# ------------------------------------------------------------------------ Optotrak arm


@needs_optotrak
def test_cluster_poses_and_probed_epicondyle() -> None:
    pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    e = elbow()
    assert e["residual_arm"] < 0.2 and e["residual_forearm"] < 0.2
    assert e["probe_residual"] < 0.2
    # Probe -> arm frame in one trial, arm cluster -> landmark in another: the same point.
    assert e["medial_vs_file_mm"] < 0.5
    assert 60 < e["epicondyle_width_mm"] < 100


#: Measured on the propulsion trial (docs/readers.md); tests keep docs and code in step.
ELBOW_HINGE_DEG = 27.3
ELBOW_TWO_AXIS_DEG = 67.4


@needs_optotrak
def test_elbow_single_hinge_vs_two_axis() -> None:
    pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    e = elbow()
    assert e["frames"] == 700
    assert abs(e["hinge_deg"] - ELBOW_HINGE_DEG) < 1.0
    assert abs(e["dominant_deg"] - e["hinge_deg"]) < 1.0
    assert abs(e["two_axis_deg"] - ELBOW_TWO_AXIS_DEG) < 2.0
    # The two-axis model explains the relative rotations much better than one hinge ...
    assert e["two_axis_rms_deg"] < 0.5 * e["hinge_rms_deg"]
