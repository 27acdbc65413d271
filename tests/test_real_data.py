"""Real-data validation of the readers (``../shared/data``; skipped when absent).

* Polhemus Liberty wide-CSV logs: repeated rows found and dropped; the hinge axis of
  sensor 2 about sensor 1 is the same in both halves of each recording and agrees
  with the dominant axis of the relative rotations.
* Optotrak C3D arm trials: segment poses from marker clusters; the medial epicondyle
  probed in one trial reappears where the file's own reconstruction puts it; elbow
  axes (single hinge and two-axis model) compared with the epicondyle line.

``python -m tests.test_real_data`` prints the numbers quoted in ``docs/readers.md``.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.io.hygiene import find_jumps
from fingerfit.io.widecsv import read_wide_csv

from ._axes import (
    axis_angle_deg,
    dominant_axis,
    relative_rotations,
    sara_axis,
    two_axis_fit,
    unit,
)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
LIBERTY = DATA / "polhemus-liberty"
OPTOTRAK = DATA / "optotrak-arm"
LIBERTY_FILES = ("rotate-90deg-x.csv", "rotate-90deg-y.csv", "rotate-90deg-z.csv")
MAP2 = {1: "hand", 2: "index.proximal"}

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

# Probe calibration (marker coordinates in the probe-tip frame, m), as published with the
# data in the Kinetics Toolkit documentation (F. Chenier, Apache-2.0).
PROBE_TIP_FRAME_MM = 1000.0 * np.array(
    [
        [0.0021213, -0.0158328, 0.0864285],
        [0.0021213, 0.0158508, 0.0864285],
        [0.0020575, 0.0160096, 0.1309445],
        [0.0021213, 0.0161204, 0.1754395],
    ]
)


@functools.cache
def liberty(name: str) -> dict:
    rec = read_wide_csv(LIBERTY / name, units="cm", rate_hz=120.0, sensors=MAP2)
    p, c = rec.poses["hand"], rec.poses["index.proximal"]
    ok = p.valid & c.valid
    rel = relative_rotations(p.rotation[ok], c.rotation[ok])
    h = rel.shape[0] // 2
    axis, _ = sara_axis(rel)
    first, _ = sara_axis(rel[:h])
    second, _ = sara_axis(rel[h:])
    swing = (Rotation.from_matrix(rel) * Rotation.from_matrix(rel[0]).inv()).magnitude()
    return {
        "recording": rec,
        "rows": int(rec.notes[0].split()[0]),
        "duplicates": int(next(n for n in rec.notes if "repeated rows" in n).split()[0]),
        "halves_deg": axis_angle_deg(first, second),
        "dominant_deg": axis_angle_deg(axis, dominant_axis(rel)),
        "range_deg": float(np.degrees(swing.max())),
        "axis_tracker": p.rotation[ok][0] @ axis,
        "ok": ok,
    }


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


def _local(rotation, position, points):
    """Points (n, 3) in the frames of poses (n, 3, 3) / (n, 3)."""
    return np.einsum("nji,nj->ni", rotation, points - position)


@functools.cache
def elbow() -> dict:
    from fingerfit.io.c3d import read_c3d_markers, read_c3d_segments
    from fingerfit.io.rigid import fit_cluster

    seg = read_c3d_segments(
        OPTOTRAK / "kinematics_racing_propulsion.c3d",
        segments={"ArmR": "arm", "ForearmR": "forearm"},
        check=False,
    )
    arm, fore = seg.recording.poses["arm"], seg.recording.poses["forearm"]
    shapes = {"ArmR": seg.shapes["arm"]}
    # Medial epicondyle: probe tip (probe calibration) in the arm frame of the probing trial.
    probing = read_c3d_markers(OPTOTRAK / "kinematics_racing_probing_medial_epicondyle_R.c3d")
    probe = fit_cluster(probing.cluster([f"Probe{i}" for i in range(1, 5)]), PROBE_TIP_FRAME_MM)
    arm_p = fit_cluster(probing.cluster(["ArmR1", "ArmR2", "ArmR3"]), shapes["ArmR"])
    medial = _local(arm_p.rotation, arm_p.translation, probe.translation).mean(axis=0)
    # The file's own reconstruction of the same landmark, in the same arm frame.
    full = read_c3d_markers(OPTOTRAK / "kinematics_racing_full.c3d")
    arm_f = fit_cluster(full.cluster(["ArmR1", "ArmR2", "ArmR3"]), shapes["ArmR"])
    me = full.marker("MedialEpicondyleR")
    okf = np.isfinite(me).all(axis=1) & np.isfinite(arm_f.residual)
    medial_file = _local(arm_f.rotation[okf], arm_f.translation[okf], me[okf]).mean(axis=0)
    ac = full.marker("AcromionR")
    oka = np.isfinite(ac).all(axis=1) & np.isfinite(arm_f.residual)
    acromion = _local(arm_f.rotation[oka], arm_f.translation[oka], ac[oka]).mean(axis=0)
    # Lateral epicondyle: skin marker, averaged in the arm frame over the trial.
    prop = read_c3d_markers(OPTOTRAK / "kinematics_racing_propulsion.c3d")
    le = prop.marker("LateralEpicondyleR")
    okl = np.isfinite(le).all(axis=1) & arm.valid
    lateral_all = _local(arm.rotation[okl], arm.position[okl], le[okl])
    lateral = lateral_all.mean(axis=0)
    epi = medial - lateral

    ok = arm.valid & fore.valid
    rel = relative_rotations(arm.rotation[ok], fore.rotation[ok])
    hinge, _ = sara_axis(rel)
    two = two_axis_fit(rel, dominant_axis(rel), n_starts=4)
    # Single-hinge residual: rotation left after the best rotation about the hinge axis.
    ref = Rotation.from_matrix(rel).mean()
    rv = (Rotation.from_matrix(rel) * ref.inv()).as_rotvec()
    off = rv - np.outer(rv @ hinge, hinge)
    return {
        "residual_arm": float(np.nanmedian(seg.fits["arm"].residual)),
        "residual_forearm": float(np.nanmedian(seg.fits["forearm"].residual)),
        "probe_residual": float(np.nanmedian(probe.residual)),
        "medial_vs_file_mm": float(np.linalg.norm(medial - medial_file)),
        "lateral_sd_mm": float(np.linalg.norm(lateral_all.std(axis=0))),
        "epicondyle_width_mm": float(np.linalg.norm(epi)),
        "frames": int(ok.sum()),
        "hinge_deg": axis_angle_deg(hinge, epi),
        "dominant_deg": axis_angle_deg(dominant_axis(rel), epi),
        "hinge_rms_deg": float(np.degrees(np.sqrt(np.mean(np.sum(off**2, axis=1))))),
        "two_axis_deg": axis_angle_deg(two["a1"], epi),
        "two_axis_rms_deg": two["rms_deg"],
        "two_axis_between_deg": axis_angle_deg(two["a1"], two["R0"] @ two["a2"]),
        "two_axis_vs_humerus_deg": axis_angle_deg(two["a1"], acromion - (medial + lateral) / 2),
        "epicondyle_vs_humerus_deg": axis_angle_deg(epi, acromion - (medial + lateral) / 2),
        "two_axis_ranges_deg": (
            float(np.degrees(np.ptp(two["t1"]))),
            float(np.degrees(np.ptp(two["t2"]))),
        ),
        "rel": rel,
        "epi": epi,
    }


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


def main() -> None:  # pragma: no cover - prints the numbers for docs/readers.md
    print("| file | rows | repeated rows dropped | frames | largest rotation from the first frame (deg) | "
          "hinge axis, half 1 vs half 2 (deg) | SARA vs dominant axis (deg) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name in LIBERTY_FILES:
        r = liberty(name)
        print(
            f"| {name} | {r['rows']} | {r['duplicates']} | {r['recording'].n_frames} | "
            f"{r['range_deg']:.1f} | {r['halves_deg']:.2f} | {r['dominant_deg']:.3f} |"
        )
    e = elbow()
    keys = [k for k in e if k not in ("rel", "epi")]
    for k in keys:
        v = e[k]
        print(f"{k}: {np.round(v, 3) if not isinstance(v, int) else v}")
    h = e["rel"].shape[0] // 2
    for part, sl in (("first half", slice(0, h)), ("second half", slice(h, None))):
        rel = e["rel"][sl]
        two = two_axis_fit(rel, dominant_axis(rel), n_starts=4)
        print(
            f"{part}: single hinge {axis_angle_deg(sara_axis(rel)[0], e['epi']):.1f} deg, "
            f"two-axis flexion {axis_angle_deg(two['a1'], e['epi']):.1f} deg "
            f"(rms {two['rms_deg']:.2f} deg)"
        )
    # Flexion axis forced onto the epicondyle line: how much worse does the model fit?
    forced = two_axis_fit(e["rel"], unit(e["epi"]), n_starts=4, fix_a1=True)
    print(f"two-axis with a1 = epicondyle line: rms {forced['rms_deg']:.2f} deg")


if __name__ == "__main__":  # pragma: no cover
    main()
