"""``fingerfit capture --protocol reference`` and ``--protocol landmarks``: the steps of
the lab's protocol that are not calibration recordings (``docs/lab.md``).

Both read the source as the other protocols do (:func:`.capture.open_source`) and write
their files together at the end (:func:`fingerfit.io.atomic.write_files`): all or none.
"""

from __future__ import annotations

import threading
from pathlib import Path

from ..errors import FingerfitError, shown
from .app import notice, say

#: Seconds of reference recorded by default (a device; a replay ends on its own).
REFERENCE_S = 2.0


def _record(source, sensors: list[str], rate_hz: float, duration: float | None, name: str):
    """Every block of ``source`` until it ends, ``duration`` s or Ctrl-C: the recording
    and whether Ctrl-C stopped it."""
    from ..capture import Accumulator

    acc = Accumulator(name, sensors)
    interrupted = False
    try:
        for block in source.blocks():
            if block is not None:
                acc.add(block.recording)
            if duration is not None and acc.n_frames >= duration * rate_hz:
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        source.close()
    rec = acc.recording()
    if duration is not None:
        rec = rec.slice(slice(0, min(rec.n_frames, round(duration * rate_hz))))
    return rec, interrupted


def capture_reference(
    folder: Path,
    spec: str,
    *,
    duration: float | None,
    subject: str | None,
    hand: str | None,
    units: str | None,
    rate: float | None,
    digits: list[str] | None,
    stations: str | None,
    overwrite: bool,
) -> None:
    """Record the reference posture into ``folder`` (starting its ``session.toml`` when
    new) unless a sensor moved too much (:mod:`fingerfit.capture.reference`)."""
    from ..capture.folder import _digits, read_folder, rendered, session_toml_text
    from ..capture.reference import MAX_MOTION_DEG, MAX_MOTION_MM, reference_motion
    from ..digits import DIGIT_NAMES
    from ..io.atomic import check_target, refuse_writing_inputs, write_files
    from ..io.posewrite import write_pose_csv
    from ..io.sessiondir import SESSION_FILE
    from ..session import digit_sensors
    from .capture_source import open_source, source_files

    meta, new, _ = read_folder(
        folder, subject=subject, hand=hand, units=units, rate=rate, fingers=digits,
        need_reference=False,
    )  # fmt: skip
    target = folder / str(meta["recordings"]["reference"])
    toml = folder / SESSION_FILE
    refuse_writing_inputs([target, toml], source_files(spec))
    check_target(target, overwrite=overwrite)
    check_target(toml)
    wanted = list(meta["fingers"]) or list(DIGIT_NAMES)
    sensors = list(dict.fromkeys(s for d in wanted for s in digit_sensors(d)))
    rate_hz = float(meta["rate_hz"])
    source = open_source(
        spec, units=meta["units"], rate_hz=rate_hz, sensors=sensors, stations=stations
    )
    if duration is None and source.live:
        duration = REFERENCE_S
    say("hold the hand still in the stretched reference posture")
    rec, interrupted = _record(source, sensors, rate_hz, duration, target.name)
    if rec.n_frames == 0:
        raise FingerfitError("nothing was recorded; no file written", field="--source")
    meta["fingers"] = _digits(meta, rec, target, new)
    used = list(dict.fromkeys(s for d in meta["fingers"] for s in digit_sensors(d)))
    rec.poses = {s: rec.poses[s] for s in used}
    moved = [m for m in reference_motion(rec, used) if m.too_much]
    for m in reference_motion(rec, used):
        say(
            "  {}: {} mm, {} deg (relative to the {})",
            m.sensor, f"{m.position_mm:.2f}", f"{m.rotation_deg:.2f}", m.relative_to,
        )  # fmt: skip
    if moved:
        worst = max(
            moved, key=lambda m: m.position_mm / MAX_MOTION_MM + m.rotation_deg / MAX_MOTION_DEG
        )
        raise FingerfitError(
            f"the hand moved too much: {worst.sensor} {worst.position_mm:.1f} mm RMS, "
            f"{worst.rotation_deg:.1f} deg RMS relative to the {worst.relative_to} (at most "
            f"{MAX_MOTION_MM:g} mm, {MAX_MOTION_DEG:g} deg): hold still and record again; no "
            "file written",
            field="--source",
        )
    data = rendered(target.name, lambda p: write_pose_csv(p, rec, units=meta["units"]))
    write_files({target: data, toml: session_toml_text(meta, folder)})
    say(
        "{} frames ({} s){} of the reference, every sensor still -> [bold]{}[/]",
        rec.n_frames, f"{rec.n_frames / rate_hz:.1f}", " (interrupted)" if interrupted else "", target,
    )  # fmt: skip


