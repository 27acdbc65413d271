"""Accuracy benchmark: fingerfit's estimators and peer implementations on simulated cohorts.

Run with ``make bench-accuracy`` (``python bench/accuracy.py --json bench/accuracy.json``).

For every condition (a :class:`~fingerfit.simulate.SimConfig`), ``--subjects``
simulated subjects (index finger, paper protocol) are fitted by every method on
the same data in the same run, and scored against the simulator's ground truth:

* **axis error** (deg): angle between the fitted and the true flexion axis, in the
  joint's parent sensor frame;
* **centre distance** (mm): distance of the model's joint centre to the true axis
  (parent sensor frame);
* **fingertip error** (mm): model fingertip vs true fingertip over the free-motion
  test recording (angles from the sensors by the model's angle method, carried by
  the hand sensor). "mean" is the mean over subjects of each subject's mean over
  frames; "p95" the 95th percentile over all frames of all subjects.

Rows: the orthogonal-axis model and ``tang2018`` (the paper exactly: projection
angles), the fingerfit methods, the peers (``biobuddy`` ``Sara`` axis and
``Score`` centre, on the same movement frames, with fingerfit's sagittal-plane
rule and kinematics around them), and the true model driven by the same noisy
sensors (the floor). Axis and centre figures are means and 95th percentiles over
subjects.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import datetime
import json
import platform
import sys
import time
import warnings
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))

from peers import HAVE_BIOBUDDY, biobuddy_sara, biobuddy_score, joint_frames
from pool import run_tasks
from revision import run_at_revision

import fingerfit.estimate.fit as fit_module
from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.estimate.axis import orient_flexion

try:
    from fingerfit.estimate.choice import HINGE, TWO_AXIS, choose_joint_model
except ImportError:  # a revision before the held-out choice (--before)
    HINGE = TWO_AXIS = ""
    choose_joint_model = None
try:  # the module whose estimators call the choice (fit.py in older revisions)
    import fingerfit.estimate.methods as CHOICE_USER
except ImportError:
    CHOICE_USER = fit_module
from fingerfit.estimate.fit import DEFAULT_METHOD, joint_data, reference_poses
from fingerfit.estimate.sagittal import intersect, sagittal_plane
from fingerfit.kinematics import carry_by_hand, chain_points, compute_kinematics
from fingerfit.model import HandModel, JointQuality, assemble_digit
from fingerfit.session import HAND_SENSOR, JOINTS, joint_sensors
from fingerfit.simulate import SimConfig, SimulatedSubject, simulate_subject
from fingerfit.simulate.study import relative_truth_in_parent
from fingerfit.simulate.truthmodel import truth_model
from fingerfit.transforms import (
    FloatArray,
    angle_between_axes,
    distance_point_to_line,
    rotation_vector,
)

FINGER = "index"
CONDITIONS: dict[str, dict] = {
    "realistic": {},
    "noise 0": {"noise": 0.0},
    "noise 2x": {"noise": 2.0},
    "ROM small (0.4)": {"rom_scale": 0.4},
    "ROM medium (0.7)": {"rom_scale": 0.7},
    "tilt 0": {"tilt_scale": 0.0},
    "tilt 3x": {"tilt_scale": 3.0},
    "STA off": {"sta": 0.0},
    "MP ab/adduction off": {"abduction": False},
    # MP ab/adduction mostly following flexion (3-10 %) plus a small slow part out of step
    # with the grasp cycles, and soft-tissue artefact twice as large (it repeats every cycle).
    "MP ab/adduction coupled": {
        "abduction_coupling": (-0.065, 0.02),
        "abduction_wander_deg": 0.3,
        "abduction_wander_hz": 0.08,
    },
    "STA 2x": {"sta": 2.0},
    "STA 2x without MP ab/adduction": {"sta": 2.0, "abduction": False},
    # A finger whose MP flexion axis is 15 deg off perpendicular to the bone (about the
    # dorsal axis), far beyond the drawn obliquity.
    "MP axis tilted 15 deg": {"mp_axis_tilt_deg": 15.0},
    # An independent truth: MyoHand's fingers (right hand; flexion-first MP).
    "MyoHand world": {"world": "myohand", "hand": "right"},
    "MyoHand world without MP ab/adduction": {
        "world": "myohand",
        "hand": "right",
        "abduction": False,
    },
}
# (row label, fit method, angle method, model variant)
FIT_ROWS = [
    ("orthogonal", "tang2018", "projection", "orthogonal"),
    ("tang2018", "tang2018", "projection", "user_axis"),
    ("tang2018 + swing-twist", "tang2018", "swing_twist", "user_axis"),
    ("pooled", "pooled", None, "user_axis"),
    ("robust", "robust", None, "user_axis"),
    ("twoaxis", "twoaxis", None, "user_axis"),
    ("twoaxis, always two axes", "twoaxis", None, "user_axis"),
    ("twoaxis + projection", "twoaxis", "projection", "user_axis"),
    ("rolling", "rolling", None, "user_axis"),
]
PEER_ROWS = ["biobuddy Sara", "biobuddy Score+Sara"] if HAVE_BIOBUDDY else []
FLOOR_ROWS = [
    "true model (floor)",
    "true model, projection angles",
    "true model, true angles (hand sensor only)",
]
FLOOR = "true model (floor)"
FRAME_STRIDE = 4  # fingertip frames kept per subject for the cohort percentile


def _label(method: str) -> str:
    return f"{method} (default)" if method == DEFAULT_METHOD else method


def geometry_errors(sim: SimulatedSubject, model: HandModel) -> tuple[list, list]:
    """Axis error (deg) and centre-to-true-axis distance (mm) per joint, parent frames."""
    deg, mm = [], []
    for j in JOINTS:
        c, a = model.in_parent(FINGER, j)
        ct, at = relative_truth_in_parent(sim, FINGER, j)
        deg.append(float(np.degrees(angle_between_axes(a, at))))
        mm.append(float(distance_point_to_line(c, ct, at)))
    return deg, mm


def tip_errors(
    sim: SimulatedSubject, model: HandModel, variant: str = "user_axis", digit: str = FINGER
) -> FloatArray:
    """Fingertip error per frame of the free-motion test recording (mm)."""
    rec = sim.session.test[0]
    kin = compute_kinematics(model, rec, variants=(variant,), fingers=[digit])
    true_tip = sim.truth.frames[rec.name]["tip"][digit]
    return np.linalg.norm(kin.motions[variant][digit].tip - true_tip, axis=1)


def true_angle_tip_errors(sim: SimulatedSubject, model: HandModel) -> FloatArray:
    """Fingertip error (mm) of the true model driven by the true joint angles: only the hand
    sensor's artefact and tracker error remain."""
    rec = sim.session.test[0]
    frames = sim.truth.frames[rec.name]
    fm = model.fingers[FINGER]
    local = chain_points(fm, "user_axis", frames["angles"][FINGER], fm.tip)
    hand = rec.pose(HAND_SENSOR)
    tip = carry_by_hand(model, hand.rotation, hand.position, local)
    return np.linalg.norm(tip - frames["tip"][FINGER], axis=1)


