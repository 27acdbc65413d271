"""Session format: exact round trip and one clear error per malformed case."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.errors import FingerfitError
from fingerfit.io import load_session, read_pose_csv, save_session, write_pose_csv
from fingerfit.simulate import write_subject

from .conftest import subject


@pytest.fixture(scope="module")
def session_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("sess") / "S01"
    write_subject(subject("realistic", 5, ("index", "middle")), d)
    return d


def _copy(session_dir: Path, tmp_path: Path) -> Path:
    d = tmp_path / "S"
    shutil.copytree(session_dir, d)
    return d


def test_round_trip_is_exact(session_dir: Path) -> None:
    sim = subject("realistic", 5, ("index", "middle")).session
    loaded = load_session(session_dir)
    assert (loaded.subject, loaded.hand, loaded.units, loaded.rate_hz) == (
        sim.subject,
        sim.hand,
        sim.units,
        sim.rate_hz,
    )
    assert loaded.fingers == sim.fingers
    for a, b in zip(sim.recordings(), loaded.recordings(), strict=True):
        assert a.name == b.name and a.sensors == b.sensors
        np.testing.assert_array_equal(a.time, b.time)
        for s in a.sensors:
            np.testing.assert_array_equal(a.poses[s].position, b.poses[s].position)
            np.testing.assert_allclose(a.poses[s].rotation, b.poses[s].rotation, rtol=0, atol=2e-15)
        assert b.notes == []
    assert loaded.landmarks.keys() == sim.landmarks.keys()
    for k, v in sim.landmarks.items():
        np.testing.assert_array_equal(v, loaded.landmarks[k])
    assert loaded.events == sim.events


def test_write_read_write_keeps_every_value(session_dir: Path, tmp_path: Path) -> None:
    """Times and positions survive a second round trip bit for bit; quaternions go through
    rotation matrices and come back to within float rounding (1e-15)."""
    first = read_pose_csv(session_dir / "grasp.csv", rate_hz=240.0)
    write_pose_csv(tmp_path / "again.csv", first)
    a = pd.read_csv(session_dir / "grasp.csv", dtype=str)
    b = pd.read_csv(tmp_path / "again.csv", dtype=str)
    assert a.shape == b.shape
    for col in ("time", "sensor", "x", "y", "z"):
        assert (a[col] == b[col]).all(), col
    qa = a[["qw", "qx", "qy", "qz"]].to_numpy(dtype=object).astype(float)
    qb = b[["qw", "qx", "qy", "qz"]].to_numpy(dtype=object).astype(float)
    np.testing.assert_allclose(qa, qb, rtol=0, atol=1e-15)


def test_units_are_converted(session_dir: Path, tmp_path: Path) -> None:
    s = load_session(session_dir)
    s.units = "cm"
    save_session(s, tmp_path / "cm")
    text = (tmp_path / "cm" / "reference.csv").read_text().splitlines()[1].split(",")
    mm = s.reference.poses[text[1]].position[0]
    assert float(text[2]) == pytest.approx(mm[0] / 10, rel=1e-12)
    back = load_session(tmp_path / "cm")
    np.testing.assert_allclose(
        back.reference.poses["hand"].position, s.reference.poses["hand"].position, rtol=1e-12
    )


def _edit_line(path: Path, line: int, new: str | None = None, **fields: str) -> None:
    """Replace line ``line`` (1-based) by ``new``, or some of its fields by name."""
    lines = path.read_text().splitlines()
    if fields:
        names = lines[0].split(",")
        values = lines[line - 1].split(",")
        for k, v in fields.items():
            values[names.index(k)] = v
        new = ",".join(values)
    lines[line - 1] = new
    path.write_text("\n".join(lines) + "\n")


CSV_CASES = [
    (1, "time,sensor,x,y,z,qx,qy,qz,qw", {}, "header must be exactly", 1),
    (5, "0.0,hand,1,2,3,1,0,0", {}, "expected 9 comma-separated fields, found 8", 5),
    (7, None, {"y": "abc"}, "field 'y': not a number: 'abc'", 7),
    (9, None, {"sensor": "thumb.middle"}, "unknown sensor name 'thumb.middle'", 9),
    (11, None, {"qw": "1.2", "qx": "0", "qy": "0", "qz": "0"}, "has norm 1.2, not 1", 11),
    (20, None, {"time": "0.0"}, "time goes backwards", 20),
    (30, None, {"time": "0.0150"}, "not on the 240 Hz sampling grid", 30),
]


@pytest.mark.parametrize(("line", "text", "fields", "message", "report_line"), CSV_CASES)
def test_malformed_pose_csv(
    session_dir, tmp_path, line, text, fields, message, report_line
) -> None:
    d = _copy(session_dir, tmp_path)
    _edit_line(d / "grasp.csv", line, text, **fields)
    with pytest.raises(FingerfitError) as err:
        load_session(d)
    msg = str(err.value)
    assert message in msg
    assert "grasp.csv" in msg and "\n" not in msg
    if report_line is not None:
        assert f"grasp.csv:{report_line}:" in msg


def test_conflicting_duplicate_is_an_error_exact_one_is_counted(session_dir, tmp_path) -> None:
    d = _copy(session_dir, tmp_path)
    lines = (d / "reference.csv").read_text().splitlines()
    (d / "reference.csv").write_text("\n".join([*lines[:3], lines[2], *lines[3:]]) + "\n")
    rec = load_session(d).reference
    assert "1 exact duplicate rows dropped" in rec.notes
    f = lines[2].split(",")
    f[2] = str(float(f[2]) + 1)
    (d / "reference.csv").write_text("\n".join([*lines[:3], ",".join(f), *lines[3:]]) + "\n")
    with pytest.raises(FingerfitError, match=r"reference.csv:4: second, different sample"):
        load_session(d)


def test_gaps_stay_visible_and_are_counted(session_dir, tmp_path) -> None:
    d = _copy(session_dir, tmp_path)
    lines = (d / "grasp.csv").read_text().splitlines()
    n_sensors = 7  # hand + 2 fingers x 3
    # Drop every row of frame 10 (a dropped tracker frame) and blank one sample of frame 20.
    frame10 = slice(1 + 10 * n_sensors, 1 + 11 * n_sensors)
    row20 = 1 + 20 * n_sensors
    blank = lines[row20].split(",")
    blank[6:] = [""] * 3  # qx, qy, qz empty: an incomplete sample
    kept = (
        lines[: frame10.start]
        + lines[frame10.stop : row20]
        + [",".join(blank)]
        + lines[row20 + 1 :]
    )
    (d / "grasp.csv").write_text("\n".join(kept) + "\n")
    rec = load_session(d).grasp[0]
    assert np.isnan(rec.poses["hand"].position[10]).all()
    assert rec.time[10] == pytest.approx(10 / 240)
    assert np.isnan(rec.poses[blank[1]].position[20]).all()
    assert "1 frames missing for every sensor (kept as NaN rows)" in rec.notes
    assert "1 samples with empty fields treated as missing" in rec.notes


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (("hand", 'hand = "both"'), "session.toml: field 'hand': must be 'left' or 'right'"),
        (("format", 'format = "other/2"'), "field 'format': unsupported format 'other/2'"),
        (("units", 'units = "furlong"'), "field 'units': must be one of"),
        (("rate_hz", "rate_hz = -3"), "field 'rate_hz': must be positive"),
        (("fingers", 'fingers = ["pinky"]'), "field 'fingers': must be a non-empty list"),
        (
            ("grasp", 'grasp = ["nope.csv"]'),
            "field 'recordings.grasp': names a file that does not exist",
        ),
        (("subject", 'subject = "S01'), "session.toml:2: invalid TOML"),
    ],
)
def test_malformed_session_toml(session_dir, tmp_path, edit, message) -> None:
    d = _copy(session_dir, tmp_path)
    lines = (d / "session.toml").read_text().splitlines()
    key, new = edit
    lines = [new if ln.startswith(f"{key} =") else ln for ln in lines]
    (d / "session.toml").write_text("\n".join(lines) + "\n")
    with pytest.raises(FingerfitError, match=message.replace("(", r"\(").replace("[", r"\[")):
        load_session(d)


def test_missing_sensor_and_landmark(session_dir, tmp_path) -> None:
    d = _copy(session_dir, tmp_path)
    lines = (d / "reference.csv").read_text().splitlines()
    (d / "reference.csv").write_text(
        "\n".join(ln for ln in lines if ",middle.distal," not in ln) + "\n"
    )
    with pytest.raises(
        FingerfitError, match=r"reference.csv: no samples for sensor 'middle.distal'"
    ):
        load_session(d)
    d2 = _copy(session_dir, tmp_path / "b")
    lines = (d2 / "landmarks.csv").read_text().splitlines()
    (d2 / "landmarks.csv").write_text(
        "\n".join(ln for ln in lines if not ln.startswith("index.pip")) + "\n"
    )
    with pytest.raises(FingerfitError, match=r"landmarks.csv: missing landmark 'index.pip'"):
        load_session(d2)


def test_cli_reports_bad_file_in_one_line(session_dir, tmp_path) -> None:
    d = _copy(session_dir, tmp_path)
    _edit_line(d / "grasp.csv", 3, "0.0,hand,1,2")
    res = CliRunner().invoke(app, ["fit", str(d)])
    assert res.exit_code == 2
    assert "grasp.csv:3: expected 9 comma-separated fields" in res.output
    assert "Traceback" not in res.output
    assert not (d / "model.json").exists()


def test_fit_reads_no_test_recording(session_dir, tmp_path) -> None:
    """``fit`` does not use the free-motion test recordings: they are checked to be there,
    not read (a long test recording costs the fit nothing); a missing one is still an
    error."""
    d = _copy(session_dir, tmp_path)
    full = load_session(d)
    assert full.test
    (d / full.test[0].name).write_text("not a pose table\n")
    with pytest.raises(FingerfitError):
        load_session(d)
    s = load_session(d, test=False)
    assert s.test == [] and [r.name for r in s.grasp] == [r.name for r in full.grasp]
    assert d / full.test[0].name in s.files
    res = CliRunner().invoke(app, ["fit", str(d), "-o", str(tmp_path / "m.json"), "-q"])
    assert res.exit_code == 0, res.output
    (d / full.test[0].name).unlink()
    with pytest.raises(FingerfitError, match=full.test[0].name):
        load_session(d, test=False)