def enter_presses() -> threading.Event:
    """An event set each time Enter is pressed on the terminal (a daemon thread)."""
    import sys

    event = threading.Event()

    def read() -> None:
        for _ in sys.stdin:
            event.set()

    threading.Thread(target=read, daemon=True).start()
    return event


def _landmarks_raw_name(folder: Path) -> str:
    """The stylus recording's file name: ``landmarks_stylus.csv``, else the first free
    ``landmarks_stylus_<k>.csv`` (a repeated step keeps the earlier recording)."""
    name, k = "landmarks_stylus.csv", 2
    while (folder / name).exists():
        name, k = f"landmarks_stylus_{k}.csv", k + 1
    return name


def capture_landmarks(
    folder: Path,
    spec: str,
    *,
    stylus: Path | None,
    takes: int,
    pads: bool,
    targets: list[str],
    only: list[str] | None,
    trigger: str,
    stations: str | None,
    overwrite: bool,
    view: bool = False,
    view_save: Path | None = None,
) -> None:
    """Digitise the session's landmarks with the stylus into ``landmarks.csv``
    (:mod:`fingerfit.capture.landmarks`); with ``view`` or ``view_save``, shown in the 3D
    view as well (:class:`fingerfit.view.landmarks.LandmarkView`)."""
    from ..capture import Accumulator
    from ..capture.folder import read_folder, rendered
    from ..capture.landmarks import LandmarkTaker
    from ..io.atomic import check_target, refuse_writing_inputs, write_files
    from ..io.posewrite import write_pose_csv
    from ..io.sessiondir import LANDMARKS_FILE, read_landmark_table, write_landmarks
    from ..session import digit_sensors, is_landmark_name
    from ..stylus import read_stylus
    from ..stylus.landmarks import landmark_names, landmark_segment, tip_points
    from .capture_source import open_source, source_files

    if stylus is None:
        raise FingerfitError(
            "the landmarks protocol needs the stylus file (fingerfit stylus)", field="--stylus"
        )
    if not (folder / "session.toml").is_file():
        raise FingerfitError(
            "has no session.toml: record the reference first (--protocol reference)", path=folder
        )
    meta, _, reference = read_folder(folder)
    assert reference is not None
    cal = read_stylus(stylus)
    digits = list(meta["fingers"])
    names = landmark_names(digits, pads=pads, targets=tuple(targets))
    for t in targets:
        if not is_landmark_name(f"target.{t}"):
            raise FingerfitError(
                f"'{shown(t)}' is not a target label (letters, digits, _, -)", field="--targets"
            )
    if only is not None:
        for n in only:
            d = n.split(".", 1)[0]
            if not is_landmark_name(n) or (not n.startswith("target.") and d not in digits):
                raise FingerfitError(
                    f"'{shown(n)}' is not a landmark of this session's digits ({', '.join(digits)})",
                    field="--only",
                )
        names = list(dict.fromkeys(only))
    lm_path = folder / LANDMARKS_FILE
    raw = folder / _landmarks_raw_name(folder)
    refuse_writing_inputs([lm_path, raw], [*source_files(spec), stylus])
    have: tuple[dict, dict] = ({}, {})
    if lm_path.exists():
        if only is None and not overwrite:
            raise FingerfitError(
                "exists: --only NAMES to take some landmarks again (the others are kept), or "
                "--overwrite to take them all again",
                path=lm_path,
            )
        check_target(lm_path)
        if only is not None:
            have = read_landmark_table(lm_path, meta["units"])
    segments = sorted({s for n in names if (s := landmark_segment(n)) is not None})
    # Every sensor of the session, then the stylus: a Liberty's default stations are the
    # other protocols' with the stylus on the next one.
    session_sensors = [s for d in digits for s in digit_sensors(d)]
    sensors = list(dict.fromkeys([*session_sensors, cal.sensor]))

    def check(rec, path) -> None:
        for s in [*segments, cal.sensor]:
            if s not in rec.poses or not rec.poses[s].valid.any():
                raise FingerfitError(
                    f"no samples for sensor '{s}', which the landmarks need", path=path
                )

    rate_hz = float(meta["rate_hz"])
    means = {
        s: reference.poses[s].mean() for s in reference.poses if reference.poses[s].valid.any()
    }
    missing_ref = [s for s in segments if s not in means]
    if missing_ref:
        raise FingerfitError(
            f"the reference recording has no samples of '{missing_ref[0]}', which carries a landmark",
            path=folder / str(meta["recordings"]["reference"]),
        )
    source = open_source(
        spec, units=meta["units"], rate_hz=rate_hz, sensors=sensors, stations=stations, check=check
    )
    viewer = None
    if view or view_save is not None:
        from ..view.landmarks import LandmarkView

        viewer = LandmarkView(view_save, means)
    taker = LandmarkTaker(names, cal, rate_hz, takes=takes, still=trigger == "still")
    pressed = enter_presses() if trigger == "enter" else None
    acc = Accumulator(raw.name, sensors)
    say("{}", taker.prompt())
    interrupted = False

    def show(lines: list[str]) -> None:
        for line in lines:
            say("{}", line)
        while viewer is not None and len(logged) < len(taker.done):
            lm = taker.done[len(logged)]
            viewer.landmark(lm.name, lm.at_reference(means), lm.sd_mm)
            logged.append(lm.name)

    logged: list[str] = []
    try:
        for block in source.blocks():
            if block is not None:
                acc.add(block.recording)
                if viewer is not None and cal.sensor in block.recording.poses:
                    p = block.recording.poses[cal.sensor]
                    viewer.tip(
                        block.recording.time,
                        tip_points(p.position, p.rotation, cal.tip_offset_mm, None),
                    )
                show(taker.add(block.recording))
            if pressed is not None and pressed.is_set():
                pressed.clear()
                show(taker.press())
            if taker.finished:
                break
    except KeyboardInterrupt:
        interrupted = True
    finally:
        source.close()
        if viewer is not None:
            viewer.close(bool(taker.done))
    recorded = acc.recording()
    raw_file = {raw: rendered(raw.name, lambda p: write_pose_csv(p, recorded, units=meta["units"]))}
    why = "interrupted" if interrupted else "the source ended"
    if not taker.done:
        if recorded.n_frames == 0:
            raise FingerfitError(f"{why} before any frame; no file written", field="--source")
        write_files(raw_file)  # what was recorded is kept, though no landmark was taken
        raise FingerfitError(
            f"{why} before a landmark was taken: landmarks.csv not written; the stylus "
            f"recording ({recorded.n_frames} frames) is kept in {raw}",
            field="--source",
        )
    points, sds = taker.result(means)
    merged = {**{k: v for k, v in have[0].items() if k not in points}, **points}
    merged_sd = {**{k: v for k, v in have[1].items() if k not in points}, **sds}
    write_files(
        {
            lm_path: rendered(
                LANDMARKS_FILE, lambda p: write_landmarks(p, merged, meta["units"], merged_sd)
            ),
            **raw_file,
        }
    )
    if taker.rejected:
        notice("note", f"{taker.rejected} shaky window(s) refused")
    missing = [n for n in names if n not in points]
    worst = max(taker.done, key=lambda lm: lm.spread_mm)
    say(
        "{} landmark(s) taken ({} takes each; widest {} {} mm apart) -> [bold]{}[/]; the "
        "stylus recording -> {}",
        len(points), takes, worst.name, f"{worst.spread_mm:.2f}", lm_path, raw,
    )  # fmt: skip
    if missing:
        notice(
            "warning",
            f"not taken ({'interrupted' if interrupted else 'the source ended'}): {', '.join(missing)} -- take them with --only",
        )