def model_from_lines(
    sim: SimulatedSubject, lines: dict[str, tuple[FloatArray, FloatArray]], name: str
) -> HandModel:
    """A one-axis model from per-joint lines (point, axis; parent frames), with fingerfit's
    flexion orientation, sagittal-plane centres, frames and swing-twist angles."""
    s = sim.session
    ref = reference_poses(s)
    q = JointQuality(0, [], [], [], 0.0, [])
    axes, points = {}, {}
    for j, (parent, child) in joint_sensors(FINGER).items():
        d = joint_data(s, parent, child, ref, j)
        mv = np.concatenate(d.periods)
        rv = rotation_vector(d.rotation[mv] @ d.reference_rotation.T)
        point, axis = lines[j]
        pp, pr = ref[parent]
        axes[j] = pr @ orient_flexion(axis / np.linalg.norm(axis), rv)
        points[j] = pr @ point + pp
    lm = np.array([s.landmark(f"{FINGER}.{k}") for k in ("mp", "pip", "dip", "tip")])
    plane = sagittal_plane(lm, np.array(list(axes.values())), FINGER)
    joints = {
        j: (p, c, intersect(plane, points[j], axes[j], j), axes[j], q)
        for j, (p, c) in joint_sensors(FINGER).items()
    }
    used = {HAND_SENSOR} | {c for _, c in joint_sensors(FINGER).values()}
    return HandModel(
        subject=s.subject,
        hand=s.hand,
        session_units="mm",
        method=name,
        reference_poses={k: v for k, v in ref.items() if k in used},
        fingers={FINGER: assemble_digit(FINGER, joints, s.landmark(f"{FINGER}.tip"))},
        angle_method="swing_twist",
    )


