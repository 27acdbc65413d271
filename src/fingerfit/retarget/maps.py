"""Robot maps: how a person's hand model corresponds to a robot hand (a small TOML file).

A map names the robot's palm frame and, per digit, its tip frame, the robot joint at the
digit's base (its anchor is the digit's MP/CMC centre), each human joint's robot joint
(``robot = sign * scale * human + offset``), an optional per-digit scale, the couplings
between robot joints (``lo <= c0 q0 + c1 q1 <= hi``, e.g. Shadow's J1/J0 tendon band),
the neutral posture of joints that are held (wrist) and the thumb-finger pinch pairs.
``docs/retargeting.md`` documents every field; the shipped maps (``maps/*.toml``) are
written the same way. Every problem is a :class:`FingerfitError` naming the map file and
the field.
"""

from __future__ import annotations

import importlib.metadata
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FingerfitError, shown
from ..transforms import FloatArray
from .robots import EXTRA, Robot

#: Human joints (angle names of ``fingerfit.kinematics``) each digit may map.
HUMAN_JOINTS: dict[str, tuple[str, ...]] = {
    **{f: ("mp", "pip", "dip", "mp_abduction") for f in ("index", "middle", "ring", "little")},
    "thumb": ("cmc", "mcp", "ip", "cmc_abduction", "mcp_abduction"),
}
#: Built-in robots: name -> map file per hand side (``maps/``).
BUILTIN = {
    "shadow": {"right": "shadow.toml", "left": "shadow.toml"},
    "allegro": {"right": "allegro_right.toml", "left": "allegro_left.toml"},
}


@dataclass(frozen=True)
class JointLink:
    """One human joint -> one robot joint: ``robot = sign * scale * human + offset`` (rad)."""

    robot: str
    sign: float = 1.0
    scale: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class DigitMap:
    """One digit on the robot.

    Attributes
    ----------
    tip : str
        Robot frame the person's fingertip (nail edge) maps to.
    base : str
        Robot joint whose anchor is the digit's base (MP, thumb CMC).
    pad : str
        Robot frame for the pinch term (the person's pad point maps to it; default ``tip``).
    pad_offset : ndarray, shape (3,), or None
        The pad point's offset from ``pad`` (m, in ``pad``'s axes), for robots whose files
        name no frame on the fingertip's pulp (Allegro: the tip sphere's centre); ``None``:
        the frame itself. :func:`fingerfit.retarget.resolve` adds the point to the robot as
        :func:`pad_point_name` and names it in ``pad``.
    scale : float or None
        Robot chain length over the person's; ``None``: measured (:mod:`.palm`).
    joints : dict[str, JointLink]
        Human joint name (``mp``, ``pip``, ``mp_abduction``, ``cmc``, ...) -> robot joint.
    """

    tip: str
    base: str
    pad: str
    scale: float | None
    joints: dict[str, JointLink]
    pad_offset: FloatArray | None = None


#: Largest pad offset (m): a larger one is a unit mistake (mm for m), not a fingertip.
PAD_OFFSET_MAX = 0.05


def pad_point_name(digit: str) -> str:
    """Name of the robot frame :func:`fingerfit.retarget.resolve` adds for a ``pad_offset``."""
    return f"fingerfit:{digit}.pad"


@dataclass(frozen=True)
class Coupling:
    """``lo <= coef[0] * q[joints[0]] + coef[1] * q[joints[1]] <= hi`` (rad, any units)."""

    joints: tuple[str, str]
    coef: tuple[float, float]
    lo: float
    hi: float


