"""Simulated subjects and cohorts with ground truth.

:func:`simulate_subject` draws one subject's anatomy, sensor mounts and
tracker errors, runs the paper's protocol (reference, grasp, target reaching,
free-motion test) and returns the measured :class:`~fingerfit.session.Session`
together with the :class:`SubjectTruth`. :func:`write_subject` saves both:
the session directory plus ``truth.json`` and ``truth/<recording>.csv``.
With ``thumb`` among the digits, :mod:`.wholehand` adds the thumb to every recording
and its own calibration recordings (circumduction, opposition, pinches), from the
thumb's own random stream.

:class:`SimConfig` is in :mod:`.config`, the truth and its files in :mod:`.truth`; their
names are importable from here too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..io.sessiondir import save_session
from ..session import (
    HAND_SENSOR,
    SEGMENTS,
    PoseSeries,
    Recording,
    Session,
    TargetEvent,
    sensor_name,
)
from ..transforms import FloatArray
from . import contact as ct
from . import motion as mo
from . import myohand as mh
from . import wholehand as wh
from .anatomy import FingerAnatomy, sample_finger, segment_motions
from .config import WORLDS as WORLDS
from .config import SimConfig
from .sensors import SensorMount, TrackerErrors, mount, sensor_poses
from .truth import TRUTH_FORMAT as TRUTH_FORMAT
from .truth import SimulatedSubject, SubjectTruth, write_truth
from .truth import relative_truth_in_parent as relative_truth_in_parent
from .truth import truth_document as truth_document
from .truth import truth_table as truth_table

TARGET_SPACING_MM = 20.0
N_TARGETS = 7
SENSOR_HEIGHT = np.array([7.5, 6.5, 5.0])  # dorsal height of phalanx sensors (mm)
# Relative skin sliding under the phalanx sensors; the distal one sits on the nail.
SENSOR_STA = np.array([1.0, 1.0, 0.3])
#: The stylus recordings' own random stream (``np.random.default_rng([seed, STYLUS_STREAM])``).
STYLUS_STREAM = 38


def _hand_pose(rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Hand frame at the reference posture: palm down (dorsal = tracker +z), random yaw."""
    yaw = Rotation.from_euler("z", rng.uniform(-30, 30), degrees=True)
    roll = Rotation.from_euler("x", rng.normal(0, 5), degrees=True)
    origin = np.array([300.0, 0.0, 80.0]) + rng.normal(0, 20.0, 3)
    return (yaw * roll).as_matrix(), origin


def _run(
    motion: mo.Motion,
    name: str,
    fingers: dict[str, FingerAnatomy],
    mounts: dict[str, SensorMount],
    tracker: TrackerErrors,
    rng: np.random.Generator,
    ts: wh.ThumbSetup | None = None,
) -> tuple[Recording, dict]:
    """Move the true hand through ``motion``; return the measured recording and its truth.

    The fingers' tracker noise comes from ``rng``, the thumb's from its own generator
    (``ts``), after the fingers'.
    """
    hand = (motion.hand_rotation, motion.hand_translation)
    poses: dict[str, PoseSeries] = {}
    truth: dict = {
        "time": motion.time,
        "angles": motion.angles,
        "tip": {},
        "pad": {},
        "sensors": {},
        "motions": {},
    }
    if fingers:
        mean_mp = np.mean([motion.angles[f]["mp"] for f in fingers], axis=0)
    else:
        mean_mp = motion.angles["thumb"]["mcp"]
    zero = np.zeros_like(motion.time)
    p, r = sensor_poses(mounts[HAND_SENSOR], hand, (mean_mp, zero))
    truth["sensors"][HAND_SENSOR] = (p, r)
    truth["motions"][HAND_SENSOR] = hand
    poses[HAND_SENSOR] = PoseSeries(*tracker.apply(rng, p, r))
    for f, anat in fingers.items():
        ang = motion.angles[f]
        seg = segment_motions(anat, ang, hand)
        tip_r, tip_t = seg["distal"]
        truth["tip"][f] = np.einsum("nij,j->ni", tip_r, anat.tip) + tip_t
        if ts is not None and f in ts.pads:
            truth["pad"][f] = np.einsum("nij,j->ni", tip_r, ts.pads[f].centre) + tip_t
        adjacent = {"proximal": ("mp", "pip"), "middle": ("pip", "dip"), "distal": ("dip", None)}
        for s in SEGMENTS:
            a, b = adjacent[s]
            sname = sensor_name(f, s)
            p, r = sensor_poses(mounts[sname], seg[s], (ang[a], zero if b is None else ang[b]))
            truth["sensors"][sname] = (p, r)
            truth["motions"][sname] = seg[s]
            poses[sname] = PoseSeries(*tracker.apply(rng, p, r))
    if ts is not None and ts.thumb is not None:
        measured, th = wh.run_thumb(ts, motion.angles["thumb"], hand, tracker)
        truth["tip"]["thumb"] = th["tip"]
        truth["pad"]["thumb"] = th["pad"]
        truth["sensors"].update(th["sensors"])
        truth["motions"].update(th["motions"])
        poses.update({k: PoseSeries(*v) for k, v in measured.items()})
    return Recording(name, motion.time.copy(), poses), truth