def peer_models(sim: SimulatedSubject) -> tuple[dict[str, HandModel], float]:
    """biobuddy Sara (axis + its centre) and Score (centre, with Sara's axis) models."""
    s = sim.session
    ref = reference_poses(s)
    sara, score = {}, {}
    t0 = time.perf_counter()
    for j, (parent, child) in joint_sensors(FINGER).items():
        d = joint_data(s, parent, child, ref, j)
        frames = joint_frames(s.grasp, parent, child, np.concatenate(d.periods))
        axis, point = biobuddy_sara(*frames)
        sara[j] = (point, axis)
        score[j] = (biobuddy_score(*frames), axis)
    elapsed = time.perf_counter() - t0
    return {
        "biobuddy Sara": model_from_lines(sim, sara, "biobuddy Sara"),
        "biobuddy Score+Sara": model_from_lines(sim, score, "biobuddy Score+Sara"),
    }, elapsed


def _always_two_axes(*args, **kwargs):
    """The model choice, overruled: two axes whenever the two-axis fit is a candidate
    (the "always two axes" row; "robust" is always one axis)."""
    choice = choose_joint_model(*args, **kwargs)
    return replace(choice, chosen=TWO_AXIS if choice.candidate else HINGE)


def run_subject(task: tuple[str, dict, int, bool]) -> dict:
    """All rows (``only_default``: the default method's and the floor) for one simulated
    subject of one condition."""
    cond, overrides, seed, only_default = task
    warnings.simplefilter("ignore")
    out: dict = {"condition": cond, "rows": {}}
    try:
        config = SimConfig(**overrides)
    except (TypeError, FingerfitError) as exc:  # a revision (--before) without the condition
        out["failures"] = [f"{cond}: {exc}"]
        return out
    sim = simulate_subject(config, seed)
    rows = [r for r in FIT_ROWS if r[0] == DEFAULT_METHOD] if only_default else FIT_ROWS
    for label, method, angles, variant in rows:
        t0 = time.perf_counter()
        if choose_joint_model is not None:
            CHOICE_USER.choose_joint_model = (
                _always_two_axes if label.endswith("always two axes") else choose_joint_model
            )
        try:
            model = fit_session(
                sim.session, FitOptions(method=method, angle_method=angles, force=True)
            )
        except FingerfitError as exc:  # refused even with force (e.g. axis in the sagittal plane)
            out["rows"][label] = None
            out.setdefault("failures", []).append(f"{cond} seed {seed} {label}: {exc}")
            continue
        elapsed = time.perf_counter() - t0
        deg, mm = geometry_errors(sim, model)
        if variant == "orthogonal":
            deg = [
                float(
                    np.degrees(
                        angle_between_axes(
                            model.in_parent(FINGER, j, "orthogonal")[1],
                            relative_truth_in_parent(sim, FINGER, j)[1],
                        )
                    )
                )
                for j in JOINTS
            ]
        err = tip_errors(sim, model, variant)
        two_axis = model.fingers[FINGER].second_axes.get("mp") is not None
        flexion_first = two_axis and model.fingers[FINGER].order("mp") == "flexion_first"
        out["rows"][label] = {
            "two_axis": two_axis,
            "flexion_first": flexion_first,
            "deg": deg,
            "mm": mm,
            "tip": err[::FRAME_STRIDE].tolist(),
            "tip_mean": float(np.nanmean(err)),
            "fit_s": elapsed,
        }
    if PEER_ROWS and not only_default:
        models, elapsed = peer_models(sim)
        for label, model in models.items():
            deg, mm = geometry_errors(sim, model)
            err = tip_errors(sim, model)
            out["rows"][label] = {
                "deg": deg,
                "mm": mm,
                "tip": err[::FRAME_STRIDE].tolist(),
                "tip_mean": float(np.nanmean(err)),
                "fit_s": elapsed,
            }
    for label, angles in zip(FLOOR_ROWS, ("swing_twist", "projection", None), strict=True):
        model = truth_model(sim, angle_method=angles or "swing_twist")
        err = tip_errors(sim, model) if angles else true_angle_tip_errors(sim, model)
        out["rows"][label] = {
            "deg": [0.0] * 3,
            "mm": [0.0] * 3,
            "tip": err[::FRAME_STRIDE].tolist(),
            "tip_mean": float(np.nanmean(err)),
            "fit_s": 0.0,
        }
    return out


