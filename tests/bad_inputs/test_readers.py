"""Readers on the command line: garbled numbers, truncated C3D files, bad model files.

Items 3 and 4 of the trust issue. Every refusal is one ``error:`` line naming the file
and the line or field, exit status 2, and no output file appears.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from fingerfit.io.liberty import format_liberty_ascii
from fingerfit.io.widecsv import write_wide_csv
from fingerfit.simulate import write_subject

from ..conftest import subject
from ..test_io_liberty import make_records
from ._cli import listing, refused, run

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
REAL_C3D = DATA / "optotrak-arm" / "kinematics_racing_propulsion.c3d"


@pytest.fixture(scope="module")
def source(tmp_path_factory) -> Path:
    """Session source files (pose CSVs, landmarks, events) of a simulated subject."""
    return write_subject(subject("realistic", 2), tmp_path_factory.mktemp("src") / "S")


def _edit(path: Path, line: int, column: int, value: str) -> None:
    lines = path.read_text().splitlines()
    fields = lines[line - 1].split(",")
    fields[column] = value
    lines[line - 1] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")


def _session_args(src: Path, out: Path) -> list:
    return [
        "session", out, "--subject", "P07", "--units", "mm", "--rate", "240",
        "--reference", src / "reference.csv", "--grasp", src / "grasp.csv",
        "--landmarks", src / "landmarks.csv", "--targets", src / "targets.csv",
        "--events", src / "events.csv",
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("file", "line", "column", "value", "expected"),
    [
        ("grasp.csv", 7, 4, "inf", "grasp.csv:7: field 'z': not a finite number: 'inf'"),
        ("grasp.csv", 9, 2, "-Infinity", "grasp.csv:9: field 'x': not a finite number"),
        ("grasp.csv", 9, 6, "1e999", "grasp.csv:9: field 'qx': not a finite number: '1e999'"),
        ("grasp.csv", 5, 0, "nan", "grasp.csv:5: field 'time': time is missing or not finite"),
        ("grasp.csv", 5, 3, "1e308", "grasp.csv:5: field 'y': coordinate 1e+308 mm is implausible"),
        ("grasp.csv", 5, 3, "1_000", "grasp.csv:5: field 'y': not a finite number: '1_000'"),
        ("reference.csv", 3, 2, '"1"', "reference.csv:3: field 'x': not a number: '\"1\"'"),
        ("landmarks.csv", 2, 1, "inf", "landmarks.csv:2: field 'x': coordinate must be a finite"),
        ("landmarks.csv", 3, 3, "NaN", "landmarks.csv:3: field 'z': coordinate must be a finite"),
        ("events.csv", 2, 4, "Infinity", "events.csv:2: field 'end': start and end (s) must be"),
        ("events.csv", 2, 3, "abc", "events.csv:2: field 'start': start and end (s) must be a num"),
        ("events.csv", 2, 4, "-1", "events.csv:2: need start < end, got "),
        ("events.csv", 2, 1, "pinky", "events.csv:2: field 'finger': unknown digit 'pinky'"),
        ("landmarks.csv", 3, 0, "index.knuckle", "landmarks.csv:3: field 'name': unknown landmark"),
        (
            "landmarks.csv",
            3,
            0,
            "index.mp",
            "landmarks.csv:3: field 'name': landmark 'index.mp' gi",
        ),
        (
            "landmarks.csv",
            1,
            0,
            "label",
            "landmarks.csv:1: header must be 'name,x,y,z', found 'lab",
        ),
        ("grasp.csv", 6, 2, "1\x002", "grasp.csv:6: not text: byte 0x00 at offset"),
        ("grasp.csv", 6, 2, "1\xe9", "grasp.csv:6: field 'x': not a number: '1\\xe9'"),
    ],
)
def test_non_finite_numbers_are_errors(
    tmp_path, source, file, line, column, value, expected
) -> None:
    src = tmp_path / "src"
    src.mkdir()
    for f in source.iterdir():
        if f.is_file():
            (src / f.name).write_bytes(f.read_bytes())
    _edit(src / file, line, column, value)
    before = listing(tmp_path)
    refused(run(*_session_args(src, tmp_path / "out")), expected)
    assert listing(tmp_path) == before


def test_garbled_time_cannot_blow_up_the_grid(tmp_path, source) -> None:
    src = tmp_path / "src"
    src.mkdir()
    for f in source.iterdir():
        if f.is_file():
            (src / f.name).write_bytes(f.read_bytes())
    lines = (src / "grasp.csv").read_text().splitlines()
    last = len(lines)
    _edit(src / "grasp.csv", last, 0, "1000000")
    before = listing(tmp_path)
    refused(
        run(*_session_args(src, tmp_path / "out")), f"grasp.csv:{last}: field 'time': time jumps"
    )
    assert listing(tmp_path) == before


def test_wide_csv_infinity_is_an_error(tmp_path) -> None:
    rec = subject("realistic", 2).session.grasp[0].slice(slice(0, 50))
    path = write_wide_csv(tmp_path / "log.csv", rec, units="cm")
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    col = header.index("loc2_y")
    _edit(path, 12, col, "Infinity")
    before = listing(tmp_path)
    args = ["convert", path, "-o", tmp_path / "out.csv", "--from", "wide-csv", "--units", "cm"]
    args += ["--rate", "240", "--map", "1=hand,2=index.proximal,3=index.middle,4=index.distal"]
    refused(run(*args), "log.csv:12: field 'loc2_y': not a finite number: 'Infinity'")
    assert listing(tmp_path) == before


@pytest.mark.parametrize(
    ("token", "expected"),
    [
        ("inf", "field 'position[1]': not a finite number: 'inf'"),
        ("-nan", "field 'position[1]': not a finite number: '-nan'"),
        ("3e38", "field 'position': coordinate 7.62e+39 mm is implausible"),
    ],
)
def test_liberty_ascii_bad_numbers(tmp_path, token, expected) -> None:
    recs = make_records(20, stations=(1, 2), items=("position", "quaternion", "timestamp"))
    lines = format_liberty_ascii(recs).splitlines()
    fields = lines[6].split()
    fields[2] = token
    lines[6] = " ".join(fields)
    path = tmp_path / "liberty.txt"
    path.write_text("\r\n".join(lines) + "\r\n", newline="")
    before = listing(tmp_path)
    args = ["convert", path, "-o", tmp_path / "out.csv", "--from", "liberty", "--items", "2,7,8"]
    args += ["--map", "1=hand,2=index.proximal"]
    refused(run(*args), f"liberty.txt:7: {expected}")
    assert listing(tmp_path) == before


@pytest.mark.parametrize(
    ("items", "column", "value", "expected"),
    [
        ("2,4", 4, "720.000", "liberty.txt:7: field 'euler': Euler angle 720 deg is outside"),
        ("2,7,9", 8, "4000000000", "liberty.txt:39: field 'frame count': frame count jumps by"),
    ],
)
def test_liberty_garbled_angles_and_frame_counts(tmp_path, items, column, value, expected) -> None:
    names = {"2": "position", "4": "euler", "7": "quaternion", "9": "frame"}
    recs = make_records(20, stations=(1, 2), items=tuple(names[k] for k in items.split(",")))
    lines = format_liberty_ascii(recs).splitlines()
    for k in (38, 39) if column == 8 else (6,):  # both stations of the last frame
        fields = lines[k].split()
        fields[column] = value
        lines[k] = " ".join(fields)
    path = tmp_path / "liberty.txt"
    path.write_text("\r\n".join(lines) + "\r\n", newline="")
    args = ["convert", path, "-o", tmp_path / "out.csv", "--from", "liberty", "--items", items]
    args += ["--map", "1=hand,2=index.proximal", "--rate", "240"]
    refused(run(*args), expected)
    assert not (tmp_path / "out.csv").exists()


# ------------------------------------------------------------------------------- C3D


def _small_c3d(path: Path, frames: int = 100) -> Path:
    """A C3D of one moving 3-marker cluster written with ezc3d (mm, 100 Hz)."""
    ezc3d = pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("ArmR1", "ArmR2", "ArmR3")
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    shape = np.array([[0.0, 0, 0], [80, 0, 0], [30, 50, 0]])
    pts = shape[None] + np.linspace(0, 50, frames)[:, None, None]
    data = np.ones((4, 3, frames))
    data[:3] = np.transpose(pts, (2, 1, 0))
    c["data"]["points"] = data
    c.write(str(path))
    return path


def _truncate(src: Path, dst: Path, frames: int) -> Path:
    raw = src.read_bytes()
    start = 512 * (struct.unpack("<H", raw[16:18])[0] - 1)
    n_points = struct.unpack("<H", raw[2:4])[0]
    dst.write_bytes(raw[: start + frames * 16 * n_points + 7])  # a partial frame too
    return dst


def test_truncated_c3d_written_here(tmp_path) -> None:
    full = _small_c3d(tmp_path / "full.c3d")
    cut = _truncate(full, tmp_path / "cut.c3d", 37)
    before = listing(tmp_path)
    res = run("convert", cut, "-o", tmp_path / "out.csv", "--from", "c3d", "--map", "ArmR=hand")
    refused(
        res,
        f"{cut}: truncated: header says 100 frames (needs {100 * 3 * 16} bytes of data), "
        "file holds 37",
    )
    assert listing(tmp_path) == before
    ok = run("convert", full, "-o", tmp_path / "out.csv", "--from", "c3d", "--map", "ArmR=hand")
    assert ok.exit_code == 0, ok.output


@pytest.mark.skipif(not REAL_C3D.is_file(), reason=f"real Optotrak C3D not found in {DATA}")
def test_truncated_real_c3d(tmp_path) -> None:
    pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")
    cut = _truncate(REAL_C3D, tmp_path / "propulsion.c3d", 149)
    before = listing(tmp_path)
    res = run("convert", cut, "-o", tmp_path / "o.csv", "--from", "c3d", "--map", "ArmR=hand")
    refused(
        res,
        "propulsion.c3d: truncated: header says 700 frames (needs 459200 bytes of data), "
        "file holds 149",
    )
    assert listing(tmp_path) == before


def test_c3d_header_garbage(tmp_path) -> None:
    full = _small_c3d(tmp_path / "full.c3d")
    raw = bytearray(full.read_bytes())
    raw[1] = 0x51
    (tmp_path / "key.c3d").write_bytes(bytes(raw))
    res = run("convert", tmp_path / "key.c3d", "-o", tmp_path / "o.csv", "--from", "c3d")
    refused(res, "key.c3d: not a readable C3D file (byte 2 of the header is 0x51, not 0x50)")
    raw = bytearray(full.read_bytes())
    raw[2:4] = struct.pack("<H", 2)  # header says 2 points, POINT:USED says 3
    (tmp_path / "used.c3d").write_bytes(bytes(raw))
    res = run("convert", tmp_path / "used.c3d", "-o", tmp_path / "o.csv", "--from", "c3d")
    refused(res, "used.c3d: not a readable C3D file (POINT:USED is 3, the header says 2 points)")
    assert not (tmp_path / "o.csv").exists()


def test_c3d_parameter_section_is_checked_before_ezc3d(tmp_path) -> None:
    """Damaged parameter records that made ezc3d hang or the reader crash (found by fuzzing)."""
    raw = _small_c3d(tmp_path / "full.c3d").read_bytes()
    dims = bytearray(raw)
    dims[raw.index(b"CONTACT") + 10] = 26  # 26 dimensions: a product beyond int64
    (tmp_path / "dims.c3d").write_bytes(bytes(dims))
    res = run("convert", tmp_path / "dims.c3d", "-o", tmp_path / "o.csv", "--from", "c3d")
    refused(res, "dims.c3d: not a readable C3D file (parameter record at byte ")
    ratio = bytearray(raw)
    ratio[raw.index(b"RATIO") + 10] = 0x80  # ROTATION:RATIO -32768: ezc3d never returned
    (tmp_path / "ratio.c3d").write_bytes(bytes(ratio))
    res = run("convert", tmp_path / "ratio.c3d", "-o", tmp_path / "o.csv", "--from", "c3d")
    refused(res, "ratio.c3d: not a readable C3D file (ROTATION:RATIO is -32768, must not be neg")
    assert not (tmp_path / "o.csv").exists()


# -------------------------------------------------------------------------- model files


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    d = write_subject(subject("realistic", 2), tmp_path_factory.mktemp("fit") / "S")
    res = run("fit", d)
    assert res.exit_code == 0, res.output
    return d / "model.json"


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (("joints", "pip", "quality", "cycles", "x"), "field 'fingers.index.joints.pip.quality"
         ".cycles': must be a whole number >= 0"),
        (("joints", "mp", "center", [1e300, 0, 0]), "field 'fingers.index.joints.mp.center': "
         "implausible value 1e+300"),
        (("joints", "dip", "quality", None), "field 'fingers.index.joints.dip.quality': must be"
         " an object"),
        (("segment_lengths", "middle", 10**400), "field 'fingers.index.segment_lengths.middle':"
         " must be a positive number"),
        (("reference_poses", []), "field 'reference_poses': must be an object"),
    ],
)  # fmt: skip
def test_bad_model_files(tmp_path, model_file, edit, expected) -> None:
    doc = json.loads(model_file.read_text())
    *keys, value = edit
    node = doc if keys[0] == "reference_poses" else doc["fingers"]["index"]
    for k in keys[:-1]:
        node = node[k]
    node[keys[-1]] = value
    path = tmp_path / "model.json"
    path.write_text(json.dumps(doc))
    before = listing(tmp_path)
    refused(run("export", path, "--urdf", tmp_path / "hand.urdf"), f"{path}: {expected}")
    assert listing(tmp_path) == before


def test_model_file_not_text(tmp_path, model_file) -> None:
    path = tmp_path / "model.json"
    path.write_bytes(model_file.read_bytes()[:100] + b"\xff\xfe" + model_file.read_bytes()[100:])
    refused(run("export", path, "--urdf", tmp_path / "h.urdf"), f"{path}: not UTF-8 text")