def _target_motion(
    rng: np.random.Generator,
    fingers: dict[str, FingerAnatomy],
    config: SimConfig,
) -> tuple[mo.Motion, FloatArray, FloatArray]:
    """Target reaching with the first finger: 7 targets 0-120 mm apart along a straight edge.

    For each target a posture is drawn (more extended for farther targets, off
    the grasp synergy by a few degrees); the hand is then placed so that the
    true fingertip touches the target exactly.

    Returns
    -------
    motion : Motion
    targets : ndarray, shape (7, 3)
        True target positions (mm).
    holds : ndarray, shape (7, 2)
        Hold intervals (s).
    """
    names = list(fingers)
    main = names[0]
    s = np.linspace(0.85, 0.1, N_TARGETS)
    peak = np.radians(mo.GRASP_PEAK_DEG) * config.rom_scale
    postures = []
    tips = []
    rot = Rotation.from_rotvec(rng.normal(0, np.radians(4.0), (N_TARGETS, 3)))
    for j in range(N_TARGETS):
        ang = {f: {} for f in names}
        for f in names:
            level = s[j] if f == main else 0.9
            for ji, k in enumerate(("mp", "pip", "dip")):
                ang[f][k] = np.array([max(level * peak[ji] + rng.normal(0, np.radians(4.0)), 0.0)])
            ang[f]["mp_abduction"] = np.array(
                [rng.normal(0, np.radians(2.0)) if config.abduction else 0.0]
            )
        postures.append(ang)
        eye = (np.eye(3)[None], np.zeros((1, 3)))
        seg = segment_motions(fingers[main], ang[main], eye)
        r, t = seg["distal"]
        tips.append(r[0] @ fingers[main].tip + t[0])
    tips_a = np.array(tips)
    direction = tips_a[-1] - tips_a[0]
    direction /= np.linalg.norm(direction)
    targets = tips_a[0] + np.arange(N_TARGETS)[:, None] * TARGET_SPACING_MM * direction
    trans = targets - rot.apply(tips_a)
    keys = [(f, k) for f in names for k in mo.ANGLE_KEYS]
    way = np.column_stack(
        [np.array([p[f][k][0] for p in postures]) for f, k in keys] + [rot.as_rotvec(), trans]
    )
    time, values, holds = mo.min_jerk_path(way, hold=1.0, move=1.0, rate=config.rate_hz)
    angles = {f: {} for f in names}
    for i, (f, k) in enumerate(keys):
        angles[f][k] = values[:, i]
    n_ang = len(keys)
    r = Rotation.from_rotvec(values[:, n_ang : n_ang + 3]).as_matrix()
    return mo.Motion(time, angles, r, values[:, n_ang + 3 :]), targets, holds


