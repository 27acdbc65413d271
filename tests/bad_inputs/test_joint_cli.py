"""``fingerfit joint``: a result on good data, one-line refusals on bad, nothing half-written.

The joint is written by fingerfit's own Liberty writer from a cached simulated subject
(stations 1-4 = hand, index proximal, middle, distal; inches, 240 Hz) and as a pose CSV
with the quaternions of one sensor pair written in another order.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fingerfit.io import read_pose_csv, write_pose_csv
from fingerfit.session import PoseSeries, Recording
from fingerfit.transforms import angle_between_axes, matrix_from_quat_wxyz, quat_wxyz_from_matrix

from ..conftest import subject
from ._cli import listing, refused, run

LIB = ("--from", "liberty", "--items", "2,7,9,1", "--units", "in", "--rate", "240")


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> Path:
    from fingerfit.simulate.trackerfiles import write_tracker_subject

    root = tmp_path_factory.mktemp("joint")
    sub = subject("realistic", 2)
    lib = write_tracker_subject(sub, root / "lib", "liberty-ascii")
    (root / "in").mkdir()
    (root / "in" / "grasp.txt").write_bytes(lib.files["grasp.csv"].read_bytes())
    return root


def test_joint_writes_json_and_table(files, tmp_path) -> None:
    src = files / "in" / "grasp.txt"
    out = tmp_path / "pip.json"
    res = run("joint", src, *LIB, "--parent", "2", "--child", "3", "--kind", "hinge", "-o", out)
    assert res.exit_code == 0, res.output
    # Results in the file's units (--units in), the pivot residual also in mm.
    assert "hinge joint (sara), in" in res.output and "pivot residual" in res.output
    doc = json.loads(out.read_text())
    assert doc["kind"] == "hinge" and doc["parent"] == "2" and doc["units"] == "in"
    assert doc["quality"]["pivot_residual_mm"] < 2.0
    assert doc["quality"]["cycles"] >= 3
    assert doc["quality"]["frames"] > 1000
    # The same joint through the API from the simulated truth: the flexion axis agrees.
    sub = subject("realistic", 2)
    axis = sub.truth.fingers["index"].axis[1]  # PIP, tracker frame at the reference posture
    proximal = sub.session.reference.poses["index.proximal"].mean()[1]
    a_true = proximal.T @ axis
    assert np.degrees(angle_between_axes(np.array(doc["axis_parent"]), a_true)) < 3.0


def test_joint_refusals_are_one_line_and_write_nothing(files, tmp_path) -> None:
    src = files / "in" / "grasp.txt"
    out = tmp_path / "o" / "j.json"
    out.parent.mkdir()
    before = listing(files, tmp_path)
    refused(run("joint", src, *LIB, "--parent", "2", "--child", "9", "-o", out),
            "field '--child'", "no segment '9'", "have: 1, 2, 3, 4")  # fmt: skip
    refused(run("joint", src, *LIB, "--parent", "2", "--child", "2", "-o", out),
            "parent and child are the same")  # fmt: skip
    refused(run("joint", src, *LIB, "--parent", "2", "--child", "3", "-o", src), "would overwrite")
    refused(run("joint", src, *LIB, "--parent", "2", "--child", "3", "--kind", "ball", "-o", out),
            "grasp.txt: 2 -> 3: the motion turns about one axis only")  # fmt: skip
    refused(run("joint", src, *LIB, "--parent", "3", "--child", "4", "--kind", "two_axis"),
            "only one axis is excited")  # fmt: skip
    refused(run("joint", src, *LIB, "--parent", "2", "--child", "3", "--method", "x", "-o", out),
            "unknown hinge method 'x'")  # fmt: skip
    refused(run("joint", files / "in" / "missing.csv", "--parent", "a", "--child", "b"),
            "missing.csv: file not found")  # fmt: skip
    refused(run("joint", src, "--from", "c3d", "--rate", "100", "--parent", "2", "--child", "3"),
            "field '--rate': does not apply to --from c3d")  # fmt: skip
    assert listing(files, tmp_path) == before


def test_joint_refuses_swapped_quaternion_order(files, tmp_path) -> None:
    """A pose CSV whose quaternions were written x,y,z,w: refused, naming the order."""
    sub = subject("realistic", 2)
    rec = sub.session.grasp[0]
    poses = {}
    for name in ("index.proximal", "index.middle"):
        p = rec.poses[name]
        q = quat_wxyz_from_matrix(p.rotation)[:, [1, 2, 3, 0]]  # x,y,z,w stored as w,x,y,z
        poses[name] = PoseSeries(p.position, matrix_from_quat_wxyz(q))
    bad = tmp_path / "swapped.csv"
    write_pose_csv(bad, Recording(rec.name, rec.time, poses))
    assert read_pose_csv(bad).n_frames == rec.n_frames
    before = listing(tmp_path)
    line = refused(
        run("joint", bad, "--parent", "index.proximal", "--child", "index.middle",
            "-o", tmp_path / "j.json"),
        "swapped.csv: index.proximal -> index.middle: the rotations look",
    )  # fmt: skip
    assert "x,y,z,w order" in line or "conjugated" in line
    assert listing(tmp_path) == before


def test_joint_refuses_wrong_units(files, tmp_path) -> None:
    """The Liberty file (inches) declared as millimetres: the PIP centre would lie 0.9 mm
    from the farther sensor. Refused naming --units; nothing written."""
    src = files / "in" / "grasp.txt"
    out = tmp_path / "j.json"
    before = listing(files, tmp_path)
    lib = ("--from", "liberty", "--items", "2,7,9,1", "--rate", "240")
    line = refused(
        run("joint", src, *lib, "--units", "mm", "--parent", "2", "--child", "3", "-o", out),
        "grasp.txt: field '--units': 2 -> 3: the joint centre lies",
        "farther segment origin (plausible 10-2000 mm)",
        "declared as millimetres",
    )
    assert "inches" in line
    assert listing(files, tmp_path) == before


def test_joint_on_a_real_hinge_with_a_measured_axis(tmp_path) -> None:
    """The real mechanical hinge of tests/data/ancillao-hinge through the command: the
    written axis lies within 0.3 deg of the pin line measured by markers on the pin."""
    from ..realdata import HINGE_DIR, load_measured_hinge

    out = tmp_path / "hinge.json"
    res = run("joint", HINGE_DIR / "hinge.csv", "--from", "wide-csv", "--units", "mm",
              "--rate", "50", "--parent", "1", "--child", "2", "-o", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["kind"] == "hinge" and doc["units"] == "mm"
    truth = load_measured_hinge()
    axis = np.array(doc["axis_parent"])
    assert np.degrees(angle_between_axes(axis, truth.axis_parent)) < 0.3