def summarise(results: list[dict], conditions: list[str]) -> dict:
    """Per condition and row: means and 95th percentiles."""
    summary: dict = {}
    for cond in conditions:
        rows: dict = {}
        subj = [r for r in results if r["condition"] == cond]
        for label in [r[0] for r in FIT_ROWS] + PEER_ROWS + FLOOR_ROWS:
            vals = [s["rows"][label] for s in subj if s["rows"].get(label) is not None]
            if not vals:
                continue
            deg = np.array([v["deg"] for v in vals])
            mm = np.array([v["mm"] for v in vals])
            tips = np.concatenate([v["tip"] for v in vals])
            rows[label] = {
                "subjects": len(vals),
                "refused": len(subj) - len(vals),
                "axis_deg": {
                    j: {"mean": float(deg[:, i].mean()), "p95": float(np.percentile(deg[:, i], 95))}
                    for i, j in enumerate(JOINTS)
                },
                "centre_mm": {
                    j: {"mean": float(mm[:, i].mean()), "p95": float(np.percentile(mm[:, i], 95))}
                    for i, j in enumerate(JOINTS)
                },
                "tip_mm": {
                    "mean": float(np.mean([v["tip_mean"] for v in vals])),
                    "p95": float(np.nanpercentile(tips, 95)),
                },
                "fit_s_per_finger": float(np.mean([v["fit_s"] for v in vals])),
                "two_axis_mp": int(sum(v.get("two_axis", False) for v in vals)),
                "flexion_first_mp": int(sum(v.get("flexion_first", False) for v in vals)),
            }
        if FLOOR not in rows:  # the condition did not run (a revision without it)
            continue
        floor = rows[FLOOR]["tip_mm"]["mean"]
        for r in rows.values():
            r["tip_over_floor"] = r["tip_mm"]["mean"] / floor
        # Paired axis-error differences, default minus each peer, on the same subjects.
        paired: dict = {}
        for peer in PEER_ROWS:
            pairs = [
                (s["rows"][DEFAULT_METHOD]["deg"], s["rows"][peer]["deg"])
                for s in subj
                if s["rows"].get(DEFAULT_METHOD) and s["rows"].get(peer)
            ]
            if len(pairs) < 2:
                continue
            diff = np.array([np.subtract(a, b) for a, b in pairs])
            half = stats.t.ppf(0.975, len(diff) - 1) * diff.std(axis=0, ddof=1) / np.sqrt(len(diff))
            paired[peer] = {
                j: {
                    "mean_deg": float(diff[:, i].mean()),
                    "ci95_deg": [
                        float(diff[:, i].mean() - half[i]),
                        float(diff[:, i].mean() + half[i]),
                    ],
                }
                for i, j in enumerate(JOINTS)
            }
        if DEFAULT_METHOD in rows:
            rows[DEFAULT_METHOD]["paired_vs_peers"] = paired
        summary[cond] = rows
    return summary


