"""The lab's protocol from the device (``fingerfit capture --protocol reference,
landmarks, pinch``) on a simulated subject's stylus recordings, against the simulator's
files and truth."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.capture.landmarks import LandmarkTaker
from fingerfit.capture.pinch import find_holds, marked_holds, pad_points
from fingerfit.cli import app
from fingerfit.estimate import fit_session
from fingerfit.io.posewrite import write_pose_csv
from fingerfit.io.sessiondir import (
    read_events,
    read_landmark_table,
    read_landmarks,
    write_landmarks,
)
from fingerfit.model import load_model, save_model
from fingerfit.session import PoseSeries, Recording
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.stylus import StylusCalibration
from fingerfit.stylus.landmarks import landmark_names, window_spread

DIGITS = ("thumb", "index")


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """A simulated subject with its stylus recordings (no field distortion: the
    stylus's error is then its white noise alone), and a stylus file with its true tip."""
    sim = simulate_subject(SimConfig(fingers=DIGITS, stylus_recordings=True, distortion=False), 5)
    root = tmp_path_factory.mktemp("lab")
    folder = write_subject(sim, root / "S01")
    tip = ",".join(repr(v) for v in sim.stylus.truth["tip_offset_mm"])
    r = CliRunner().invoke(app, ["stylus", "--tip-offset", tip, "-o", str(root / "stylus.json")])
    assert r.exit_code == 0, r.output
    return sim, folder, root


def _run(*args):
    return CliRunner().invoke(app, ["capture", *map(str, args)])


def _reference(folder, new):
    return _run(
        new, "--protocol", "reference", "--source", f"replay:{folder / 'reference.csv'}@1000",
        "--subject", "P01", "--fingers", ",".join(DIGITS),
    )  # fmt: skip


def _targets(sim) -> str:
    return ",".join(
        k.removeprefix("target.") for k in sim.session.landmarks if k.startswith("target.")
    )


def test_reference_landmarks_match_the_simulators_and_a_step_can_be_repeated(lab):
    sim, folder, root = lab
    new = root / "P01"
    r = _reference(folder, new)
    assert r.exit_code == 0, r.output
    assert "every sensor still" in r.output
    assert (new / "reference.csv").is_file() and (new / "session.toml").is_file()
    source = f"replay:{folder / 'stylus_landmarks.csv'}@1000"
    stylus = root / "stylus.json"
    args = ["--protocol", "landmarks", "--stylus", stylus, "--source", source, "--pads"]
    r = _run(new, *args, "--targets", _targets(sim), "--view-save", root / "landmarks.rrd")
    assert r.exit_code == 0, r.output
    assert (root / "landmarks.rrd").stat().st_size > 10_000  # the tip, takes and landmarks
    assert "place the stylus on thumb.cmc" in r.output
    got, sd = read_landmark_table(new / "landmarks.csv")
    want = sim.session.landmarks
    assert set(got) == set(want)
    err = {k: float(np.linalg.norm(got[k] - want[k])) for k in want}
    assert max(err.values()) < 0.3, err  # measured 0.03-0.15 here
    assert set(sd) == set(want) and all(0 < v < 1.0 for v in sd.values())
    assert (new / "landmarks_stylus.csv").is_file()
    before = (new / "landmarks.csv").read_text().splitlines()

    # Taking them all again is refused; --only takes some again and keeps the rest.
    r = _run(new, *args)
    assert r.exit_code == 2 and "--only NAMES" in r.output
    # The stylus on the index's tip alone: the stretch of the recording with its takes.
    holds = np.array(sim.stylus.truth["holds"]["index.tip"])
    rec = sim.stylus.landmarks
    keep = (rec.time > holds[0, 0] - 0.5) & (rec.time < holds[-1, 1] + 0.3)
    again = write_pose_csv(root / "again.csv", rec.slice(keep))
    # A stylus whose tip is 1 mm further out: the index's tip moves, nothing else.
    tip = np.array(sim.stylus.truth["tip_offset_mm"])
    longer = ",".join(repr(float(v)) for v in tip * (1 + 1 / np.linalg.norm(tip)))
    assert (
        CliRunner()
        .invoke(app, ["stylus", "--tip-offset", longer, "-o", str(root / "s2.json")])
        .exit_code
        == 0
    )
    only = [
        "--protocol",
        "landmarks",
        "--stylus",
        root / "s2.json",
        "--source",
        f"replay:{again}@1000",
    ]
    r = _run(new, *only, "--only", "index.tip")
    assert r.exit_code == 0, r.output
    after = (new / "landmarks.csv").read_text().splitlines()
    assert len(after) == len(before)
    changed = {line.split(",")[0] for line in set(after) - set(before)}
    assert changed == {"index.tip"}
    moved = read_landmarks(new / "landmarks.csv")["index.tip"] - got["index.tip"]
    assert 0.9 < np.linalg.norm(moved) < 1.1
    assert (new / "landmarks_stylus_2.csv").is_file()  # the first stylus recording kept


def test_a_reference_that_moves_is_refused_and_writes_nothing(lab):
    _, folder, root = lab
    new = root / "moving"
    r = _run(
        new, "--protocol", "reference", "--source", f"replay:{folder / 'grasp.csv'}@1000",
        "--duration", "1.5", "--subject", "P02", "--fingers", ",".join(DIGITS),
    )  # fmt: skip
    assert r.exit_code == 2
    assert "moved too much" in r.output and "no file written" in r.output
    assert not new.exists() or not any(new.iterdir())


def test_landmarks_need_the_reference_first(lab):
    _, folder, root = lab
    r = _run(root / "empty", "--protocol", "landmarks", "--stylus", root / "stylus.json",
             "--source", f"replay:{folder / 'stylus_landmarks.csv'}")  # fmt: skip
    assert r.exit_code == 2 and "record the reference first" in r.output


def test_three_takes_average_the_tip_placements(lab):
    """One take vs the mean of three, at the tips, against where the stylus rested."""
    sim, _, _ = lab
    st = sim.stylus
    taker = LandmarkTaker(
        list(st.truth["order"]),
        StylusCalibration("stylus", np.array(st.truth["tip_offset_mm"])),
        240.0,
    )
    rec = st.landmarks
    for a in range(0, rec.n_frames, 24):
        taker.add(rec.slice(slice(a, a + 24)))
    assert len(taker.done) == len(st.truth["order"])
    means = {s: p.mean() for s, p in sim.session.reference.poses.items()}
    for lm in taker.done:
        placed = np.array(st.truth["placements"][lm.name])  # reference posture, tracker frame
        if lm.segment is None:
            takes = lm.takes
        else:
            pos, rot = means[lm.segment]
            takes = lm.takes @ rot.T + pos
        # Each take is where the stylus rested, to the tracker's noise.
        np.testing.assert_array_less(np.linalg.norm(takes - placed, axis=1), 0.3)


def test_a_shaky_key_press_is_refused():
    rate = 240.0
    t = np.arange(480) / rate
    rot = np.broadcast_to(np.eye(3), (t.size, 3, 3)).copy()
    still = np.zeros((t.size, 3))
    shaky = np.column_stack([2.0 * np.sin(2 * np.pi * 5 * t), np.zeros_like(t), np.zeros_like(t)])
    cal = StylusCalibration("stylus", np.array([0.0, 0.0, -100.0]))
    for pos, ok in ((shaky, False), (still, True)):
        taker = LandmarkTaker(["target.a"], cal, rate, takes=1, still=False)
        assert taker.add(Recording("r", t, {"stylus": PoseSeries(pos, rot)})) == []
        lines = taker.press()
        assert ("shaky" in lines[0]) is not ok, lines
        assert taker.finished is ok


def test_window_spread_sees_motion_not_white_noise():
    rng = np.random.default_rng(0)
    noise = rng.normal(0, 0.3, (240, 3))
    assert window_spread(noise) < 0.1
    drift = noise + np.linspace(0, 2.0, 240)[:, None] * np.array([1.0, 0, 0])
    assert window_spread(drift) > 0.4


def test_pinch_holds_cover_the_simulators_events_and_no_key_pinch(lab):
    sim, _, _ = lab
    s = sim.session
    pads = pad_points(s.landmarks, s.reference, list(DIGITS))
    for name in ("thumb_opposition.csv", "pinch.csv"):
        rec = s.recording(name)
        found = find_holds(rec, pads, s.rate_hz)
        truth = [e for e in s.events if e.recording == name]
        assert len(found) == len(truth)  # the key pinches of pinch.csv are not holds
        for e in truth:  # each event inside a hold found, to a frame or two
            assert any(
                f.target == e.target and f.start <= e.start + 0.02 and f.end >= e.end - 0.02
                for f in found
            )
    # The pads fitted to the holds found are those fitted to the simulator's events.
    found = [
        e
        for n in ("thumb_opposition.csv", "pinch.csv")
        for e in find_holds(s.recording(n), pads, s.rate_hz)
    ]
    kept = [e for e in s.events if e.recording not in ("thumb_opposition.csv", "pinch.csv")]
    a = fit_session(s)
    b = fit_session(replace(s, events=[*kept, *found]))
    for d in DIGITS:
        assert np.linalg.norm(a.fingers[d].pad - b.fingers[d].pad) < 0.2


def test_capture_pinch_writes_events(lab):
    sim, folder, root = lab
    new = root / "P03"
    common = ["--subject", "P03", "--fingers", ",".join(DIGITS)]
    r = _run(new, "--source", f"replay:{folder / 'pinch.csv'}@1000", "--protocol", "pinch",
             "--reference", folder / "reference.csv", "--landmarks", folder / "landmarks.csv", *common)  # fmt: skip
    assert r.exit_code == 0, r.output
    assert "pad-to-pad holds found: thumb-index 3" in r.output
    events = read_events(new / "events.csv")
    truth = [e for e in sim.session.events if e.recording == "pinch.csv"]
    assert len(events) == len(truth)
    assert 'events = "events.csv"' in (new / "session.toml").read_text()


def test_the_tip_uncertainty_reaches_the_model(realistic_subject, tmp_path):
    s = realistic_subject.session
    sd = {"index.tip": 0.21, "index.pip": 0.4}
    model = fit_session(replace(s, landmark_sd=sd))
    assert model.fingers["index"].tip_sd_mm == pytest.approx(0.21)
    path = save_model(model, tmp_path / "m.json")
    assert json.loads(path.read_text())["fingers"]["index"]["tip_sd_mm"] == pytest.approx(0.21)
    assert load_model(path).fingers["index"].tip_sd_mm == pytest.approx(0.21)
    # landmarks.csv's sd column: written and read in the session's units.
    write_landmarks(tmp_path / "l.csv", s.landmarks, "cm", sd)
    got, got_sd = read_landmark_table(tmp_path / "l.csv", "cm")
    assert got_sd == pytest.approx(sd)
    assert set(got) == set(s.landmarks)


def test_landmark_order_is_the_files():
    assert landmark_names(["index"], pads=True, targets=("a",)) == [
        "index.mp", "index.pip", "index.dip", "index.tip", "index.pad", "target.a",
    ]  # fmt: skip


def test_key_marked_holds_name_the_finger_nearest_the_thumb(lab):
    sim, _, _ = lab
    s = sim.session
    rec = s.recording("pinch.csv")
    truth = [e for e in s.events if e.recording == "pinch.csv"]
    presses = [t for e in truth for t in (e.start, e.end)]
    for kind in ("pad", "tip"):  # the pads, or without them the tips
        points = pad_points(s.landmarks, s.reference, list(DIGITS), kind)
        found, unpaired = marked_holds(rec, [*presses, 30.0], points)
        assert unpaired == 1
        assert [(e.target, e.start, e.end) for e in found] == [
            (e.target, e.start, e.end) for e in truth
        ]


def test_a_negative_landmark_sd_is_refused(tmp_path):
    from fingerfit.errors import FingerfitError

    path = tmp_path / "landmarks.csv"
    path.write_text("name,x,y,z,sd\nindex.tip,1,2,3,-0.5\n")
    with pytest.raises(FingerfitError) as exc:
        read_landmark_table(path)
    assert str(exc.value) == f"{path}:2: field 'sd': sd must not be negative"


def test_the_command_line_names_the_protocols_capture_has():
    """``fingerfit.cli.capture`` spells the protocols out (its start-up imports no NumPy):
    they must be those of :mod:`fingerfit.capture.protocols`."""
    from fingerfit.capture import protocols
    from fingerfit.cli import capture as cli

    assert set(cli.PROTOCOLS) == set(protocols.PROTOCOLS)
    assert cli.HOLD_PROTOCOLS == protocols.HOLD_PROTOCOLS


def test_a_source_that_ends_before_a_landmark_keeps_its_recording(lab):
    sim, folder, root = lab
    new = root / "P04"
    assert _reference(folder, new).exit_code == 0
    rec = sim.stylus.landmarks
    short = write_pose_csv(root / "short.csv", rec.slice(slice(0, 480)))  # 2 s: one take
    r = _run(new, "--protocol", "landmarks", "--stylus", root / "stylus.json",
             "--source", f"replay:{short}@1000")  # fmt: skip
    assert r.exit_code == 2
    assert "before a landmark was taken: landmarks.csv not written" in r.output
    assert "(480 frames) is kept in" in r.output
    assert not (new / "landmarks.csv").exists()
    assert (new / "landmarks_stylus.csv").is_file()
