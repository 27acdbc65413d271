"""Parquet through the commands: ``convert -o``, ``session``, ``angles -o``, ``retarget -o``,
``stream --record`` -- the same numbers as the CSV path, refusals in one line."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from fingerfit.io import parquet as fpq
from fingerfit.io import read_pose_csv, write_pose_csv
from fingerfit.io.widecsv import write_wide_csv
from fingerfit.simulate import write_subject

from ._live import fitted, write_recording
from .bad_inputs._cli import refused, run
from .conftest import subject


def _same_table(parquet: Path, csv: Path, fmt: str, atol: float = 0.0) -> pd.DataFrame:
    """The Parquet table's columns equal the CSV's, bit for bit (NaN where empty), or to
    ``atol``."""
    got = fpq.read_parquet(parquet, fmt)
    want = pd.read_csv(csv)
    assert got.names == list(want.columns)
    for c in want.columns:
        if atol:
            np.testing.assert_allclose(got.columns[c], want[c].to_numpy(float), atol=atol)
        else:
            assert np.array_equal(got.columns[c], want[c].to_numpy(float), equal_nan=True), c
    return want


def test_session_of_parquet_recordings_fits_like_the_csv_session(tmp_path: Path) -> None:
    src = write_subject(subject("realistic", 2), tmp_path / "src")
    models = {}
    for ext in ("csv", "parquet"):
        args = ["session", tmp_path / ext, "--subject", "S", "--rate", "240", "--fingers", "index"]
        for opt, name in (("--reference", "reference"), ("--grasp", "grasp"), ("--test", "test")):
            rec = read_pose_csv(src / f"{name}.csv", units="mm", rate_hz=240)
            args += [opt, write_pose_csv(tmp_path / f"{name}.{ext}", rec, units="mm")]
        args += ["--landmarks", src / "landmarks.csv", "-q"]
        r = run(*args)
        assert r.exit_code == 0, r.output
        r = run("fit", tmp_path / ext, "-o", tmp_path / f"{ext}.json", "-q")
        assert r.exit_code == 0, r.output
        models[ext] = json.loads((tmp_path / f"{ext}.json").read_text())["fingers"]
    names = sorted(p.name for p in (tmp_path / "parquet").iterdir())
    assert names == ["grasp.parquet", "landmarks.csv", "reference.parquet", "session.toml",
                     "test.parquet"]  # fmt: skip
    assert 'grasp = ["grasp.parquet"]' in (tmp_path / "parquet" / "session.toml").read_text()
    assert models["csv"] == models["parquet"]


def test_parquet_session_takes_events_naming_the_csv_recordings(tmp_path: Path) -> None:
    """events.csv written for targets.csv names the recording of a session converted to
    targets.parquet by its stem; a name no recording has is refused with its line and
    the session's recordings."""
    from fingerfit.io import load_session

    src = write_subject(subject("realistic", 2), tmp_path / "src")
    args = ["session", tmp_path / "pq", "--subject", "S", "--rate", "240", "--fingers", "index"]
    for opt, name in (("--reference", "reference"), ("--grasp", "grasp"), ("--targets", "targets")):
        rec = read_pose_csv(src / f"{name}.csv", units="mm", rate_hz=240)
        args += [opt, write_pose_csv(tmp_path / f"{name}.parquet", rec, units="mm")]
    args += ["--landmarks", src / "landmarks.csv", "-q"]
    assert "targets.csv," in (src / "events.csv").read_text()
    r = run(*args, "--events", src / "events.csv")
    assert r.exit_code == 0, r.output
    session = load_session(tmp_path / "pq")
    assert session.events and {e.recording for e in session.events} == {"targets.parquet"}
    assert (tmp_path / "pq" / "events.csv").read_bytes() == (src / "events.csv").read_bytes()
    bad = tmp_path / "events.csv"
    lines = (src / "events.csv").read_text().splitlines()
    lines[2] = lines[2].replace("targets.csv", "target.csv")
    bad.write_text("\n".join(lines) + "\n")
    line = refused(run(*args[:1], tmp_path / "pq2", *args[2:], "--events", bad), "events.csv:3:")
    assert "unknown recording 'target.csv' (the session's recordings: reference.parquet, " in line
    assert not (tmp_path / "pq2").exists()


def test_angles_and_urdf_names_to_parquet(tmp_path: Path) -> None:
    d, model = fitted()
    rec = read_pose_csv(d / "test.csv", units="mm")
    grasp = write_pose_csv(tmp_path / "test.parquet", rec, units="cm")
    for out, traj in (("a.csv", "q.csv"), ("a.parquet", "q.parquet")):
        r = run("angles", model, grasp, "--units", "cm", "-o", tmp_path / out,
                "--urdf-names", tmp_path / traj, "-q")  # fmt: skip
        assert r.exit_code == 0, r.output
    _same_table(tmp_path / "a.parquet", tmp_path / "a.csv", fpq.ANGLES)
    _same_table(tmp_path / "q.parquet", tmp_path / "q.csv", fpq.JOINTS)
    meta = pq.read_schema(tmp_path / "a.parquet").metadata
    assert meta[b"fingerfit.units"] == b"cm" and meta[b"fingerfit.angle_units"] == b"deg"
    assert pq.read_schema(tmp_path / "q.parquet").metadata[b"fingerfit.angle_units"] == b"rad"