def simulate_subject(config: SimConfig, seed: int, subject: str = "S01") -> SimulatedSubject:
    """Simulate one subject's session with ground truth.

    Parameters
    ----------
    config : SimConfig
    seed : int
        Everything is deterministic given ``(config, seed)``. The fingers draw from
        ``default_rng(seed)``, the thumb and every digit's pad from
        :func:`.wholehand.thumb_generator` ``(seed)``: a finger's truth is the same with
        or without the thumb.
    subject : str
        Subject identifier written to ``session.toml``.

    Returns
    -------
    SimulatedSubject
        ``session`` (as if loaded from files, mm) and ``truth``. With the thumb, the
        thumb's calibration recordings follow ``grasp.csv`` under ``grasp`` and its
        pad-to-pad touches are ``events`` (``finger`` = ``thumb``, ``target`` = the
        finger touched).
    """
    if config.world == "myohand":
        mh.check_config(config.hand)
    rng = np.random.default_rng(seed)
    hand_rot, hand_origin = _hand_pose(rng)
    scale = rng.normal(1.0, 0.06)
    with_thumb = "thumb" in config.fingers
    fingers: dict[str, FingerAnatomy] = {}
    myo = None
    if config.world == "myohand":
        fingers, myo = mh.sample_fingers(
            rng,
            [f for f in config.fingers if f != "thumb"],
            hand_scale=scale,
            hand_rotation=hand_rot,
            hand_origin=hand_origin,
            tilt_scale=config.tilt_scale,
        )
    for f in config.fingers:
        if f == "thumb" or myo is not None:
            continue
        fingers[f] = sample_finger(
            rng,
            f,
            hand=config.hand,
            hand_scale=scale,
            hand_rotation=hand_rot,
            hand_origin=hand_origin,
            tilt_scale=config.tilt_scale,
            rolling=config.rolling,
            abduction=config.abduction,
            mp_tilt_deg=config.mp_axis_tilt_deg,
        )
    mounts: dict[str, SensorMount] = {}
    hand_site = hand_origin + hand_rot @ np.array([-45.0, 0.0, 18.0])
    mounts[HAND_SENSOR] = mount(
        rng,
        HAND_SENSOR,
        hand_site,
        hand_rot,
        offset_sd=np.array([5.0, 5.0, 1.0]),
        sta=0.4 * config.sta,
    )
    for f, anat in fingers.items():
        pts = np.vstack([anat.centre, anat.tip])
        for i, s in enumerate(SEGMENTS):
            site = 0.5 * (pts[i] + pts[i + 1]) + SENSOR_HEIGHT[i] * anat.frame[:, 2]
            mounts[sensor_name(f, s)] = mount(
                rng,
                sensor_name(f, s),
                site,
                anat.frame,
                offset_sd=np.array([2.0, 1.5, 0.5]),
                sta=SENSOR_STA[i] * config.sta,
            )
    tracker = TrackerErrors.sample(rng, config.noise, config.distortion)
    # MP ab/adduction per radian of flexion (fingers converge in a fist): about -4 deg over a
    # full grasp, varying between subjects.
    coupling = rng.normal(*config.abduction_coupling, len(fingers)) if config.abduction else None
    flist = list(fingers)
    ts = wh.setup(
        seed,
        with_thumb=with_thumb,
        hand=config.hand,
        fingers=fingers,
        hand_rotation=hand_rot,
        hand_origin=hand_origin,
        hand_scale=scale,
        tilt_scale=config.tilt_scale,
        sta=config.sta,
        myohand=myo,
    )
    mounts.update(ts.mounts)
    trng = ts.rng
    digits = (["thumb"] if with_thumb else []) + flist

    hinge_mcp = ts.thumb is not None and not ts.thumb.mcp_abduction

    def run(m: mo.Motion, name: str, noise: np.random.Generator = rng) -> tuple[Recording, dict]:
        if hinge_mcp:  # a hinge MCP (MyoHand): its ab/adduction stays 0 (held thumb too)
            m.angles["thumb"]["mcp_abduction"] = np.zeros_like(m.time)
        return _run(m, name, fingers, mounts, tracker, noise, ts)

    truth = SubjectTruth(fingers, mounts, config=config, thumb=ts.thumb, pads=ts.pads, myohand=myo)
    static = mo.static(flist, config.rate_hz, 1.5)
    if with_thumb:
        static.angles["thumb"] = wh.static_angles(static.time.size)
    ref, truth.frames["reference.csv"] = run(static, "reference.csv")
    grasp_kw = dict(
        cycles=config.cycles,
        rom_scale=config.rom_scale,
        abduction_coupling=coupling,
        abduction=config.abduction,
        abduction_wander=(np.radians(config.abduction_wander_deg), config.abduction_wander_hz),
        pivot=hand_origin,
    )
    # The thumb's MCP ab/adducts in the grasp and circumduction only with "every".
    thumb_mcp = config.abduction and config.thumb_mcp_abduction == "every"
    if flist:
        grasp_motion = mo.grasp(rng, flist, config.rate_hz, **grasp_kw)
        if with_thumb:
            grasp_motion.angles["thumb"] = wh.grasp_angles(ts, grasp_motion, flist, thumb_mcp)
    else:
        # A thumb alone still grasps on the clock of a grasp cycle (from its own stream).
        clock = mo.grasp(
            trng, ["index"], config.rate_hz, **{**grasp_kw, "abduction_coupling": None}
        )
        clock.angles["thumb"] = wh.grasp_angles(ts, clock, ["index"], thumb_mcp)
        del clock.angles["index"]
        grasp_motion = clock
    grasp, truth.frames["grasp.csv"] = run(grasp_motion, "grasp.csv")
    calibration = [grasp]
    events: list[TargetEvent] = []
    if with_thumb:
        for name, m, contacts in wh.protocols(
            ts,
            fingers,
            config.rate_hz,
            abduction=config.abduction,
            circumduction_mcp_abduction=thumb_mcp,
            pivot=hand_origin,
        ):
            # Recordings only the thumb brings: every sensor's noise from its stream.
            rec, truth.frames[name] = run(m, name, trng)
            calibration.append(rec)
            truth.contacts += wh.contact_truth(ts, fingers, name, contacts, truth.frames[name])
            events += [
                TargetEvent(name, "thumb", c.target, c.start, c.end)
                for c in contacts
                if c.pad_to_pad
            ]

    landmarks: dict[str, FloatArray] = {}
    for f, anat in fingers.items():
        for k, v in anat.landmarks.items():
            landmarks[f"{f}.{k}"] = v + rng.normal(0, config.stylus_mm, 3)
    if with_thumb:
        # Thumb landmarks, then every digit's pad (the pulp's skin point), from the
        # thumb's stream.
        for k, v in ts.thumb.landmarks.items():
            if k != "pad":
                landmarks[f"thumb.{k}"] = v + trng.normal(0, config.stylus_mm, 3)
        for d in digits:
            landmarks[f"{d}.pad"] = ts.pads[d].surface + trng.normal(0, config.stylus_mm, 3)
    targets: list[Recording] = []
    if config.targets and flist:
        tm, tpos, holds = _target_motion(rng, fingers, config)
        if with_thumb:
            tm.angles["thumb"] = ct.thumb_hold(trng, tm.time)
        rec, truth.frames["targets.csv"] = run(tm, "targets.csv")
        targets.append(rec)
        for j in range(N_TARGETS):
            label = f"t{round(j * TARGET_SPACING_MM):03d}"
            # The stylus reading is the mean of five measurements.
            landmarks[f"target.{label}"] = tpos[j] + rng.normal(0, config.stylus_mm / np.sqrt(5), 3)
            events.append(
                TargetEvent("targets.csv", flist[0], label, holds[j, 0] + 0.15, holds[j, 1] - 0.15)
            )
    test: list[Recording] = []
    if config.test:
        fm = mo.free(
            rng,
            flist,
            config.rate_hz,
            abduction_coupling=coupling,
            abduction=config.abduction,
            pivot=hand_origin,
        )
        if with_thumb:
            fm.angles["thumb"] = ct.thumb_free(trng, fm.time, config.abduction and not hinge_mcp)
        rec, truth.frames["test.csv"] = run(fm, "test.csv")
        test.append(rec)
    stylus = None
    if config.stylus_recordings:
        stylus = _stylus_session(
            np.random.default_rng([seed, STYLUS_STREAM]),
            config,
            landmarks,
            digits,
            flist,
            hand_origin,
            run,
            tracker,
        )
    session = Session(
        subject=subject,
        hand=config.hand,
        units="mm",
        rate_hz=config.rate_hz,
        fingers=digits,
        reference=ref,
        grasp=calibration,
        landmarks=landmarks,
        targets=targets,
        test=test,
        events=events,
    )
    return SimulatedSubject(session, truth, stylus)