#: Conditions whose subjects' MP does not ab/adduct (the MP axis target is for the others).
NO_MP_ABDUCTION = {c for c, o in CONDITIONS.items() if o.get("abduction") is False}
ALWAYS_TWO = "twoaxis, always two axes"


def choice_targets(summary: dict) -> list[tuple[str, bool, str]]:
    """No regret of the model choice, and the MP axis where the MP ab/adducts."""
    out = []
    regret = []
    for c, rows in summary.items():
        if not {DEFAULT_METHOD, "robust", ALWAYS_TWO} <= set(rows):
            continue
        best = min(rows[k]["tip_mm"]["mean"] for k in ("robust", ALWAYS_TWO))
        ratio = rows[DEFAULT_METHOD]["tip_mm"]["mean"] / best
        if ratio > 1.05:
            regret.append(f"{c} ({ratio:.2f}x)")
    out.append(
        (
            "default tip <= 1.05 x the better of always one / always two axes, every condition",
            not regret,
            "; ".join(regret) or "all",
        )
    )
    far = [
        f"{c} ({rows[DEFAULT_METHOD]['axis_deg']['mp']['mean']:.2f})"
        for c, rows in summary.items()
        if c not in NO_MP_ABDUCTION
        and DEFAULT_METHOD in rows
        and rows[DEFAULT_METHOD]["axis_deg"]["mp"]["mean"] > 1.0
    ]
    out.append(
        (
            "default MP axis <= 1.0 deg mean, every condition with MP ab/adduction",
            not far,
            "; ".join(far) or "all",
        )
    )
    return out


def before_after(before: dict, after: dict, rev: str) -> str:
    """The default method before (``rev``) and after, per condition: MP axis and tip."""
    lines = [
        f"### {_label(DEFAULT_METHOD)} before ({rev}) and after, same subjects",
        "",
        "| condition | MP deg before | MP deg after | tip mm before | tip mm after | "
        "tip after/before |",
        "|---|---|---|---|---|---|",
    ]
    for c, rows in after.items():
        a, b = rows.get(DEFAULT_METHOD), before.get(c, {}).get(DEFAULT_METHOD)
        if a is None or b is None:
            lines.append(f"| {c} | n/a | | | | |")
            continue
        ta, tb = a["tip_mm"]["mean"], b["tip_mm"]["mean"]
        lines.append(
            f"| {c} | {b['axis_deg']['mp']['mean']:.2f} | {a['axis_deg']['mp']['mean']:.2f} | "
            f"{tb:.2f} | {ta:.2f} | {ta / tb:.2f} |"
        )
    return "\n".join(lines)


def run_before(rev: str, args: argparse.Namespace) -> dict:
    """The default method of revision ``rev`` on the same subjects: this script run on
    that revision's ``src`` in a subprocess (:func:`revision.run_at_revision`)."""
    cmd = ["--only-default", "--subjects", str(args.subjects), "--workers", str(args.workers)]
    cmd += ["--seed", str(args.seed), "--conditions", args.conditions]
    return run_at_revision(rev, __file__, cmd)["summary"]