def test_stream_record_parquet_equals_angles(tmp_path: Path) -> None:
    _, model = fitted()
    csv = write_recording(tmp_path / "rec.csv", 480)
    r = run(
        "stream", model, "--source", f"replay:{csv}@8", "--record", tmp_path / "live.parquet", "-q"
    )
    assert r.exit_code == 0, r.output
    r = run("angles", model, csv, "-o", tmp_path / "a.csv", "-q")
    assert r.exit_code == 0, r.output
    # To 1e-9, not to the bit: the stream computes the frames in the blocks they arrive in,
    # one frame under load, and BLAS sums a one-column product in another order than a
    # long one (the last bits of a few values differ).
    want = _same_table(tmp_path / "live.parquet", tmp_path / "a.csv", fpq.ANGLES, atol=1e-9)
    assert len(want) == 480
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv", "live.parquet", "rec.csv"]
    assert pq.ParquetFile(tmp_path / "live.parquet").metadata.num_row_groups >= 1


def test_record_output_appends_row_groups_and_discards_on_failure(tmp_path: Path) -> None:
    from fingerfit.live.outputs import RecordOutput

    out = RecordOutput(tmp_path / "sub" / "r.parquet", "cm")
    for k in range(3):
        out.push(pd.DataFrame({"time": np.arange(4.0) + 4 * k, "index.mp": np.full(4, -0.0)}))
        assert not (tmp_path / "sub" / "r.parquet").exists()
    out.close()
    f = pq.ParquetFile(tmp_path / "sub" / "r.parquet")
    assert f.metadata.num_row_groups == 3 and f.metadata.num_rows == 12
    assert np.signbit(f.read().column("index.mp").to_numpy()).all()
    out = RecordOutput(tmp_path / "new" / "r.parquet")
    out.push(pd.DataFrame({"time": [0.0]}))
    out.close(ok=False)
    assert not (tmp_path / "new").exists()


def test_convert_to_and_from_parquet(tmp_path: Path) -> None:
    rec = subject("exact", 1).session.grasp[0]
    mapping = ",".join(f"{i}={s}" for i, s in enumerate(rec.sensors, start=1))
    wide_csv = write_wide_csv(tmp_path / "w.csv", rec, units="cm")
    wide_pq = write_wide_csv(tmp_path / "w.parquet", rec, units="cm")
    common = ["--from", "wide-csv", "--rate", "240", "--map", mapping, "-q"]
    outs = {}
    for src, out, extra in (
        (wide_csv, "o.csv", ["--units", "cm"]),
        (wide_csv, "o.parquet", ["--units", "cm"]),
        (wide_pq, "p.parquet", []),
    ):
        r = run("convert", src, "-o", tmp_path / out, *common, *extra)
        assert r.exit_code == 0, r.output
        outs[out] = read_pose_csv(tmp_path / out, units="mm", rate_hz=240)
    for name in ("o.parquet", "p.parquet"):
        for s in rec.sensors:
            a, b = outs["o.csv"].poses[s], outs[name].poses[s]
            assert np.array_equal(a.position, b.position, equal_nan=True)
            assert np.array_equal(a.rotation, b.rotation, equal_nan=True)
    line = refused(
        run("convert", wide_pq, "-o", tmp_path / "x.csv", *common, "--units", "mm"),
        "w.parquet",
        "field 'fingerfit.units'",
    )
    assert "in cm, not mm" in line
    assert not (tmp_path / "x.csv").exists()
    # `fingerfit joint` reads the same files through the same dispatch: the wide Parquet
    # file states its units, so no --units is needed and the results are in its cm.
    res = run(
        "joint", wide_pq, "--from", "wide-csv", "--rate", "240", "--parent", "2", "--child", "3",
        "--kind", "hinge", "-o", tmp_path / "j.json",
    )  # fmt: skip
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "j.json").read_text())["units"] == "cm"


def test_refusals_through_the_commands(tmp_path: Path) -> None:
    d, model = fitted()
    rec = read_pose_csv(d / "test.csv", units="mm")
    good = write_pose_csv(tmp_path / "t.parquet", rec, units="mm")
    bad = tmp_path / "bad.parquet"
    bad.write_bytes(good.read_bytes()[:-100])
    refused(
        run("angles", model, bad, "-o", tmp_path / "a.parquet"),
        "bad.parquet",
        "not a readable Parquet",
    )
    table = pq.read_table(good)
    pq.write_table(table.drop_columns(["qw"]), tmp_path / "noqw.parquet")
    refused(run("angles", model, tmp_path / "noqw.parquet", "-o", tmp_path / "a.csv"),
            "noqw.parquet", "field 'qw'", "column missing")  # fmt: skip
    refused(run("angles", model, good, "--units", "cm", "-o", tmp_path / "a.csv"),
            "field 'fingerfit.units'")  # fmt: skip
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "bad.parquet",
        "noqw.parquet",
        "t.parquet",
    ]


