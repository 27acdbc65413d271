"""The session folder a capture records into: everything it will read and write,
checked before the source opens (:func:`plan_capture`), and the files written together
once the recording ends (:func:`write_capture`).

Checked first: the folder's ``session.toml`` (or the options that start one) and that the
options agree with it; the recording's name and every file to be written (none an input,
none read-only, an existing one replaced only with ``--overwrite``); the recordings the
folder lists; the reference recording, which must have samples of every sensor of the
session's digits; the landmarks. Nothing is written until the recording is complete: the
copies of ``--reference`` and ``--landmarks``, the recording and ``session.toml`` are
written all or none (:func:`fingerfit.io.atomic.write_files`), so a capture that is
refused or interrupted before recording leaves the folder as it was.
"""

from __future__ import annotations

import json
import tempfile
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..digits import DIGIT_NAMES
from ..errors import FingerfitError, shown
from ..io.sessiondir import EVENTS_FILE, LANDMARKS_FILE, SESSION_FILE
from ..session import UNITS_TO_MM, Recording, Session, check_subject_id, digit_sensors
from .protocols import HOLD_PROTOCOLS, RECORDING_LIST, next_recording, shown_digits

#: Defaults of a new session (``fingerfit capture`` without ``session.toml``).
NEW_SESSION = {"hand": "left", "units": "mm", "rate_hz": 240.0}
#: File names a recording may not take.
_RESERVED = (SESSION_FILE, LANDMARKS_FILE, EVENTS_FILE)


@dataclass
class CapturePlan:
    """A capture, checked: what it records, from what, and every file it will write.

    Attributes
    ----------
    folder : Path
    protocol : str
    name : str
        The recording's file name (``grasp.csv``; ``.parquet``: Parquet).
    meta : dict
        ``session.toml``'s content (read, or made of the options).
    digits : list of str
        The session's digits.
    shown : list of str
        The digits whose joints the protocol shows.
    sensors : list of str
        The recording's sensors (those of ``digits``, hand first).
    base : Session
        The reference (mm), the calibration recordings the folder lists (the one being
        replaced left out), the landmarks: what the evidence pools with the recording.
    copies : dict of Path to bytes
        ``--reference`` and ``--landmarks`` to copy into the folder, with the recording.
    overwrite : bool
    new : bool
        The folder has no ``session.toml`` yet.
    """

    folder: Path
    protocol: str
    name: str
    meta: dict
    digits: list[str]
    shown: list[str]
    sensors: list[str]
    base: Session
    copies: dict[Path, bytes] = field(default_factory=dict)
    overwrite: bool = False
    new: bool = False

    @property
    def target(self) -> Path:
        """The recording's path."""
        return self.folder / self.name

    @property
    def units(self) -> str:
        return str(self.meta["units"])

    @property
    def rate_hz(self) -> float:
        return float(self.meta["rate_hz"])


