"""``fingerfit capture``: a replayed grasp recorded into a session folder, with the fit's
own evidence per joint."""

from __future__ import annotations

import shutil
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.capture import EvidenceProcess, evidence, thresholds
from fingerfit.cli import app
from fingerfit.estimate import FitOptions
from fingerfit.estimate.cycles import extract_cycles
from fingerfit.io import load_session, read_pose_csv
from fingerfit.io.posewrite import write_pose_csv
from fingerfit.session import joint_sensors
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.transforms import relative_pose

from .conftest import subject

DIGITS = ("index", "middle")


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    sub = subject("realistic", 2, DIGITS)
    folder = write_subject(sub, tmp_path_factory.mktemp("capture") / "S01")
    return sub, folder


def _start(folder, tmp_path, name):
    """A new session folder holding only the reference and the landmarks."""
    new = tmp_path / name
    new.mkdir()
    for f in ("reference.csv", "landmarks.csv"):
        shutil.copyfile(folder / f, new / f)
    return new


def _capture(sub, new, source, protocol="grasp", digits=DIGITS, extra=()):
    return CliRunner().invoke(
        app,
        [
            "capture",
            str(new),
            "--source",
            source,
            "--protocol",
            protocol,
            "--subject",
            "S01",
            "--hand",
            sub.session.hand,
            "--units",
            sub.session.units,
            "--rate",
            str(sub.session.rate_hz),
            "--fingers",
            ",".join(digits),
            *extra,
        ],
    )


