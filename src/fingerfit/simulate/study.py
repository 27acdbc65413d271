"""Simulated subjects and cohorts with ground truth.

:func:`simulate_subject` draws one subject's anatomy, sensor mounts and
tracker errors, runs the paper's protocol (reference, grasp, target reaching,
free-motion test) and returns the measured :class:`~fingerfit.session.Session`
together with the :class:`SubjectTruth`. :func:`write_subject` saves both:
the session directory plus ``truth.json`` and ``truth/<recording>.csv``.
With ``thumb`` among the digits, :mod:`.wholehand` adds the thumb to every recording
and its own calibration recordings (circumduction, opposition, pinches), from the
thumb's own random stream.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from ..errors import FingerfitError
from ..io.atomic import atomic_write
from ..io.sessiondir import save_session
from ..session import (
    HAND_SENSOR,
    JOINTS,
    SEGMENTS,
    PoseSeries,
    Recording,
    Session,
    TargetEvent,
    sensor_name,
)
from ..transforms import FloatArray, apply_inverse_pose, quat_wxyz_from_matrix
from . import contact as ct
from . import motion as mo
from . import myohand as mh
from . import wholehand as wh
from .anatomy import FingerAnatomy, sample_finger, segment_motions
from .sensors import SensorMount, TrackerErrors, mount, sensor_poses
from .thumb import THUMB_KEYS, Pad, ThumbAnatomy

TRUTH_FORMAT = "fingerfit.truth/1"
#: The true hands a session can be simulated from (``SimConfig.world``).
WORLDS = ("default", "myohand")
TARGET_SPACING_MM = 20.0
N_TARGETS = 7
SENSOR_HEIGHT = np.array([7.5, 6.5, 5.0])  # dorsal height of phalanx sensors (mm)
# Relative skin sliding under the phalanx sensors; the distal one sits on the nail.
SENSOR_STA = np.array([1.0, 1.0, 0.3])


@dataclass(frozen=True)
class SimConfig:
    """Switches and magnitudes of a simulated session.

    Every error source can be switched off; :meth:`exact` gives the noise-free,
    pure-hinge configuration used to check exactness.

    Attributes
    ----------
    fingers : tuple of str
        Digits: any of ``thumb``, ``index``, ``middle``, ``ring``, ``little``. The thumb
        adds its own recordings (:mod:`.wholehand`) and draws everything from its own
        generator, so the fingers' truth does not depend on it.
    hand : {"left", "right"}
    rate_hz : float
    noise : float
        Tracker error scale (white noise and field distortion); 1 = Liberty-like.
    distortion : bool
        Smooth field distortion on/off (scaled by ``noise``).
    sta : float
        Soft-tissue artefact scale (1 = realistic, 0 = rigid sensors).
    stylus_mm : float
        Stylus noise SD per axis (mm).
    tilt_scale : float
        Axis obliquity scale (1 = literature; 0 = axes perpendicular to bones).
    rolling : bool
        Centre of rotation migrating with flexion.
    abduction : bool
        MP ab/adduction axis moving during grasp and free motion (the thumb's MCP
        ab/adduction likewise; its CMC always has two axes).
    abduction_coupling : tuple of float
        MP ab/adduction per radian of MP flexion (rad/rad): mean and SD over subjects and
        fingers (drawn per finger).
    abduction_wander_deg, abduction_wander_hz : float
        The MP ab/adduction independent of flexion during the grasp cycles: SD (deg) and
        the highest frequency (Hz) of its slow wander (frequencies from 0.05 Hz up).
    thumb_mcp_abduction : {"every", "contact"}
        Recordings in which the thumb's MCP ab/adducts (with ``abduction``): ``every``
        one, or only the opposition and pinch recordings (and free motion).
    rom_scale : float
        Grasp range-of-motion scale.
    cycles : int
        Grasp cycles.
    targets, test : bool
        Include the target-reaching and free-motion recordings.
    world : {"default", "myohand"}
        The true hand: fingerfit's own anatomy (:mod:`.anatomy`, :mod:`.thumb`) or the
        MyoHand model's fingers and thumb (:mod:`.myohand`: right hand, fixed axes, so
        ``rolling`` has no effect there, and a hinge thumb MCP; ``tilt_scale`` scales its
        per-subject axis scatter).
    mp_axis_tilt_deg : float, optional
        Sets every finger's MP flexion-axis obliquity off perpendicular to the bone (deg,
        about the finger's dorsal axis z: positive turns the axis's +y end distally) in
        place of the drawn one; the dorsal tilt and everything else are drawn as usual.
        ``None`` (default): the drawn obliquity, every output as without the field.
        Default world only; ``|value| < 60``.
    """

    fingers: tuple[str, ...] = ("index",)
    hand: str = "left"
    rate_hz: float = 240.0
    noise: float = 1.0
    distortion: bool = True
    sta: float = 1.0
    stylus_mm: float = 0.3
    tilt_scale: float = 1.0
    rolling: bool = True
    abduction: bool = True
    abduction_coupling: tuple[float, float] = (-0.07, 0.04)
    abduction_wander_deg: float = 1.0
    abduction_wander_hz: float = 0.3
    thumb_mcp_abduction: str = "every"
    rom_scale: float = 1.0
    cycles: int = 10
    targets: bool = True
    test: bool = True
    world: str = "default"
    mp_axis_tilt_deg: float | None = None

    def __post_init__(self) -> None:
        if self.world not in WORLDS:
            raise FingerfitError(
                f"must be one of {', '.join(WORLDS)}, not {self.world!r}", field="--world"
            )
        tilt = self.mp_axis_tilt_deg
        if tilt is not None:
            if not (np.isfinite(tilt) and abs(tilt) < 60.0):
                raise FingerfitError(
                    f"must be a finite angle below 60 deg in magnitude, not {tilt!r}",
                    field="mp_axis_tilt_deg",
                )
            if self.world != "default":
                raise FingerfitError(
                    "the MP axis tilt is an option of the default world only",
                    field="mp_axis_tilt_deg",
                )

    @classmethod
    def exact(cls, **kw) -> SimConfig:
        """Noise-free, rigid sensors, pure hinges: the model is exactly right."""
        base = dict(
            noise=0.0, distortion=False, sta=0.0, stylus_mm=0.0, rolling=False, abduction=False
        )
        base.update(kw)
        return cls(**base)


@dataclass
class SubjectTruth:
    """Ground truth of one simulated subject (mm, rad, tracker coordinates).

    Attributes
    ----------
    fingers : dict[str, FingerAnatomy]
        True geometry at the reference posture (the four fingers only).
    mounts : dict[str, SensorMount]
        True sensor poses at the reference posture (before artefact and noise), thumb
        sensors included.
    frames : dict[str, dict]
        Per recording: ``time`` ``(n,)``, ``angles[digit][key]`` ``(n,)`` rad,
        ``tip[digit]`` and ``pad[digit]`` (pulp centre) ``(n, 3)`` mm, ``sensors[name]``
        noise-free ``(position (n, 3), rotation (n, 3, 3))``, ``motions[name]`` the
        segment motions ``(R (n, 3, 3), t (n, 3))`` relative to the reference posture.
    config : SimConfig
    thumb : ThumbAnatomy or None
        The thumb's true geometry (None without a thumb).
    pads : dict[str, Pad]
        Every digit's pad (pulp centre, half-thickness, skin point).
    contacts : list of dict
        Every touch of the thumb (:func:`.wholehand.contact_truth`).
    myohand : MyoHandSubject or None
        The subject's MyoHand parameters (``world="myohand"`` only).
    """

    fingers: dict[str, FingerAnatomy]
    mounts: dict[str, SensorMount]
    frames: dict[str, dict] = field(default_factory=dict)
    config: SimConfig = field(default_factory=SimConfig)
    thumb: ThumbAnatomy | None = None
    pads: dict[str, Pad] = field(default_factory=dict)
    contacts: list[dict] = field(default_factory=list)
    myohand: mh.MyoHandSubject | None = None


@dataclass
class SimulatedSubject:
    session: Session
    truth: SubjectTruth


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
    return SimulatedSubject(session, truth)


def truth_document(sim: SimulatedSubject) -> dict:
    """``truth.json`` content: true geometry at the reference posture (tracker and sensor frames)."""
    truth = sim.truth
    ref_sensor = {name: (m.position, m.rotation) for name, m in truth.mounts.items()}
    fingers = {}
    for f, anat in truth.fingers.items():
        joints = {}
        parents = [HAND_SENSOR] + [sensor_name(f, s) for s in SEGMENTS]
        for i, j in enumerate(JOINTS):
            pp, pr = ref_sensor[parents[i]]
            joints[j] = {
                "center": anat.centre[i].tolist(),
                "axis": anat.axis[i].tolist(),
                "rolling_mm_per_rad": anat.rolling[i].tolist(),
                "parent_sensor": parents[i],
                "center_in_parent": (pr.T @ (anat.centre[i] - pp)).tolist(),
                "axis_in_parent": (pr.T @ anat.axis[i]).tolist(),
            }
        fingers[f] = {
            "joints": joints,
            "mp_abduction": {
                "point": anat.abduction_point.tolist(),
                "axis": anat.abduction_axis.tolist(),
            },
            "segment_lengths": dict(zip(SEGMENTS, anat.lengths.tolist(), strict=True)),
            "tip": anat.tip.tolist(),
            "landmarks": {k: v.tolist() for k, v in anat.landmarks.items()},
        }
        if anat.order != FingerAnatomy.order:
            fingers[f]["axis_order"] = {"mp": list(anat.order)}
        if f in truth.pads:
            fingers[f].update(_pad_document(truth.pads[f]))
    if truth.thumb is not None:
        thumb = wh.thumb_document(truth.thumb, ref_sensor)
        thumb.update(_pad_document(truth.thumb.pad))
        fingers = {"thumb": thumb, **fingers}
    config = asdict(truth.config)
    if config["world"] == "default":
        del config["world"]  # truth.json of the default world as before the field existed
    if config["mp_axis_tilt_deg"] is None:
        del config["mp_axis_tilt_deg"]  # likewise
    doc = {
        "format": TRUTH_FORMAT,
        "subject": sim.session.subject,
        "units": "mm",
        "frame": "tracker coordinates at the reference posture; *_in_parent: parent sensor frame",
        "config": config,
        "sensors": {
            name: {"position": p.tolist(), "quat_wxyz": quat_wxyz_from_matrix(r).tolist()}
            for name, (p, r) in ref_sensor.items()
        },
        "fingers": fingers,
        "contacts": truth.contacts,
    }
    if truth.myohand is not None:
        doc["myohand"] = truth.myohand.document()
    return doc


def _pad_document(pad: Pad) -> dict:
    return {
        "pad": pad.surface.tolist(),
        "pad_center": pad.centre.tolist(),
        "pad_half_thickness_mm": pad.half_thickness,
    }


def truth_table(frames: dict, pads: dict[str, Pad] | None = None) -> pd.DataFrame:
    """Per-frame truth of one recording (tracker coordinates, mm; angles deg).

    Columns: ``time``; per digit ``<digit>.<angle>`` (``mp``, ``mp_abduction``, ``pip``,
    ``dip``; the thumb's ``cmc``, ``cmc_abduction``, ``mcp``, ``mcp_abduction``, ``ip``)
    and ``<digit>.tip.x|y|z``; with ``pads``, ``<digit>.pad.x|y|z`` (the pulp's skin
    point, as the ``<digit>.pad`` landmark) and, with the thumb,
    ``thumb.pad_distance.<finger>``: thumb to finger pulp centre (pads touch at the sum
    of the half-thicknesses) and ``thumb.contact.<finger>.x|y|z``: the point of the thumb's
    pulp surface on the line between the two pulp centres, where the pulps touch during
    that finger's pad-to-pad events (every frame; meaningful while they touch).
    """
    cols: dict[str, FloatArray] = {"time": frames["time"]}
    for f, ang in frames["angles"].items():
        for k in THUMB_KEYS if f == "thumb" else mo.ANGLE_KEYS:
            cols[f"{f}.{k}"] = np.degrees(ang[k])
        for i, c in enumerate("xyz"):
            cols[f"{f}.tip.{c}"] = frames["tip"][f][:, i]
        if pads and f in pads and f in frames.get("pad", {}):
            # Skin point = centre moved palmar by the half-thickness, carried by the
            # distal segment: centre + R (surface - centre).
            r = frames["motions"][f"{f}.distal"][0]
            skin = frames["pad"][f] + r @ (pads[f].surface - pads[f].centre)
            for i, c in enumerate("xyz"):
                cols[f"{f}.pad.{c}"] = skin[:, i]
    if "thumb" in frames["angles"] and pads:
        for f in frames["angles"]:
            if f != "thumb" and f in frames.get("pad", {}):
                line = frames["pad"][f] - frames["pad"]["thumb"]
                dist = np.linalg.norm(line, axis=1)
                cols[f"thumb.pad_distance.{f}"] = dist
                contact = frames["pad"]["thumb"] + pads["thumb"].half_thickness * (
                    line / dist[:, None]
                )
                for i, c in enumerate("xyz"):
                    cols[f"thumb.contact.{f}.{c}"] = contact[:, i]
    return pd.DataFrame(cols)


def write_subject(sim: SimulatedSubject, directory: str | Path) -> Path:
    """Write the session directory plus ``truth.json`` and ``truth/<recording>.csv``."""
    directory = Path(directory)
    sim.session.path = directory
    save_session(sim.session, directory)
    write_truth(sim, directory)
    return directory


def write_truth(sim: SimulatedSubject, directory: str | Path) -> None:
    """Write ``truth.json`` and ``truth/<recording>.csv`` into ``directory``."""
    directory = Path(directory)
    with atomic_write(directory / "truth.json") as fh:
        json.dump(truth_document(sim), fh, indent=1)
    for name, frames in sim.truth.frames.items():
        with atomic_write(directory / "truth" / name, newline="") as fh:
            truth_table(frames, sim.truth.pads).to_csv(fh, index=False, lineterminator="\n")


def simulate_cohort(config: SimConfig, n_subjects: int, seed: int) -> list[SimulatedSubject]:
    """``n_subjects`` independent subjects ``S01..``; subject i uses seed ``(seed, i)``."""
    seeds = np.random.SeedSequence(seed).spawn(n_subjects)
    return [
        simulate_subject(config, int(s.generate_state(1)[0]), f"S{i + 1:02d}")
        for i, s in enumerate(seeds)
    ]


def relative_truth_in_parent(
    sim: SimulatedSubject, finger: str, joint: str
) -> tuple[FloatArray, FloatArray]:
    """True joint centre ``(3,)`` mm and axis ``(3,)`` in the parent sensor frame at reference.

    For the thumb, ``joint`` is any of ``cmc``, ``cmc_abduction``, ``mcp``,
    ``mcp_abduction``, ``ip``; the centre of a second axis is the point of its line
    nearest the flexion axis.
    """
    if finger == "thumb":
        th = sim.truth.thumb
        if th is None:
            raise ValueError("the simulated subject has no thumb")
        flexion = joint.removesuffix("_abduction")
        parent = {"cmc": HAND_SENSOR, "mcp": "thumb.metacarpal", "ip": "thumb.proximal"}[flexion]
        m = sim.truth.mounts[parent]
        c = apply_inverse_pose(m.rotation[None], m.position[None], th.axis_point[joint][None])[0]
        return c, m.rotation.T @ th.axis[joint]
    i = JOINTS.index(joint)
    parent = HAND_SENSOR if i == 0 else sensor_name(finger, SEGMENTS[i - 1])
    m = sim.truth.mounts[parent]
    anat = sim.truth.fingers[finger]
    c = apply_inverse_pose(m.rotation[None], m.position[None], anat.centre[i][None])[0]
    return c, m.rotation.T @ anat.axis[i]


__all__ = [
    "SimConfig",
    "SimulatedSubject",
    "SubjectTruth",
    "simulate_cohort",
    "simulate_subject",
    "write_subject",
]