def test_retarget_to_parquet(tmp_path: Path) -> None:
    pytest.importorskip("mujoco")
    pytest.importorskip("pinocchio")
    from .test_retarget import MAP, ROBOT_XML

    d, model = fitted()
    (tmp_path / "toy.xml").write_text(ROBOT_XML)
    (tmp_path / "toy.toml").write_text(MAP)
    shutil.copy(d / "test.csv", tmp_path / "test.csv")
    for out in ("q.csv", "q.parquet"):
        r = run("retarget", model, tmp_path / "test.csv", "--robot", tmp_path / "toy.xml",
                "--map", tmp_path / "toy.toml", "-o", tmp_path / out[2:] / out, "-q")  # fmt: skip
        assert r.exit_code == 0, r.output
    _same_table(tmp_path / "parquet" / "q.parquet", tmp_path / "csv" / "q.csv", fpq.JOINTS)
    refused(run("retarget", model, tmp_path / "test.csv", "--robot", tmp_path / "toy.xml",
                "--map", tmp_path / "toy.toml", "-o", tmp_path / "o" / "q.txt"),
            "field '--output'", ".csv or .parquet")  # fmt: skip


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def test_convert_a_pose_table_to_parquet_and_back_bit_for_bit(tmp_path: Path) -> None:
    """No --from: the extension chooses. The rows stay the rows of the file (its sensor
    order within a frame, a sample with an empty field, a frame lost), the numbers bit for
    bit (-0.0, a subnormal, digits beyond the shortest form), the units the file's own."""
    rec = subject("exact", 1).session.grasp[0].slice(slice(0, 40))
    text = write_pose_csv(tmp_path / "g.csv", rec).read_text().splitlines()
    head, body = text[0], text[1:]
    n_s = len(rec.sensors)
    body[0], body[1] = body[1], body[0]  # another sensor order in the first frame
    del body[5 * n_s : 6 * n_s]  # frame 5 lost
    f = body[3].split(",")
    f[2], f[3], f[4], f[5] = "-0.0", "5e-324", "12.500000000000000001", ""
    body[3] = ",".join(f)
    src = tmp_path / "odd.csv"
    src.write_text("\n".join([head, *body]) + "\n")
    r = run("convert", src, "-o", tmp_path / "odd.parquet", "-q")
    assert r.exit_code == 0, r.output
    got = fpq.read_parquet(tmp_path / "odd.parquet", fpq.POSE, text=("sensor",))
    assert got.meta["fingerfit.units"] == "mm" and got.n_rows == len(body)
    rows = [line.split(",") for line in body]
    codes, names = got.columns["sensor"]
    assert [names[c] for c in codes] == [r[1] for r in rows]
    for j, c in enumerate(("time", "x", "y", "z", "qw", "qx", "qy", "qz")):
        want = np.array([float(r[j + (j > 0)] or "nan") for r in rows])
        assert np.array_equal(_bits(got.columns[c]), _bits(want)), c
    # and back: the CSV fingerfit wrote comes back byte for byte
    r = run("convert", tmp_path / "g.csv", "-o", tmp_path / "g.parquet", "-q")
    assert r.exit_code == 0, r.output
    r = run("convert", tmp_path / "g.parquet", "-o", tmp_path / "back.csv", "-q")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "back.csv").read_bytes() == (tmp_path / "g.csv").read_bytes()
    # a table in cm stays in cm both ways, and says so in its metadata
    r = run("convert", tmp_path / "g.csv", "-o", tmp_path / "cm.parquet", "--units", "cm",
            "--no-unit-check")  # fmt: skip
    assert r.exit_code == 0, r.output
    assert fpq.parquet_schema(tmp_path / "cm.parquet")[1]["fingerfit.units"] == "cm"
    r = run("convert", tmp_path / "cm.parquet", "-o", tmp_path / "cm.csv", "--no-unit-check")
    assert r.exit_code == 0, r.output
    assert (tmp_path / "cm.csv").read_bytes() == (tmp_path / "g.csv").read_bytes()


def test_convert_says_what_it_cannot_tell(tmp_path: Path) -> None:
    """A file that is not a pose table needs --from; a Parquet file named .csv is named as
    one, never shown as its binary bytes (by convert and by every reader of a pose CSV)."""
    rec = subject("exact", 1).session.grasp[0]
    wide = write_wide_csv(tmp_path / "w.csv", rec, units="cm")
    line = refused(run("convert", wide, "-o", tmp_path / "o.parquet"), "w.csv", "'--from'")
    assert "give --from liberty, liberty-binary, wide-csv or c3d" in line
    hidden = tmp_path / "grasp.csv"
    hidden.write_bytes(write_pose_csv(tmp_path / "g.parquet", rec).read_bytes())
    for args in (
        ("convert", hidden, "-o", tmp_path / "o.parquet"),
        ("joint", hidden, "--parent", "hand", "--child", "index.proximal"),
    ):
        line = refused(run(*args), "grasp.csv:1:")
        assert "not text: a Parquet file (name it grasp.parquet" in line, line
        assert "PAR1" not in line
    assert not (tmp_path / "o.parquet").exists()