@dataclass(frozen=True)
class RobotMap:
    """A parsed map file.

    Attributes
    ----------
    path : Path
        The map file.
    name : str
    robot_file : Path or None
        The robot file it names (absolute), if any.
    hand : {"right", "left"}
        The robot's handedness (a model of the other hand is mirrored onto it).
    palm : str
        Robot frame of the palm.
    distal, dorsal : ndarray, shape (3,)
        Unit directions of the palm frame's x (distal, along the fingers) and z (dorsal)
        axes, in the ``palm`` frame's coordinates.
    neutral : dict[str, float]
        Robot joint -> value held (rad): the wrist, and joints of digits the model lacks
        (default 0 clipped to the limits).
    digits : dict[str, DigitMap]
    couplings : list[Coupling]
    pinch : list[tuple[str, str]]
        (thumb, finger) digit pairs whose pad points must meet when the person's do.
    """

    path: Path
    name: str
    robot_file: Path | None
    hand: str
    palm: str
    distal: FloatArray
    dorsal: FloatArray
    neutral: dict[str, float]
    digits: dict[str, DigitMap]
    couplings: list[Coupling] = field(default_factory=list)
    pinch: list[tuple[str, str]] = field(default_factory=list)


class _Fields:
    """Typed access to the TOML document with errors naming the file and the field."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def err(self, where: str, message: str) -> FingerfitError:
        return FingerfitError(message, path=self.path, field=where)

    def table(self, doc: Any, where: str, allowed: tuple[str, ...] | None = None) -> dict:
        if not isinstance(doc, dict):
            raise self.err(where, f"must be a table, not {type(doc).__name__}")
        if allowed is not None:
            extra = [k for k in doc if k not in allowed]
            if extra:
                raise self.err(
                    f"{where}.{extra[0]}" if where else extra[0],
                    f"unknown key (allowed: {', '.join(allowed)})",
                )
        return doc

    def string(self, doc: dict, key: str, where: str, default: str | None = None) -> str:
        if key not in doc:
            if default is not None:
                return default
            raise self.err(f"{where}.{key}" if where else key, "missing")
        v = doc[key]
        if not isinstance(v, str) or not v:
            raise self.err(f"{where}.{key}" if where else key, "must be a non-empty string")
        return v

    def number(self, v: Any, where: str) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v):
            raise self.err(where, f"must be a finite number, not {shown(v)}")
        return float(v)

    def vector(self, doc: dict, key: str, where: str) -> FloatArray:
        v = doc.get(key)
        if not isinstance(v, list) or len(v) != 3:
            raise self.err(f"{where}.{key}", "must be a list of 3 numbers")
        a = np.array([self.number(x, f"{where}.{key}") for x in v])
        n = np.linalg.norm(a)
        if n < 1e-9:
            raise self.err(f"{where}.{key}", "must not be the zero vector")
        return a / n


def _robot_file(f: _Fields, doc: dict) -> Path | None:
    if "file" not in doc:
        return None
    rel = f.string(doc, "file", "robot")
    if "package" in doc:
        package = f.string(doc, "package", "robot")
        try:
            dist = importlib.metadata.distribution(package)
        except importlib.metadata.PackageNotFoundError:
            raise FingerfitError(
                f"the robot file is shipped by the Python package '{package}', which is not "
                f"installed: pip install fingerfit[{EXTRA}]",
                path=f.path,
                field="robot.package",
            ) from None
        path = Path(str(dist.locate_file(rel)))
    else:
        path = (f.path.parent / rel).resolve()
    if not path.is_file():
        raise f.err("robot.file", f"robot file not found: {path}")
    return path


def _link(f: _Fields, v: Any, where: str) -> JointLink:
    if isinstance(v, str):
        v = {"robot": v}
    d = f.table(v, where, ("robot", "sign", "scale", "offset"))
    sign = f.number(d.get("sign", 1.0), f"{where}.sign")
    if sign not in (1.0, -1.0):
        raise f.err(f"{where}.sign", "must be 1 or -1")
    return JointLink(
        f.string(d, "robot", where),
        sign,
        f.number(d.get("scale", 1.0), f"{where}.scale"),
        f.number(d.get("offset", 0.0), f"{where}.offset"),
    )


def parse_map(path: str | Path, text: str | None = None) -> RobotMap:
    """Read and check a map file (without the robot: see :func:`check_map`).

    Parameters
    ----------
    path : str or Path
        The TOML file (``text`` overrides its content, for package resources).

    Returns
    -------
    RobotMap

    Raises
    ------
    FingerfitError
        Naming the file and the field.
    """
    path = Path(path)
    f = _Fields(path)
    try:
        if text is None:
            text = path.read_text(encoding="utf-8")
        doc = tomllib.loads(text)
    except FileNotFoundError:
        raise FingerfitError("map file not found", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FingerfitError(f"cannot read map file: {exc}", path=path) from None
    except tomllib.TOMLDecodeError as exc:
        raise FingerfitError(f"not valid TOML: {exc}", path=path) from None
    f.table(doc, "", ("robot", "neutral", "digits", "coupling", "pinch"))
    robot = f.table(
        doc.get("robot"),
        "robot",
        (
            "name",
            "file",
            "package",
            "hand",
            "palm",
            "distal",
            "dorsal",
        ),
    )
    hand = f.string(robot, "hand", "robot")
    if hand not in ("right", "left"):
        raise f.err("robot.hand", "must be right or left")
    neutral_doc = f.table(doc.get("neutral", {}), "neutral")
    neutral = {k: f.number(v, f"neutral.{k}") for k, v in neutral_doc.items()}
    digits_doc = f.table(doc.get("digits"), "digits", tuple(HUMAN_JOINTS))
    if not digits_doc:
        raise f.err("digits", "must name at least one digit")
    digits: dict[str, DigitMap] = {}
    for name, dd in digits_doc.items():
        w = f"digits.{name}"
        d = f.table(dd, w, ("tip", "base", "pad", "pad_offset", "scale", "joints"))
        tip = f.string(d, "tip", w)
        joints_doc = f.table(d.get("joints", {}), f"{w}.joints", HUMAN_JOINTS[name])
        joints = {j: _link(f, v, f"{w}.joints.{j}") for j, v in joints_doc.items()}
        scale = None
        if "scale" in d:
            scale = f.number(d["scale"], f"{w}.scale")
            if scale <= 0:
                raise f.err(f"{w}.scale", "must be > 0")
        offset = None
        if "pad_offset" in d:
            v = d["pad_offset"]
            if not isinstance(v, list) or len(v) != 3:
                raise f.err(f"{w}.pad_offset", "must be a list of 3 numbers (m)")
            offset = np.array([f.number(x, f"{w}.pad_offset") for x in v])
            if np.linalg.norm(offset) > PAD_OFFSET_MAX:
                raise f.err(
                    f"{w}.pad_offset",
                    f"{np.linalg.norm(offset):.3g} m from the pad frame: give metres "
                    f"(at most {PAD_OFFSET_MAX} m)",
                )
        digits[name] = DigitMap(
            tip, f.string(d, "base", w), f.string(d, "pad", w, tip), scale, joints, offset
        )
    couplings = []
    cdoc = doc.get("coupling", [])
    if not isinstance(cdoc, list):
        raise f.err("coupling", "must be an array of tables ([[coupling]])")
    for i, c in enumerate(cdoc):
        w = f"coupling[{i}]"
        c = f.table(c, w, ("joints", "coef", "range"))
        js, coef, rng = c.get("joints"), c.get("coef"), c.get("range")
        if not (isinstance(js, list) and len(js) == 2 and all(isinstance(x, str) for x in js)):
            raise f.err(f"{w}.joints", "must be a list of 2 robot joint names")
        if not (isinstance(coef, list) and len(coef) == 2):
            raise f.err(f"{w}.coef", "must be a list of 2 numbers")
        if not (isinstance(rng, list) and len(rng) == 2):
            raise f.err(f"{w}.range", "must be a list [lo, hi]")
        cf = tuple(f.number(x, f"{w}.coef") for x in coef)
        lo, hi = (f.number(x, f"{w}.range") for x in rng)
        if 0.0 in cf:
            raise f.err(f"{w}.coef", "coefficients must be non-zero")
        if lo > hi or js[0] == js[1]:
            raise f.err(
                f"{w}.range" if lo > hi else f"{w}.joints",
                "must have lo <= hi and two different joints",
            )
        couplings.append(Coupling((js[0], js[1]), cf, lo, hi))  # type: ignore[arg-type]
    used = [j for c in couplings for j in c.joints]
    dup = sorted({j for j in used if used.count(j) > 1})
    if dup:
        raise f.err("coupling", f"joint '{dup[0]}' is in more than one coupling")
    pinch = []
    pdoc = doc.get("pinch", [])
    if not isinstance(pdoc, list):
        raise f.err("pinch", "must be an array of tables ([[pinch]])")
    for i, p in enumerate(pdoc):
        w = f"pinch[{i}]"
        p = f.table(p, w, ("digits",))
        ds = p.get("digits")
        if not (isinstance(ds, list) and len(ds) == 2 and all(x in digits for x in ds)):
            raise f.err(f"{w}.digits", "must be 2 digits of [digits]")
        pinch.append((ds[0], ds[1]))
    return RobotMap(
        path=path,
        name=f.string(robot, "name", "robot", path.stem),
        robot_file=_robot_file(f, robot),
        hand=hand,
        palm=f.string(robot, "palm", "robot"),
        distal=f.vector(robot, "distal", "robot"),
        dorsal=f.vector(robot, "dorsal", "robot"),
        neutral=neutral,
        digits=digits,
        couplings=couplings,
        pinch=pinch,
    )


def check_map(rmap: RobotMap, robot: Robot) -> None:
    """Check every robot frame and joint the map names against the robot.

    Raises
    ------
    FingerfitError
        Naming the map file and the field of the first unknown frame or joint, or a palm
        frame that moves with the digits' joints.
    """
    f = _Fields(rmap.path)
    names = set(robot.joint_names)

    def frame(name: str, where: str) -> None:
        if not robot.has_frame(name):
            raise f.err(where, f"unknown robot frame '{shown(name)}' in {robot.path.name}")

    def joint(name: str, where: str) -> None:
        if name not in names:
            raise f.err(where, f"unknown robot joint '{shown(name)}' in {robot.path.name}")

    frame(rmap.palm, "robot.palm")
    if abs(float(rmap.distal @ rmap.dorsal)) > 0.1:
        raise f.err("robot.dorsal", "must be perpendicular to robot.distal")
    for j in rmap.neutral:
        joint(j, f"neutral.{j}")
    for d, dm in rmap.digits.items():
        frame(dm.tip, f"digits.{d}.tip")
        frame(dm.pad, f"digits.{d}.pad")
        joint(dm.base, f"digits.{d}.base")
        for h, link in dm.joints.items():
            joint(link.robot, f"digits.{d}.joints.{h}.robot")
    for i, c in enumerate(rmap.couplings):
        for j in c.joints:
            joint(j, f"coupling[{i}].joints")
    palm = set(robot.ancestors(rmap.palm))
    for d, dm in rmap.digits.items():
        for j in robot.ancestors(dm.tip):
            if j in palm and robot.joint_names[j] not in rmap.neutral:
                raise f.err(
                    "neutral",
                    f"joint '{robot.joint_names[j]}' moves the palm frame and digit {d}: "
                    "hold it in [neutral]",
                )


def builtin_map(name: str, hand: str) -> RobotMap:
    """The shipped map of a built-in robot (``shadow``, ``allegro``) for a model's hand side.

    Parameters
    ----------
    name : str
    hand : {"right", "left"}
        The person's hand (Allegro has a left and a right hand; Shadow only a right one).
    """
    if name not in BUILTIN:
        raise FingerfitError(
            f"unknown robot '{shown(name)}' (built in: {', '.join(BUILTIN)}; "
            "or give a .urdf/.xml file with --map)",
            field="--robot",
        )
    file = BUILTIN[name][hand if hand in ("right", "left") else "right"]
    res = resources.files("fingerfit.retarget") / "maps" / file
    return parse_map(Path(str(res)), res.read_text(encoding="utf-8"))