def _two_cycles(sub) -> int:
    """A frame after the second grasp cycle and before the third."""
    rec, s = sub.session.grasp[0], sub.session
    parent, child = joint_sensors("index")["pip"]
    ref = s.reference.pose(parent).mean()[1].T @ s.reference.pose(child).mean()[1]
    p, c = rec.pose(parent), rec.pose(child)
    r, _ = relative_pose(p.rotation, p.position, c.rotation, c.position)
    periods = extract_cycles(r, ref, s.rate_hz).periods
    assert len(periods) >= 4
    return int((periods[1].max() + periods[2].min()) // 2)


def _fits_and_assembles(
    new: Path, tmp_path: Path, hand: str, digits: list[str], grasp: list[str]
) -> None:
    """The folder capture wrote passes ``fingerfit fit``, and ``fingerfit session``
    assembles its files (reference, the ``grasp`` recordings, landmarks) into a session."""
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 0, res.output
    args = ["session", str(tmp_path / "assembled"), "--subject", "S01", "--hand", hand]
    args += ["--fingers", ",".join(digits), "--reference", str(new / "reference.csv")]
    for name in grasp:
        args += ["--grasp", str(new / name)]
    args += ["--landmarks", str(new / "landmarks.csv")]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output


def test_thresholds_are_the_fits():
    o = FitOptions()
    assert thresholds() == (max(o.min_cycles, 2), o.min_rom_deg, o.max_axis_ci_deg)


def test_full_grasp_is_enough_and_the_folder_fits(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P01")
    grasp = folder / sub.session.grasp[0].name
    r = _capture(sub, new, f"replay:{grasp}@1000")
    assert r.exit_code == 0, r.output
    assert "enough for every joint" in r.output
    assert r.output.count("enough") >= 6  # one row per joint in the table
    rows = evidence(sub.session, list(DIGITS))
    assert all(row.enough for row in rows)
    assert max(row.axis_ci_deg for row in rows) < FitOptions().max_axis_ci_deg
    assert {row.joint: row.second for row in rows if row.digit == "index"} == {
        "mp": True,  # the simulated MP turns about two axes and the choice finds them
        "pip": None,
        "dip": None,
    }
    # The same frames as replayed, in the session's format.
    got = read_pose_csv(new / "grasp.csv", units=sub.session.units)
    want = read_pose_csv(grasp, units=sub.session.units)
    np.testing.assert_array_equal(got.time, want.time)
    for s in got.poses:
        np.testing.assert_array_equal(got.poses[s].position, want.poses[s].position)
    _fits_and_assembles(new, tmp_path, sub.session.hand, list(DIGITS), ["grasp.csv"])


def test_two_cycles_are_not_enough_as_the_fit_says(simulated, tmp_path):
    sub, folder = simulated
    cut = sub.session.grasp[0].slice(slice(0, _two_cycles(sub)))
    short = write_pose_csv(tmp_path / "cut.csv", cut, units=sub.session.units)
    new = _start(folder, tmp_path, "P02")
    r = _capture(sub, new, f"replay:{short}@1000")
    assert r.exit_code == 0, r.output
    assert "not enough for `fingerfit fit` yet" in r.output
    rows = evidence(replace(sub.session, grasp=[cut]), list(DIGITS))
    assert not any(row.enough for row in rows)
    assert max(row.cycles for row in rows) <= 2
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 2 and "cycle" in res.output  # the fit refuses it too


def test_a_folder_without_session_toml_needs_a_subject(simulated, tmp_path):
    _, folder = simulated
    new = _start(folder, tmp_path, "P03")
    r = CliRunner().invoke(
        app, ["capture", str(new), "--source", f"replay:{folder / 'grasp.csv'}@1000"]
    )
    assert r.exit_code == 2 and "--subject" in r.output
    assert not (new / "grasp.csv").exists()


def test_the_axis_confidence_narrows_as_cycles_are_added(simulated):
    sub, _ = simulated
    rec = sub.session.grasp[0]
    n = rec.n_frames

    def ci(frames: int) -> np.ndarray:
        cut = replace(sub.session, grasp=[rec.slice(slice(0, frames))])
        rows = evidence(cut, list(DIGITS))
        return np.array([r.axis_ci_deg for r in rows])

    third, half, full = ci(n // 3), ci(n // 2), ci(n)
    assert np.isfinite(third).all()
    assert np.mean(full) < np.mean(half) < np.mean(third)


@pytest.fixture(scope="module")
def with_thumb(tmp_path_factory):
    sub = simulate_subject(SimConfig(fingers=("thumb", "index")), 3)
    folder = write_subject(sub, tmp_path_factory.mktemp("capture_thumb") / "S01")
    return sub, folder


def test_thumb_protocol_after_the_grasp_is_enough_and_the_folder_fits(with_thumb, tmp_path):
    sub, folder = with_thumb
    digits = ("thumb", "index")
    new = _start(folder, tmp_path, "P04")
    r = _capture(sub, new, f"replay:{folder / 'grasp.csv'}@1000", "grasp", digits)
    assert r.exit_code == 0, r.output
    # A grasp alone does not turn the thumb's CMC about both axes: the capture says so,
    # and the fit refuses the CMC for the same reason.
    assert "thumb cmc" in r.output and "second axis not identified" in r.output
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 2 and "cmc" in res.output
    # The thumb protocol takes the circumduction next (its default name) and pools it
    # with the grasp, as the fit does.
    r = _capture(sub, new, f"replay:{folder / 'thumb_circumduction.csv'}@1000", "thumb", digits)
    assert r.exit_code == 0, r.output
    assert "enough for every joint" in r.output
    assert (new / "thumb_circumduction.csv").is_file()
    session = load_session(new)
    assert [g.name for g in session.grasp] == ["grasp.csv", "thumb_circumduction.csv"]
    rows = evidence(session, ["thumb"])
    assert [r.joint for r in rows if r.enough] == ["cmc", "mcp", "ip"]
    cmc = rows[0]
    assert cmc.second is True and cmc.axis_ci_deg < FitOptions().max_axis_ci_deg
    _fits_and_assembles(
        new, tmp_path, sub.session.hand, digits, ["grasp.csv", "thumb_circumduction.csv"]
    )


def test_thumb_protocol_needs_a_thumb(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P05")
    r = _capture(sub, new, f"replay:{folder / 'grasp.csv'}@1000", "thumb")
    assert r.exit_code == 2 and "--protocol" in r.output
    assert not (new / "thumb_circumduction.csv").exists()


def test_the_evidence_process_reports_what_evidence_gives(simulated):
    sub, _ = simulated
    rec = sub.session.grasp[0]
    base = replace(sub.session, grasp=[])
    child = EvidenceProcess(base, rec.name, list(rec.poses), list(DIGITS))
    try:
        for i in range(0, rec.n_frames, 500):
            child.add(rec.slice(slice(i, i + 500)))
        got, deadline = None, time.monotonic() + 300  # a guard, not a measurement
        while (got is None or got[1] < rec.n_frames) and time.monotonic() < deadline:
            got = child.latest() or got
            time.sleep(0.05)
    finally:
        child.close()
    assert got is not None and got[1] == rec.n_frames
    assert got[0] == evidence(replace(base, grasp=[rec]), list(DIGITS))


def _newest(series):
    """The value of a ``(frame, value)`` list at its last frame (the row logged last)."""
    return max(enumerate(series), key=lambda iv: (iv[1][0], iv[0]))[1]


def test_view_save_has_the_evidence_capture_prints_and_the_recording_is_whole(simulated, tmp_path):
    """``capture --view-save``: per joint the series, the bounds, the table and the
    sensors, the last update equal to the printed table; the recording the same as
    without the view."""
    pytest.importorskip("rerun")
    from fingerfit.capture import table_cells
    from fingerfit.session import digit_sensors

    from .test_view import _read

    sub, folder = simulated
    grasp = folder / sub.session.grasp[0].name
    plain, viewed = _start(folder, tmp_path, "P06"), _start(folder, tmp_path, "P07")
    rrd = tmp_path / "evidence.rrd"
    r = _capture(sub, plain, f"replay:{grasp}@1000")
    assert r.exit_code == 0, r.output
    r = _capture(sub, viewed, f"replay:{grasp}@1000", extra=["--view-save", str(rrd)])
    assert r.exit_code == 0, r.output
    assert f"view -> {rrd}" in r.output.replace("\n", "")
    # The recording is whole: the view takes nothing from it.
    assert (viewed / "grasp.csv").read_bytes() == (plain / "grasp.csv").read_bytes()
    rec = read_pose_csv(viewed / "grasp.csv", units=sub.session.units)
    last = rec.n_frames - 1

    rows, static = _read(rrd)
    printed = {}  # (digit, joint) -> the cells of the table's first line of the joint
    for line in r.output.splitlines():
        cells = [c.strip() for c in line.strip("│ ").split("│")]
        if len(cells) == 7 and cells[0] in DIGITS:
            printed[cells[0], cells[1]] = cells
    want = evidence(load_session(viewed), list(DIGITS))  # what capture printed
    assert set(printed) == {(w.digit, w.joint) for w in want}
    need = thresholds()
    for series, limit, value in (("axis_deg", "bound", need[2]), ("cycles", "needed", need[0]),
                                 ("rom_deg", "needed", need[1])):  # fmt: skip
        entity = f"/evidence/{series}/{limit}"
        assert "SeriesLines:names" in static[entity]
        assert _newest(rows[entity]["Scalars:scalars"]) == (last, [value])
    for w in want:
        got = {
            s: _newest(rows[f"/evidence/{s}/{w.digit}/{w.joint}"]["Scalars:scalars"])
            for s in ("axis_deg", "cycles", "rom_deg")
        }
        assert {v[0] for v in got.values()} == {last}  # the last update: the last frame
        shown = replace(
            w,
            cycles=int(got["cycles"][1][0]),
            rom_deg=got["rom_deg"][1][0],
            axis_ci_deg=got["axis_deg"][1][0],
        )
        cells = table_cells(shown)
        assert cells[2:5] == printed[w.digit, w.joint][2:5], (cells, printed)
        assert cells[6] == printed[w.digit, w.joint][6]
    frame, (text,) = _newest(rows["/evidence/table"]["TextDocument:text"])
    assert frame == last and text.startswith(f"**{rec.n_frames} frames")
    for w in want:  # the panel's rows: the printed cells, enough or more
        assert "| " + " | ".join(table_cells(w)) + " |" in text
    # The sensors' axes at the last frame, mm in the tracker frame.
    sensors = list(dict.fromkeys(s for d in DIGITS for s in digit_sensors(d)))
    frame, origins = _newest(rows["/sensors"]["Arrows3D:origins"])
    assert frame == last and len(origins) == 3 * len(sensors)
    expect = np.repeat([rec.poses[s].position[last] for s in sensors], 3, axis=0)
    np.testing.assert_allclose(np.array(origins), expect, atol=1e-3)


def test_view_options_are_refused_in_one_line(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P08")
    grasp = f"replay:{folder / 'grasp.csv'}@1000"
    r = _capture(sub, new, grasp, extra=["--view-save", str(tmp_path / "x.txt")])
    assert r.exit_code == 2 and ".rrd" in r.output
    r = _capture(sub, new, grasp, extra=["--view", "--view-save", str(tmp_path / "x.rrd")])
    assert r.exit_code == 2 and "--view" in r.output
    assert not (new / "grasp.csv").exists()
