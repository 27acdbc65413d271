"""C3D reader: marker clusters -> segment poses (rigid fit) and ROTATION channels."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fingerfit.errors import FingerfitError
from fingerfit.io.c3d import (
    find_clusters,
    parse_clusters,
    read_c3d,
    read_c3d_markers,
    read_c3d_segments,
)
from fingerfit.io.rigid import technical_frame

ezc3d = pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")

ARM = np.array([[0.0, 0, 0], [80, 0, 0], [30, 50, 0]])
FORE = np.array([[0.0, 0, 0], [70, 10, 0], [20, 45, 5], [40, 20, 30]])


def write_c3d(path, labels, points, rate=100.0, units="mm", rotations=None, rot_labels=None):
    """points: (n, m, 3) in ``units``; rotations: (n_ch, n, 4, 4)."""
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    n, m, _ = points.shape
    data = np.ones((4, m, n))
    data[:3] = np.transpose(points, (2, 1, 0))
    c["data"]["points"] = data
    if rotations is not None:
        c["data"]["rotations"] = np.transpose(rotations, (2, 3, 0, 1))
        c.add_parameter("ROTATION", "LABELS", list(rot_labels))
        c.add_parameter("ROTATION", "RATE", [rate])
        c.add_parameter("ROTATION", "USED", [len(rot_labels)])
    c.write(str(path))
    return path


def moving(n: int, shape: np.ndarray, seed: int):
    rot = Rotation.from_rotvec(
        np.linspace(0, 1, n)[:, None] * Rotation.random(random_state=seed).as_rotvec()
    )
    trans = np.array([500.0, 200.0, 1000.0]) + np.linspace(0, 100, n)[:, None] * [1, 0.5, 0]
    pts = np.einsum("nij,mj->nmi", rot.as_matrix(), shape) + trans[:, None, :]
    return rot.as_matrix(), trans, pts


def test_find_and_parse_clusters() -> None:
    labels = ["ArmR1", "ArmR2", "ArmR3", "Probe1", "Probe2", "Sternum", "ForearmR3", "ForearmR1"]
    labels += ["ForearmR2", "X10", "X2", "X1"]
    assert find_clusters(labels) == {
        "ArmR": ["ArmR1", "ArmR2", "ArmR3"],
        "ForearmR": ["ForearmR1", "ForearmR2", "ForearmR3"],
        "X": ["X1", "X2", "X10"],
    }
    assert parse_clusters("A=a,b,c;B=d,e,f,g") == {"A": ["a", "b", "c"], "B": ["d", "e", "f", "g"]}
    with pytest.raises(FingerfitError, match="clusters"):
        parse_clusters("A=a,b")


def test_cluster_poses_recover_known_motion(tmp_path) -> None:
    n = 120
    r_arm, t_arm, p_arm = moving(n, ARM, 1)
    r_fore, t_fore, p_fore = moving(n, FORE, 2)
    p_fore[10:15, 3] = np.nan  # 3 of 4 visible: still fitted
    p_arm[20:23, 1] = np.nan  # 2 of 3 visible: missing
    labels = ["ArmR1", "ArmR2", "ArmR3", "ForearmR1", "ForearmR2", "ForearmR3", "ForearmR4"]
    pts = np.concatenate([p_arm, p_fore], axis=1) / 1000.0
    path = write_c3d(tmp_path / "m.c3d", labels, pts, rate=70.0, units="m")
    seg = read_c3d_segments(path, segments={"ArmR": "hand", "ForearmR": "index.proximal"})
    rec = seg.recording
    assert rec.sensors == ["hand", "index.proximal"]
    np.testing.assert_allclose(rec.time, np.arange(n) / 70.0)
    for name, r_true, t_true, local in (
        ("hand", r_arm, t_arm, ARM),
        ("index.proximal", r_fore, t_fore, FORE),
    ):
        pose = rec.poses[name]
        ok = pose.valid
        # The segment frame is the cluster's technical frame, at the markers' centroid.
        r_off, origin = technical_frame(local)
        # (C3D stores float32: about 1e-4 mm at 1 m from the origin.)
        np.testing.assert_allclose(pose.rotation[ok], r_true[ok] @ r_off, atol=1e-5)
        np.testing.assert_allclose(
            pose.position[ok], np.einsum("nij,j->ni", r_true[ok], origin) + t_true[ok], atol=1e-3
        )
        assert np.nanmax(seg.fits[name].residual) < 1e-3
    assert np.flatnonzero(~rec.poses["hand"].valid).tolist() == [20, 21, 22]
    assert rec.poses["index.proximal"].valid.all()
    assert seg.fits["index.proximal"].n_markers[10:15].tolist() == [3] * 5
    assert "sensor 'hand': 3 of 120 frames missing" in rec.notes
    assert any(n.startswith("segment 'hand': rigid fit of 3 markers") for n in rec.notes)


def test_static_trial_shapes_give_the_same_frames(tmp_path) -> None:
    _, _, p_static = moving(30, ARM, 3)
    _, _, p_move = moving(80, ARM, 4)
    labels = ["ArmR1", "ArmR2", "ArmR3"]
    rng = np.random.default_rng(0)
    noisy = p_move + rng.normal(scale=0.3, size=p_move.shape)
    write_c3d(tmp_path / "static.c3d", labels, p_static)
    write_c3d(tmp_path / "move.c3d", labels, noisy)
    with_static = read_c3d_segments(tmp_path / "move.c3d", static=tmp_path / "static.c3d")
    assert any("shape from static.c3d" in n for n in with_static.recording.notes)
    np.testing.assert_allclose(with_static.shapes["ArmR"], technical_frame_shape(ARM), atol=1e-3)
    again = read_c3d_segments(tmp_path / "move.c3d", shapes=with_static.shapes)
    np.testing.assert_array_equal(
        again.recording.poses["ArmR"].rotation, with_static.recording.poses["ArmR"].rotation
    )
    assert 0.1 < np.median(again.fits["ArmR"].residual) < 0.4


def technical_frame_shape(local: np.ndarray) -> np.ndarray:
    r, o = technical_frame(local)
    return (local - o) @ r


def test_deforming_cluster_is_reported(tmp_path) -> None:
    _, _, pts = moving(50, FORE, 5)
    pts[25:28, 2] += [0.0, 0.0, 20.0]  # a marker knocked 20 mm for 3 frames
    write_c3d(tmp_path / "d.c3d", ["A1", "A2", "A3", "A4"], pts)
    rec = read_c3d(tmp_path / "d.c3d", segments={"A": "hand"})
    note = next(n for n in rec.notes if n.startswith("segment 'hand'"))
    assert "3 frames above 5 mm" in note and "(frame 2" in note


def test_rotation_channels(tmp_path) -> None:
    n = 40
    rot = Rotation.random(n, random_state=7).as_matrix()
    t = np.random.default_rng(8).normal(scale=100.0, size=(n, 3))
    m = np.tile(np.eye(4), (2, n, 1, 1))
    m[0, :, :3, :3] = rot
    m[0, :, :3, 3] = t
    m[1, :, :3, :3] = rot[::-1]
    m[1, 5] = np.nan
    path = write_c3d(tmp_path / "r.c3d", ["m1"], np.zeros((n, 1, 3)), rotations=m,
                     rot_labels=["Hand", "Index1"])  # fmt: skip
    seg = read_c3d_segments(
        path, segments={"Hand": "hand", "Index1": "index.proximal"}, check=False
    )
    rec = seg.recording
    np.testing.assert_allclose(rec.poses["hand"].rotation, rot, atol=1e-12)
    np.testing.assert_allclose(rec.poses["hand"].position, t, atol=1e-9)
    assert np.flatnonzero(~rec.poses["index.proximal"].valid).tolist() == [5]
    m[0, 7, :3, :3] *= 1.1
    bad = write_c3d(tmp_path / "b.c3d", ["m1"], np.zeros((n, 1, 3)), rotations=m,
                    rot_labels=["Hand", "Index1"])  # fmt: skip
    with pytest.raises(FingerfitError, match=r"b\.c3d: field 'ROTATION:Hand': frame 8: not a rot"):
        read_c3d_segments(bad)


def test_c3d_errors(tmp_path) -> None:
    _, _, pts = moving(10, ARM, 6)
    path = write_c3d(tmp_path / "e.c3d", ["ArmR1", "ArmR2", "ArmR3"], pts)
    with pytest.raises(FingerfitError, match=r"field 'map': no cluster or ROTATION channel 'Arm'"):
        read_c3d(path, segments={"Arm": "hand"})
    with pytest.raises(FingerfitError, match=r"names marker 'ArmR4'"):
        read_c3d(path, clusters={"ArmR": ["ArmR1", "ArmR2", "ArmR4"]})
    (tmp_path / "junk.c3d").write_bytes(b"\x00" * 100)
    with pytest.raises(FingerfitError, match=r"junk\.c3d: not a readable C3D file"):
        read_c3d(tmp_path / "junk.c3d")
    with pytest.raises(FingerfitError, match="file not found"):
        read_c3d(tmp_path / "none.c3d")
    write_c3d(tmp_path / "u.c3d", ["ArmR1", "ArmR2", "ArmR3"], pts, units="furlong")
    with pytest.raises(FingerfitError, match=r"field 'POINT:UNITS': unknown units 'furlong'"):
        read_c3d_markers(tmp_path / "u.c3d")
    assert read_c3d_markers(tmp_path / "u.c3d", units="cm").points[0, 0, 0] == pts[0, 0, 0] * 10