def plan_capture(
    folder: Path,
    protocol: str,
    name: str | None = None,
    *,
    subject: str | None = None,
    hand: str | None = None,
    units: str | None = None,
    rate: float | None = None,
    fingers: list[str] | None = None,
    reference: Path | None = None,
    landmarks: Path | None = None,
    inputs: tuple[Path, ...] = (),
    overwrite: bool = False,
) -> CapturePlan:
    """Check a capture before its source opens (module docstring).

    Parameters
    ----------
    folder : Path
        The session folder.
    protocol : str
        A key of :data:`fingerfit.capture.PROTOCOLS`.
    name : str, optional
        The recording's file name (default: the protocol's next,
        :func:`fingerfit.capture.protocols.next_recording`).
    subject, hand, units, rate, fingers
        ``--subject`` ... ``--fingers`` as given (None: not given). They start a
        folder without ``session.toml``; with one, each given must agree with it.
    reference, landmarks : Path, optional
        Files to copy into the folder as its reference recording and ``landmarks.csv``.
    inputs : tuple of Path
        Other files the capture reads (a replayed recording), never written onto.
    overwrite : bool
        Replace the recording (and the copies) if they exist.

    Returns
    -------
    CapturePlan

    Raises
    ------
    FingerfitError
        One line naming the option, file or field at fault; nothing is written.
    """
    from ..io import read_pose_csv
    from ..io.atomic import check_target, refuse_writing_inputs
    from ..io.sessiondir import read_landmarks

    meta, new = _session_meta(folder, subject, hand, units, rate, fingers)
    listed = _listed(meta)
    name = name or next_recording(protocol, folder)
    suffix = Path(name).suffix.lower()
    if "/" in name or "\\" in name or name.startswith(".") or suffix not in (".csv", ".parquet"):
        raise FingerfitError("must be a file name ending in .csv or .parquet", field="--name")
    ref_name = str(meta["recordings"]["reference"])
    if name == ref_name or name in _RESERVED:
        raise FingerfitError(f"'{shown(name)}' is not a recording's name here", field="--name")
    toml = folder / SESSION_FILE
    sources = {ref_name: reference, LANDMARKS_FILE: landmarks}
    given = [p for p in (reference, landmarks) if p is not None]
    for p in given:
        if not p.is_file():
            raise FingerfitError("no such file", path=p)
    copies = {folder / f: p for f, p in sources.items() if p is not None}
    copies = {t: p for t, p in copies.items() if not (t.exists() and t.samefile(p))}
    targets = [folder / name, toml, *copies]
    if protocol in HOLD_PROTOCOLS:
        targets.append(folder / EVENTS_FILE)
        check_target(folder / EVENTS_FILE)
    refuse_writing_inputs(targets, [*inputs, *given])
    check_target(folder / name, overwrite=overwrite)
    check_target(toml)  # read-only found now, not after the recording
    for t in copies:
        check_target(t, overwrite=overwrite)
    ref_path = sources[ref_name] or folder / ref_name
    if not ref_path.is_file():
        raise FingerfitError(
            "no reference recording: give --reference FILE (the static posture the "
            "evidence is measured from)",
            path=folder / ref_name,
        )
    reference_rec = read_pose_csv(ref_path, units=meta["units"], rate_hz=meta["rate_hz"])
    digits = _digits(meta, reference_rec, ref_path, new)
    missing = [f for f in listed if f != name and not (folder / f).is_file()]
    if missing:
        raise FingerfitError(
            f"lists '{shown(missing[0])}', which is not in the folder",
            path=toml,
            field=f"recordings.{RECORDING_LIST}",
        )
    prior = [
        read_pose_csv(folder / f, units=meta["units"], rate_hz=meta["rate_hz"])
        for f in listed
        if f != name
    ]
    lm_path = sources[LANDMARKS_FILE] or folder / LANDMARKS_FILE
    lm = read_landmarks(lm_path, units=meta["units"]) if lm_path.is_file() else {}
    base = Session(
        str(meta.get("subject", folder.name)),
        str(meta.get("hand", NEW_SESSION["hand"])),
        "mm",
        float(meta["rate_hz"]),
        digits,
        reference_rec,
        prior,
        lm,
    )
    meta["fingers"] = digits
    sensors = list(dict.fromkeys(s for d in digits for s in digit_sensors(d)))
    return CapturePlan(
        folder,
        protocol,
        name,
        meta,
        digits,
        shown_digits(protocol, digits),
        sensors,
        base,
        {t: p.read_bytes() for t, p in copies.items()},
        overwrite,
        new,
    )


def check_sensors(recording: Recording, plan: CapturePlan, path: Path | str) -> None:
    """Refuse a recording (a replayed file before it is replayed, or what was recorded)
    without samples of a sensor the session's digits need: the fit could not use it, nor
    the session once it listed it.

    Raises
    ------
    FingerfitError
        Naming ``path`` and the first such sensor.
    """
    for s in plan.sensors:
        pose = recording.poses.get(s)
        if pose is None or not pose.valid.any():
            raise FingerfitError(
                f"no samples for sensor '{s}', which the session's digits "
                f"({', '.join(plan.digits)}) need: not recorded",
                path=path,
            )


