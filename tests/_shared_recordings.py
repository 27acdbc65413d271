"""The real recordings of ``../shared/data`` (beside the repository; absent on most
machines) and the measurements on them that the tests assert and ``bench/`` prints.

* Polhemus Liberty wide-CSV logs (``polhemus-liberty``): :func:`liberty`,
  :func:`liberty_pivot_residuals`;
* Optotrak C3D arm trials (``optotrak-arm``): :func:`elbow`.

Axis helpers: ``tests/_axes.py``. Lengths mm, angles deg.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from fingerfit.estimate.plausibility import pivot_residuals
from fingerfit.io.widecsv import read_wide_csv

from ._axes import axis_angle_deg, dominant_axis, relative_rotations, sara_axis, two_axis_fit

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
LIBERTY = DATA / "polhemus-liberty"
OPTOTRAK = DATA / "optotrak-arm"
LIBERTY_FILES = ("rotate-90deg-x.csv", "rotate-90deg-y.csv", "rotate-90deg-z.csv")
MAP2 = {1: "hand", 2: "index.proximal"}

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
    """One Liberty log read as two sensors: rows, repeated rows, hinge axis of sensor 2
    about sensor 1 in each half and against the dominant axis, rotation range."""
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


def liberty_pivot_residuals() -> dict[str, dict[str, float]]:
    """Pivot residual (mm) per quaternion reading of each real Liberty recording."""
    out = {}
    for name in LIBERTY_FILES:
        rec = read_wide_csv(
            LIBERTY / name, units="cm", rate_hz=120.0, sensors={1: "hand", 2: "index.proximal"}
        )
        out[name] = pivot_residuals(rec.poses["hand"], rec.poses["index.proximal"])[0]
    return out


def _local(rotation, position, points):
    """Points (n, 3) in the frames of poses (n, 3, 3) / (n, 3)."""
    return np.einsum("nji,nj->ni", rotation, points - position)


@functools.cache
def elbow() -> dict:
    """The elbow of the propulsion trial: cluster residuals, probed and reconstructed
    epicondyles, single-hinge and two-axis fits against the epicondyle line."""
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
