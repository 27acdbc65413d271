"""``fingerfit capture``: a replayed grasp recorded into a session folder, with the fit's
own evidence per joint."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.capture import evidence, reference_rotations, thresholds
from fingerfit.cli import app
from fingerfit.estimate import FitOptions
from fingerfit.estimate.cycles import extract_cycles
from fingerfit.io import read_pose_csv
from fingerfit.io.posecsv import write_pose_csv
from fingerfit.session import joint_sensors
from fingerfit.simulate import write_subject
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


def _capture(sub, new, source):
    return CliRunner().invoke(
        app,
        [
            "capture",
            str(new),
            "--source",
            source,
            "--protocol",
            "grasp",
            "--subject",
            "S01",
            "--hand",
            sub.session.hand,
            "--units",
            sub.session.units,
            "--rate",
            str(sub.session.rate_hz),
            "--fingers",
            ",".join(DIGITS),
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


def test_thresholds_are_the_fits():
    o = FitOptions()
    assert thresholds() == (max(o.min_cycles, 2), o.min_rom_deg)


def test_full_grasp_is_enough_and_the_folder_fits(simulated, tmp_path):
    sub, folder = simulated
    new = _start(folder, tmp_path, "P01")
    grasp = folder / sub.session.grasp[0].name
    r = _capture(sub, new, f"replay:{grasp}@1000")
    assert r.exit_code == 0, r.output
    assert "enough for every joint" in r.output
    assert r.output.count("enough") >= 6  # one row per joint in the table
    # The same frames as replayed, in the session's format.
    got = read_pose_csv(new / "grasp.csv", units=sub.session.units)
    want = read_pose_csv(grasp, units=sub.session.units)
    np.testing.assert_array_equal(got.time, want.time)
    for s in got.poses:
        np.testing.assert_array_equal(got.poses[s].position, want.poses[s].position)
    res = CliRunner().invoke(app, ["fit", str(new), "-q"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(
        app,
        [
            "session",
            str(tmp_path / "assembled"),
            "--subject",
            "S01",
            "--hand",
            sub.session.hand,
            "--fingers",
            ",".join(DIGITS),
            "--reference",
            str(new / "reference.csv"),
            "--grasp",
            str(new / "grasp.csv"),
            "--landmarks",
            str(new / "landmarks.csv"),
        ],
    )
    assert res.exit_code == 0, res.output


def test_two_cycles_are_not_enough_as_the_fit_says(simulated, tmp_path):
    sub, folder = simulated
    cut = sub.session.grasp[0].slice(slice(0, _two_cycles(sub)))
    short = write_pose_csv(tmp_path / "cut.csv", cut, units=sub.session.units)
    new = _start(folder, tmp_path, "P02")
    r = _capture(sub, new, f"replay:{short}@1000")
    assert r.exit_code == 0, r.output
    assert "not enough for `fingerfit fit` yet" in r.output
    rows = evidence(cut, reference_rotations(sub.session.reference, list(DIGITS)), 240.0)
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