def targets(summary: dict) -> list[tuple[str, bool, str]]:
    """The issue's targets, checked on the summary."""
    t = "tang2018"
    out = choice_targets(summary)
    real = summary["realistic"]
    ratio = real[DEFAULT_METHOD]["tip_mm"]["mean"] / real[t]["tip_mm"]["mean"]
    out.append(("default tip <= 0.75 x tang2018 (realistic)", ratio <= 0.75, f"{ratio:.2f}x"))
    worse = [
        c
        for c, rows in summary.items()
        if rows[DEFAULT_METHOD]["tip_mm"]["mean"] > rows[t]["tip_mm"]["mean"]
    ]
    out.append(("default tip <= tang2018 in every condition", not worse, ", ".join(worse) or "all"))
    fails = []
    for c, rows in summary.items():
        for j in JOINTS:
            best = min(
                (rows[p]["axis_deg"][j]["mean"] for p in PEER_ROWS if p in rows), default=np.inf
            )
            if rows[DEFAULT_METHOD]["axis_deg"][j]["mean"] > best:
                fails.append(
                    f"{c} {j} ({rows[DEFAULT_METHOD]['axis_deg'][j]['mean']:.2f} vs {best:.2f})"
                )
    out.append(
        (
            "default axis error <= best peer, every condition and joint",
            not fails,
            "; ".join(fails) or "all",
        )
    )
    r = real[DEFAULT_METHOD]["tip_over_floor"]
    out.append(("default tip <= 1.3 x floor (realistic)", r <= 1.3, f"{r:.2f}x"))
    return out


def markdown(summary: dict, meta: dict) -> str:
    """Tables: the realistic condition in full, then one line per condition and row."""
    lines = [
        f"Run {meta['date']}: `{meta['command']}` ({meta['subjects']} subjects per "
        f"condition, {meta['seconds']:.0f} s on {meta['workers']} worker(s)).",
        "",
    ]
    if "realistic" in summary:  # the full table only with that condition
        real = summary["realistic"]
        lines += [
            "### Realistic condition",
            "",
            "| method | MP deg | PIP deg | DIP deg | MP mm | PIP mm | DIP mm | tip mean mm | "
            "tip p95 mm | x floor | fit s/finger |",
            "|---|" + "---|" * 10,
        ]
        for label, r in real.items():
            a, c = r["axis_deg"], r["centre_mm"]
            geo = (
                " | ".join(f"{a[j]['mean']:.2f} ({a[j]['p95']:.2f})" for j in JOINTS)
                + " | "
                + " | ".join(f"{c[j]['mean']:.2f} ({c[j]['p95']:.2f})" for j in JOINTS)
            )
            if label in FLOOR_ROWS:
                geo = " | ".join(["–"] * 6)
            lines.append(
                f"| {_label(label)} | {geo} | {r['tip_mm']['mean']:.2f} | "
                f"{r['tip_mm']['p95']:.2f} | {r['tip_over_floor']:.2f} | "
                f"{r['fit_s_per_finger']:.3f} |"
            )
    lines += [
        "",
        "Axis and centre cells: mean (95th percentile) over subjects.",
        "",
        "### Every condition",
        "",
        "| condition | method | MP deg | PIP deg | DIP deg | MP mm | PIP mm | DIP mm | "
        "tip mean mm | tip p95 mm | x floor |",
        "|---|---|" + "---|" * 9,
    ]
    for cond, rows in summary.items():
        for label, r in rows.items():
            if label in FLOOR_ROWS[1:]:
                continue
            a, c = r["axis_deg"], r["centre_mm"]
            geo = (
                " | ".join(f"{a[j]['mean']:.2f}" for j in JOINTS)
                + " | "
                + " | ".join(f"{c[j]['mean']:.2f}" for j in JOINTS)
            )
            if label in FLOOR_ROWS:
                geo = " | ".join(["–"] * 6)
            ref = "" if not r["refused"] else f" ({r['refused']} refused)"
            if r.get("two_axis_mp"):
                ref += f" [{r['two_axis_mp']}/{r['subjects']} two-axis MP"
                if r.get("flexion_first_mp"):
                    ref += f", {r['flexion_first_mp']} flexion first"
                ref += "]"
            lines.append(
                f"| {cond} | {_label(label)}{ref} | {geo} | {r['tip_mm']['mean']:.2f} | "
                f"{r['tip_mm']['p95']:.2f} | {r['tip_over_floor']:.2f} |"
            )
    if PEER_ROWS:
        lines += [
            "",
            f"### Axis error, {_label(DEFAULT_METHOD)} minus each peer (paired, same subjects)",
            "",
            "Mean difference in deg and its 95 % confidence interval (t); negative = "
            f"{DEFAULT_METHOD} closer to the true axis.",
            "",
            "| condition | peer | MP | PIP | DIP |",
            "|---|---|---|---|---|",
        ]
        for cond, rows in summary.items():
            for peer, d in rows.get(DEFAULT_METHOD, {}).get("paired_vs_peers", {}).items():
                cells = " | ".join(
                    f"{d[j]['mean_deg']:+.2f} [{d[j]['ci95_deg'][0]:+.2f}, {d[j]['ci95_deg'][1]:+.2f}]"
                    for j in JOINTS
                )
                lines.append(f"| {cond} | {peer} | {cells} |")
    if meta.get("failures"):
        lines += ["", "Fits that failed even with `force` (counted as refused above):", ""]
        lines += [f"- {f}" for f in meta["failures"]]
    lines += ["", "### Targets", "", "| target | met | value |", "|---|---|---|"]
    for name, ok, val in meta["targets"]:
        lines.append(f"| {name} | {'yes' if ok else '**no**'} | {val} |")
    return "\n".join(lines)