def _stylus_session(
    rng: np.random.Generator,
    config: SimConfig,
    landmarks: dict[str, FloatArray],
    digits: list[str],
    flist: list[str],
    hand_origin: FloatArray,
    run,
    tracker: TrackerErrors,
):
    """The subject's stylus recordings (:mod:`.stylus`), from their own random stream
    after every other recording (nothing else changes with them)."""
    from ..stylus.landmarks import landmark_names
    from .stylus import stylus_session

    targets = tuple(k.removeprefix("target.") for k in landmarks if k.startswith("target."))
    order = landmark_names(digits, pads=any(k.endswith(".pad") for k in landmarks), targets=targets)
    # The SD of each landmark's mean: as the session's landmarks were drawn.
    sd = {k: config.stylus_mm / (np.sqrt(5) if k.startswith("target.") else 1.0) for k in order}

    def still(time, rotation, translation, name, noise):
        m = mo.static(flist, config.rate_hz, 0.0)
        m.time, m.hand_rotation, m.hand_translation = time, rotation, translation
        zero = np.zeros_like(time)
        m.angles = {f: dict.fromkeys(mo.ANGLE_KEYS, zero) for f in flist}
        if "thumb" in digits:
            m.angles["thumb"] = wh.static_angles(time.size)
        return run(m, name, noise)[0]

    return stylus_session(
        rng,
        landmarks=landmarks,
        landmark_sd=sd,
        order=order,
        pivot_point=hand_origin + np.array([120.0, 40.0, -60.0]),
        hand_origin=hand_origin,
        rate_hz=config.rate_hz,
        run=still,
        apply_errors=tracker.apply,
    )