def write_capture(
    plan: CapturePlan, recording: Recording, extra: dict[Path, bytes] | None = None
) -> Path:
    """Write the recording (in the session's units and the format of its name), the
    copies of ``--reference`` and ``--landmarks``, ``extra`` files (a pinch recording's
    ``events.csv``) and ``session.toml`` listing the recording: all of them or none.

    Returns
    -------
    Path
        ``session.toml``.
    """
    from ..io.atomic import write_files
    from ..io.posewrite import write_pose_csv

    data = rendered(plan.name, lambda p: write_pose_csv(p, recording, units=plan.units))
    toml = plan.folder / SESSION_FILE
    files = {
        **plan.copies,
        **(extra or {}),
        plan.target: data,
        toml: session_toml_text(plan.meta, plan.folder, plan.name),
    }
    write_files(files, overwrite=True)  # every target checked by plan_capture
    return toml


def rendered(name: str, write: Callable[[Path], object]) -> bytes:
    """The bytes a file writer writes for a file called ``name`` (written in a temporary
    folder), to be written with others all or none
    (:func:`fingerfit.io.atomic.write_files`)."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        write(path)
        return path.read_bytes()


def read_folder(
    folder: Path,
    *,
    subject: str | None = None,
    hand: str | None = None,
    units: str | None = None,
    rate: float | None = None,
    fingers: list[str] | None = None,
    need_reference: bool = True,
) -> tuple[dict, bool, Recording | None]:
    """A session folder's ``session.toml`` (or, without one, the options that start it,
    ``subject`` needed) checked against the options, and its reference recording.

    Returns
    -------
    meta : dict
        ``session.toml``'s content (``fingers`` set to the session's digits when the
        reference is read).
    new : bool
        The folder has no ``session.toml``.
    reference : Recording or None
        The reference recording (mm); None when ``need_reference`` is False and the
        folder has none.

    Raises
    ------
    FingerfitError
        As :func:`plan_capture`: the option, file or field at fault.
    """
    from ..io import read_pose_csv

    meta, new = _session_meta(folder, subject, hand, units, rate, fingers)
    ref_path = folder / str(meta["recordings"]["reference"])
    if not ref_path.is_file():
        if need_reference:
            raise FingerfitError(
                "no reference recording: record it first (fingerfit capture --protocol reference)",
                path=ref_path,
            )
        return meta, new, None
    reference = read_pose_csv(ref_path, units=meta["units"], rate_hz=meta["rate_hz"])
    meta["fingers"] = _digits(meta, reference, ref_path, new)
    return meta, new, reference


def _listed(meta: dict) -> list[str]:
    listed = meta["recordings"].get(RECORDING_LIST, [])
    return [listed] if isinstance(listed, str) else [str(f) for f in listed]


def _session_meta(
    folder: Path,
    subject: str | None,
    hand: str | None,
    units: str | None,
    rate: float | None,
    fingers: list[str] | None,
) -> tuple[dict, bool]:
    """The folder's ``session.toml`` as TOML, checked against the options given; or,
    without one, the options' (``subject`` needed). The flag: a new session."""
    path = folder / SESSION_FILE
    given = {"subject": subject, "hand": hand, "units": units, "rate_hz": rate}
    if hand is not None and hand not in ("left", "right"):
        raise FingerfitError("must be left or right", field="--hand")
    if units is not None and units not in UNITS_TO_MM:
        raise FingerfitError(f"must be one of {', '.join(UNITS_TO_MM)}", field="--units")
    if path.is_file():
        try:
            meta = tomllib.loads(path.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise FingerfitError(f"invalid TOML ({exc})", path=path) from None
        for key in ("units", "rate_hz", "fingers", "recordings"):
            if key not in meta:
                raise FingerfitError(f"missing '{key}'", path=path, field=key)
        if meta["units"] not in UNITS_TO_MM:
            raise FingerfitError(
                f"must be one of {', '.join(UNITS_TO_MM)}", path=path, field="units"
            )
        meta["rate_hz"] = float(meta["rate_hz"])
        meta["recordings"].setdefault("reference", "reference.csv")
        have = {k: meta.get(k, NEW_SESSION.get(k, folder.name)) for k in given}
        have["fingers"] = list(meta["fingers"])
        for key, value in (*given.items(), ("fingers", fingers)):
            if value is not None and value != have[key]:
                option = "--rate" if key == "rate_hz" else f"--{key}"
                stated = ",".join(have[key]) if key == "fingers" else have[key]
                raise FingerfitError(
                    f"the folder's session.toml says {key} = {shown(str(stated))}: leave "
                    f"{option} out to record into this session, or capture into a new folder",
                    field=option,
                )
        return meta, False
    if subject is None:
        raise FingerfitError(
            f"{folder} has no session.toml: give --subject (and --hand, --units, --rate, "
            "--fingers) to start one",
            field="--subject",
        )
    check_subject_id(subject)
    meta = {
        "format": "fingerfit.session/1",
        "subject": subject,
        **{k: v if given[k] is None else given[k] for k, v in NEW_SESSION.items()},
        "fingers": list(fingers or []),
        "recordings": {"reference": "reference.csv", RECORDING_LIST: []},
    }
    meta["rate_hz"] = float(meta["rate_hz"])
    return meta, True


def _digits(meta: dict, reference: Recording, path: Path, new: bool) -> list[str]:
    """The session's digits: ``fingers`` (every sensor of each with samples in the
    reference recording), or for a new session without ``--fingers`` those the reference
    has every sensor of."""

    def has(d: str) -> bool:
        return all(
            s in reference.poses and reference.poses[s].valid.any() for s in digit_sensors(d)
        )

    digits = list(meta["fingers"]) or [d for d in DIGIT_NAMES if has(d)]
    if not digits:
        raise FingerfitError("the reference recording has the sensors of no digit", path=path)
    for d in digits:
        lacking = [
            s
            for s in digit_sensors(d)
            if s not in reference.poses or not reference.poses[s].valid.any()
        ]
        if lacking:
            where = "--fingers" if new else f"{SESSION_FILE} fingers"
            raise FingerfitError(
                f"no samples for sensor '{lacking[0]}' of the {d} ({where}): record a "
                "reference with every sensor of the session's digits, or leave the digit out",
                path=path,
            )
    return digits


def session_toml_text(meta: dict, folder: Path, listed_name: str | None = None) -> str:
    """``session.toml`` of ``meta`` (as :func:`read_folder` gives it), with
    ``listed_name`` added to the ``grasp`` list."""
    recs = dict(meta["recordings"])
    listed = _listed(meta)
    if listed_name is not None and listed_name not in listed:
        listed.append(listed_name)
    recs[RECORDING_LIST] = listed
    lines = [
        f"format = {json.dumps(meta.get('format', 'fingerfit.session/1'))}",
        f"subject = {json.dumps(meta.get('subject', folder.name))}",
        f"hand = {json.dumps(meta.get('hand', NEW_SESSION['hand']))}",
        f"units = {json.dumps(meta['units'])}",
        f"rate_hz = {float(meta['rate_hz'])!r}",
        f"fingers = {json.dumps(list(meta['fingers']))}",
        "",
        "[recordings]",
    ]
    for key in ("reference", RECORDING_LIST, "targets", "test", "events"):
        if key in recs:
            lines.append(f"{key} = {json.dumps(recs[key])}")
    return "\n".join(lines) + "\n"
