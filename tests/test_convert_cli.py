"""``fingerfit convert``: every format to the pose CSV; bad input -> one line, exit 2, no file."""

from __future__ import annotations

import re

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.io.liberty import format_liberty_ascii, liberty_binary_bytes
from fingerfit.io.posecsv import read_pose_csv
from fingerfit.io.widecsv import write_wide_csv

from .test_io_liberty import make_records
from .test_io_widecsv import truth

runner = CliRunner()


def convert(*args):
    return runner.invoke(app, ["convert", *map(str, args)])


def test_liberty_ascii_to_pose_csv(tmp_path) -> None:
    recs = make_records(30, items=("position", "quaternion", "frame"))
    lines = format_liberty_ascii(recs).splitlines(keepends=True)
    lines = lines[:10] + lines[8:10] + lines[14:]  # one repeated frame, frames 5-6 lost
    (tmp_path / "s.txt").write_text("".join(lines), newline="")
    out = tmp_path / "out" / "grasp.csv"
    res = convert(tmp_path / "s.txt", "-o", out, "--from", "liberty", "--items", "2,7,9,1",
                  "--rate", 240, "--map", "1=hand,2=index.proximal", "--out-units", "cm")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "note: 2 exactly repeated records (same frame count) dropped" in res.output
    assert "note: 2 frames missing for every sensor (kept as NaN rows)" in res.output
    back = read_pose_csv(out, units="cm", rate_hz=240)
    assert back.n_frames == 30
    assert np.flatnonzero(~back.poses["hand"].valid).tolist() == [5, 6]
    ok = back.poses["hand"].valid
    np.testing.assert_allclose(
        back.poses["hand"].position[ok], recs.values["position"][::2][ok] * 25.4, rtol=1e-14
    )


def test_binary_wide_and_gap_filling(tmp_path) -> None:
    recs = make_records(20, items=("position", "euler"))
    (tmp_path / "s.bin").write_bytes(liberty_binary_bytes(recs))
    res = convert(tmp_path / "s.bin", "-o", tmp_path / "b.csv", "--from", "liberty-binary",
                  "--rate", 120, "--map", "1=hand,2=index.proximal")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert read_pose_csv(tmp_path / "b.csv", rate_hz=120).n_frames == 20
    rec = truth(40)
    rec.poses["hand"].position[10:12] = np.nan
    rec.poses["hand"].rotation[10:12] = np.nan
    write_wide_csv(tmp_path / "w.csv", rec, units="cm")
    res = convert(tmp_path / "w.csv", "-o", tmp_path / "w_out.csv", "--from", "wide-csv",
                  "--units", "cm", "--rate", 120, "--map", "1=hand,2=index.proximal",
                  "--fill-gaps", 2)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "sensor 'hand': 1 gaps (2 frames) interpolated" in res.output
    back = read_pose_csv(tmp_path / "w_out.csv", rate_hz=120)
    assert back.poses["hand"].valid.all()
    np.testing.assert_allclose(back.poses["hand"].position, rec.poses["hand"].position[[0]].repeat(
        40, axis=0), atol=0.05)  # fmt: skip


def test_c3d_with_residuals(tmp_path) -> None:
    pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    from .test_io_c3d import ARM, FORE, moving, write_c3d

    _, _, a = moving(30, ARM, 1)
    _, _, f = moving(30, FORE, 2)
    f[:, :, 0] += 50.0  # forearm cluster ~ a finger segment away from the arm cluster
    labels = ["A1", "A2", "A3", "F1", "F2", "F3", "F4"]
    write_c3d(tmp_path / "m.c3d", labels, np.concatenate([a, f], axis=1))
    res = convert(tmp_path / "m.c3d", "-o", tmp_path / "m.csv", "--from", "c3d", "--map",
                  "A=hand,F=index.proximal", "--residuals", tmp_path / "res.csv")  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "rigid fit of 4 markers" in res.output
    text = (tmp_path / "res.csv").read_text().splitlines()
    assert text[0] == "time,segment,residual_mm,markers" and len(text) == 61


BAD_CASES = [
    ("trunc", ["--from", "liberty", "--rate", 240], r"s\.txt:12: expected 7 fields"),
    ("station", ["--from", "liberty", "--rate", 240], r"s\.txt:3: unknown station 5 \(not in"),
    ("nomap", ["--from", "liberty", "--rate", 240], "name every station with --map"),
    ("good", ["--from", "liberty", "--rate", 240, "--units", "m"], "implausible distance"),
    ("good", ["--from", "liberty"], "--rate is needed"),
    ("good", ["--from", "liberty-binary", "--rate", 240], r"record 1 \(byte 0\): not a Liberty"),
    ("good", ["--from", "wide-csv"], r"s\.txt:1: no column matches 'loc\{n\}_x'"),
    ("good", ["--from", "c3d"], "not a readable C3D file"),
    ("good", ["--from", "liberty", "--rate", 240, "--map", "1=thumb"], "not a sensor name"),
    ("good", ["--from", "liberty", "--rate", 240, "--columns", "x=a"], "does not apply"),
]


@pytest.mark.parametrize(("kind", "args", "match"), BAD_CASES)
def test_bad_input_one_line_exit_2_no_output(tmp_path, kind, args, match) -> None:
    lines = format_liberty_ascii(make_records(6)).splitlines(keepends=True)
    if kind == "trunc":
        lines[-1] = lines[-1][:12]
    elif kind == "station":
        lines[2] = "05" + lines[2][2:]
    (tmp_path / "s.txt").write_text("".join(lines), newline="")
    out = tmp_path / "o.csv"
    extra = [] if kind == "nomap" or "--map" in args else ["--map", "1=hand,2=index.proximal"]
    if "--from" in args and args[args.index("--from") + 1] == "wide-csv":
        extra.append("--units=cm")
    res = convert(tmp_path / "s.txt", "-o", out, *args, *extra)
    assert res.exit_code == 2, res.output
    assert isinstance(res.exception, SystemExit)
    text = " ".join(res.output.split())  # rich may wrap long lines in a narrow terminal
    assert text.startswith("error: ")
    assert "Traceback" not in res.output
    assert re.search(match, text), text
    assert not out.exists()
    assert not list(tmp_path.glob(".o.csv.*"))  # no temporary file left behind


def test_failure_leaves_an_existing_output_untouched(tmp_path) -> None:
    lines = format_liberty_ascii(make_records(4)).splitlines(keepends=True)
    (tmp_path / "s.txt").write_text("".join(lines[:-1]) + lines[-1][:9], newline="")
    out = tmp_path / "o.csv"
    out.write_text("precious\n")
    res = convert(tmp_path / "s.txt", "-o", out, "--from", "liberty", "--rate", 240,
                  "--map", "1=hand,2=index.proximal")  # fmt: skip
    assert res.exit_code == 2
    assert out.read_text() == "precious\n"