def write_subject(sim: SimulatedSubject, directory: str | Path) -> Path:
    """Write the session directory plus ``truth.json`` and ``truth/<recording>.csv``."""
    directory = Path(directory)
    sim.session.path = directory
    save_session(sim.session, directory)
    if sim.stylus is not None:
        from ..io.posewrite import write_pose_csv
        from .stylus import LANDMARKS_RECORDING, PIVOT_FILE

        write_pose_csv(directory / PIVOT_FILE, sim.stylus.pivot)
        write_pose_csv(directory / LANDMARKS_RECORDING, sim.stylus.landmarks)
    write_truth(sim, directory)
    return directory


def simulate_cohort(config: SimConfig, n_subjects: int, seed: int) -> list[SimulatedSubject]:
    """``n_subjects`` independent subjects named by :func:`subject_ids`; subject i uses
    seed ``(seed, i)``."""
    seeds = np.random.SeedSequence(seed).spawn(n_subjects)
    return [
        simulate_subject(config, int(s.generate_state(1)[0]), name)
        for s, name in zip(seeds, subject_ids(n_subjects), strict=True)
    ]


def subject_ids(n_subjects: int) -> list[str]:
    """The IDs of a simulated cohort: ``S`` + the subject's number zero-padded to the
    digits of ``n_subjects`` (at least 2: ``S01``, ``S001``, ``S0001``), so they sort in
    order."""
    width = max(2, len(str(n_subjects)))
    return [f"S{i + 1:0{width}d}" for i in range(n_subjects)]


__all__ = [
    "SimConfig",
    "SimulatedSubject",
    "SubjectTruth",
    "simulate_cohort",
    "simulate_subject",
    "write_subject",
]