def _config(cond: str) -> dict | str:
    """The condition's SimConfig as a dict (or why this revision cannot make it)."""
    try:
        return asdict(SimConfig(**CONDITIONS[cond]))
    except (TypeError, FingerfitError) as exc:
        return f"not available: {exc}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--subjects", type=int, default=20)
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--seed", type=int, default=2018)
    ap.add_argument(
        "--conditions",
        default=",".join(CONDITIONS),
        help="comma-separated subset of the conditions",
    )
    ap.add_argument(
        "--before",
        default=None,
        help="a git revision: its default method on the same subjects, side by side",
    )
    ap.add_argument("--only-default", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    chosen = [c.strip() for c in args.conditions.split(",")]
    for c in chosen:
        if c not in CONDITIONS:
            ap.error(f"unknown condition '{c}'")
    tasks = []
    for ci, cond in enumerate(chosen):
        seeds = np.random.SeedSequence([args.seed, ci]).spawn(args.subjects)
        tasks += [
            (cond, CONDITIONS[cond], int(s.generate_state(1)[0]), args.only_default) for s in seeds
        ]
    t0 = time.perf_counter()
    results = run_tasks(run_subject, tasks, args.workers)
    summary = summarise(results, chosen)
    cmd = "python bench/accuracy.py " + " ".join(sys.argv[1:])
    meta = {
        "date": datetime.date.today().isoformat(),
        "command": cmd.strip(),
        "subjects": args.subjects,
        "workers": args.workers,
        "seconds": time.perf_counter() - t0,
        "default_method": DEFAULT_METHOD,
        "peers": PEER_ROWS,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "conditions": {c: _config(c) for c in chosen},
    }
    if args.only_default:
        meta["targets"] = []
    elif "realistic" in summary:
        meta["targets"] = targets(summary)
    else:
        meta["targets"] = choice_targets(summary)
    meta["failures"] = [f for r in results for f in r.get("failures", [])]
    if args.only_default:
        args.json.write_text(json.dumps({"meta": meta, "summary": summary}, indent=1) + "\n")
        return
    text = markdown(summary, meta)
    if args.before:
        before = run_before(args.before, args)
        meta["before"] = {"revision": args.before, "summary": before}
        text += "\n\n" + before_after(before, summary, args.before)
    print(text)
    if args.json:
        args.json.write_text(json.dumps({"meta": meta, "summary": summary}, indent=1) + "\n")


if __name__ == "__main__":
    main()
