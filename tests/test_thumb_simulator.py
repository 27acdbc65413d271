"""The simulator's thumb: literature anatomy, exact truth, touches, protocols."""

from __future__ import annotations

import numpy as np
import pytest

from fingerfit.kinematics import two_axis_angles
from fingerfit.simulate import contact as ct
from fingerfit.simulate.anatomy import sample_finger, segment_motions
from fingerfit.simulate.thumb import (
    BUCHHOLZ_THUMB,
    CMC_ANGLE_DEG,
    CMC_OFFSET_MM,
    MCP_OFFSET_MM,
    NOMINAL_HAND_LENGTH,
    THUMB_KEYS,
    THUMB_LENGTH_CV,
    moved,
    sample_pad,
    sample_thumb,
    thumb_segment_motions,
)
from fingerfit.transforms import axis_angle_matrix

_EYE = (np.eye(3)[None], np.zeros((1, 3)))


def _hand(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial.transform import Rotation

    return Rotation.random(random_state=rng).as_matrix(), rng.normal(0, 100.0, 3)


def _cohort(n: int, side: str = "left"):
    rng = np.random.default_rng(7)
    out = []
    for _ in range(n):
        rot, origin = _hand(rng)
        length = NOMINAL_HAND_LENGTH * rng.normal(1.0, 0.06)
        out.append((length, sample_thumb(rng, length, side, hand_rotation=rot, hand_origin=origin)))
    return out


def test_sampled_anatomy_matches_the_literature_over_50_subjects() -> None:
    cohort = _cohort(50)
    ratios = np.array([t.lengths / length for length, t in cohort])
    # Buchholz 1992 ratios: the link CMC-MCP and MCP-IP run along the thumb's line; the
    # distal link ends at the nail edge, which sits the nail height above that line.
    sd = BUCHHOLZ_THUMB * THUMB_LENGTH_CV
    assert np.all(np.abs(ratios[:, :2].mean(axis=0) - BUCHHOLZ_THUMB[:2]) < sd[:2])
    assert abs(ratios[:, 2].mean() - BUCHHOLZ_THUMB[2]) < 2 * sd[2]
    cmc_off = np.array([t.offset("cmc") for _, t in cohort])
    cmc_ang = np.degrees([t.axes_angle("cmc") for _, t in cohort])
    mcp_off = np.array([t.offset("mcp") for _, t in cohort])
    # Chang & Pollard 2008: 4.6 mm apart, 87 deg (scaled by hand size: within one SD).
    assert abs(cmc_off.mean() - CMC_OFFSET_MM[0]) < CMC_OFFSET_MM[1]
    assert abs(cmc_ang.mean() - CMC_ANGLE_DEG[0]) < CMC_ANGLE_DEG[1]
    assert abs(mcp_off.mean() - MCP_OFFSET_MM[0]) < MCP_OFFSET_MM[1]
    # Every subject: non-intersecting, non-orthogonal CMC lines; per-subject variation.
    assert cmc_off.min() > 1.0 and cmc_off.std() > 0.5
    assert np.mean(np.abs(cmc_ang - 90.0) > 0.5) > 0.8 and cmc_ang.std() > 2.0
    # The pad lies palmar of the nail edge, 12-18 mm tip-to-tip needs ~2 x 7 mm depth.
    for _, t in cohort:
        z = t.frame[:, 2]
        assert 3.0 < (t.tip - t.pad.centre) @ z < 7.0
        assert 2.5 < t.pad.half_thickness < 5.5
        # Frame is right-handed and orthonormal; the CMC axes near y and +-z.
        assert np.allclose(t.frame.T @ t.frame, np.eye(3), atol=1e-12)
        assert np.linalg.det(t.frame) == pytest.approx(1.0)
        assert t.axis["cmc"] @ t.frame[:, 1] > 0.7
        assert t.side * (t.axis["cmc_abduction"] @ t.frame[:, 2]) > 0.3


def test_left_thumb_is_the_mirror_of_the_right() -> None:
    rot, origin = np.eye(3), np.zeros(3)
    right = sample_thumb(
        np.random.default_rng(3), 170.0, "right", hand_rotation=rot, hand_origin=origin
    )
    left = sample_thumb(
        np.random.default_rng(3), 170.0, "left", hand_rotation=rot, hand_origin=origin
    )
    m = np.diag([1.0, -1.0, 1.0])
    assert np.allclose(left.tip, m @ right.tip) and np.allclose(
        left.pad.centre, m @ right.pad.centre
    )
    ang = {k: np.radians(np.array([10.0, 25.0])) for k in THUMB_KEYS}
    tl = moved(
        thumb_segment_motions(left, ang, (np.eye(3)[None].repeat(2, 0), np.zeros((2, 3))))[
            "distal"
        ],
        left.tip,
    )
    tr = moved(
        thumb_segment_motions(right, ang, (np.eye(3)[None].repeat(2, 0), np.zeros((2, 3))))[
            "distal"
        ],
        right.tip,
    )
    # Same angles give mirrored positions: flexion and palmar abduction mean the same.
    assert np.allclose(tl, tr @ m, atol=1e-9)
    # Positive palmar abduction moves the tip palmar (hand -z) on both hands; positive
    # CMC flexion moves it ulnarly (towards the little finger).
    for t in (left, right):
        for k, direction in (
            ("cmc_abduction", np.array([0, 0, -1.0])),
            ("cmc", np.array([0, -t.side, 0.0])),
        ):
            a = {j: np.zeros(1) for j in THUMB_KEYS}
            a[k] = np.radians([20.0])
            tip = moved(thumb_segment_motions(t, a, _EYE)["distal"], t.tip)[0]
            assert (tip - t.tip) @ direction > 5.0


def test_two_axis_angles_recover_the_thumb_angles() -> None:
    rng = np.random.default_rng(5)
    rot, origin = _hand(rng)
    t = sample_thumb(rng, 175.0, "right", hand_rotation=rot, hand_origin=origin)
    n = 200
    ang = {
        "cmc": rng.uniform(-0.5, 1.0, n),
        "cmc_abduction": rng.uniform(-0.3, 1.0, n),
        "mcp": rng.uniform(-0.2, 1.0, n),
        "mcp_abduction": rng.uniform(-0.25, 0.25, n),
        "ip": rng.uniform(-0.2, 1.4, n),
    }
    hr = axis_angle_matrix(
        np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8]), rng.uniform(-1, 1, n)
    )
    seg = thumb_segment_motions(t, ang, (hr, rng.normal(0, 50, (n, 3))))
    q_cmc = np.transpose(seg["hand"][0], (0, 2, 1)) @ seg["metacarpal"][0]
    q_mcp = np.transpose(seg["metacarpal"][0], (0, 2, 1)) @ seg["proximal"][0]
    q_ip = np.transpose(seg["proximal"][0], (0, 2, 1)) @ seg["distal"][0]
    # Flexion proximal: proximal axis = flexion, distal axis = ab/adduction.
    theta, beta = two_axis_angles(q_cmc, t.axis["cmc_abduction"], t.axis["cmc"])
    assert np.allclose(theta, ang["cmc"], atol=1e-9) and np.allclose(
        beta, ang["cmc_abduction"], atol=1e-9
    )
    theta, beta = two_axis_angles(q_mcp, t.axis["mcp_abduction"], t.axis["mcp"])
    assert np.allclose(theta, ang["mcp"], atol=1e-9) and np.allclose(
        beta, ang["mcp_abduction"], atol=1e-9
    )
    assert np.allclose(q_ip, axis_angle_matrix(t.axis["ip"], ang["ip"]), atol=1e-12)
    # The lines, not just the directions: the ab/adduction line only turns about the
    # flexion line, so its nearest point keeps the lines' offset from the (parent-fixed)
    # flexion line; the IP line stays put between the phalanges.
    for parent, child, k in (("hand", "metacarpal", "cmc"), ("metacarpal", "proximal", "mcp")):
        rp, tp = seg[parent]
        pb = moved(seg[child], t.axis_point[f"{k}_abduction"])
        local = np.einsum("nji,nj->ni", rp, pb - tp) - t.axis_point[k]
        dist = np.linalg.norm(local - np.outer(local @ t.axis[k], t.axis[k]), axis=1)
        assert np.allclose(dist, t.offset(k), atol=1e-9)
    assert np.allclose(
        moved(seg["proximal"], t.axis_point["ip"]),
        moved(seg["distal"], t.axis_point["ip"]),
        atol=1e-9,
    )


def test_touch_solver_puts_pulp_surfaces_together() -> None:
    rng = np.random.default_rng(11)
    rot, origin = np.eye(3), np.zeros(3)
    side = "left"
    s = -1.0
    thumb = sample_thumb(rng, NOMINAL_HAND_LENGTH, side, hand_rotation=rot, hand_origin=origin)
    index = sample_finger(
        rng, "index", hand=side, hand_scale=1.0, hand_rotation=rot, hand_origin=origin
    )
    pad = sample_pad(rng, "index", index.tip, index.frame)
    ta, fa, err = ct.solve_touch(
        thumb,
        index,
        pad,
        "pad",
        ct._rad(ct.OPPOSITION_THUMB_DEG["index"]),
        ct._rad(ct.OPPOSITION_FINGER_DEG["index"]),
        side=s,
        finger_abduction=True,
        mcp_abduction=True,
    )
    assert abs(err) < 1e-9
    tdist = thumb_segment_motions(thumb, {k: np.array([v]) for k, v in ta.items()}, _EYE)["distal"]
    fdist = segment_motions(index, {k: np.array([v]) for k, v in fa.items()}, _EYE)["distal"]
    gap = np.linalg.norm(moved(tdist, thumb.pad.centre) - moved(fdist, pad.centre))
    assert gap == pytest.approx(thumb.pad.half_thickness + pad.half_thickness, abs=1e-9)
    tips = np.linalg.norm(moved(tdist, thumb.tip) - moved(fdist, index.tip))
    assert 12.0 <= tips <= 18.0
    for k, (lo, hi) in ct.THUMB_LIMITS_DEG.items():
        assert lo - 1e-9 <= np.degrees(ta[k]) <= hi + 1e-9


# ---------------------------------------------------------------- whole-hand sessions

HAND = ("thumb", "index", "middle", "ring", "little")
THUMB_PROTOCOLS = ("thumb_circumduction.csv", "thumb_opposition.csv", "pinch.csv")


def _whole(kind: str):
    from tests.conftest import subject

    return subject(kind, 11 if kind == "exact" else 2, HAND)


def test_exact_sensor_poses_follow_the_true_segment_motions() -> None:
    sim = _whole("exact")
    mounts = sim.truth.mounts
    for rec in sim.session.recordings():
        fr = sim.truth.frames[rec.name]
        for s in ("thumb.metacarpal", "thumb.proximal", "thumb.distal"):
            r, t = fr["motions"][s]
            m = mounts[s]
            pose = rec.poses[s]
            assert np.max(np.abs(pose.position - (r @ m.position + t))) < 1e-9
            assert np.max(np.abs(pose.rotation - r @ m.rotation)) < 1e-9


def test_true_relative_rotations_give_the_true_angles() -> None:
    sim = _whole("exact")
    th = sim.truth.thumb
    mounts = sim.truth.mounts
    chain = {"cmc": ("hand", "thumb.metacarpal"), "mcp": ("thumb.metacarpal", "thumb.proximal")}
    for name in ("grasp.csv", *THUMB_PROTOCOLS, "test.csv"):
        rec = sim.session.recording(name)
        ang = sim.truth.frames[name]["angles"]["thumb"]
        for j, (p, c) in chain.items():
            rel = np.transpose(rec.poses[p].rotation, (0, 2, 1)) @ rec.poses[c].rotation
            q = mounts[p].rotation @ rel @ mounts[c].rotation.T  # tracker frame, reference
            theta, beta = two_axis_angles(q, th.axis[f"{j}_abduction"], th.axis[j])
            assert np.max(np.abs(theta - ang[j])) < 1e-9
            assert np.max(np.abs(beta - ang[f"{j}_abduction"])) < 1e-9


def test_truth_model_drives_the_thumb_exactly() -> None:
    from fingerfit.kinematics import compute_kinematics
    from fingerfit.simulate.truthmodel import truth_model

    sim = _whole("exact")
    model = truth_model(sim)
    assert set(model.fingers["thumb"].second_axes) == {"cmc"}
    for name in THUMB_PROTOCOLS:
        kin = compute_kinematics(model, sim.session.recording(name))
        fr = sim.truth.frames[name]
        motion = kin.motions["user_axis"]["thumb"]
        for k, v in motion.angles.items():
            assert np.max(np.abs(np.degrees(v - fr["angles"]["thumb"][k]))) < 1e-6
        assert np.max(np.linalg.norm(motion.tip - fr["tip"]["thumb"], axis=1)) < 1e-6


def test_pinch_events_touch_pads_with_nail_edges_12_to_18_mm_apart() -> None:
    for kind in ("exact", "realistic"):
        sim = _whole(kind)
        pads = sim.truth.pads
        pinches = [e for e in sim.session.events if e.is_pinch]
        # Opposition to each of the four fingers and three tip pinches.
        assert len(pinches) == 7 and {e.target for e in pinches} == set(HAND[1:])
        for ev in pinches:
            fr = sim.truth.frames[ev.recording]
            sel = (fr["time"] >= ev.start) & (fr["time"] <= ev.end)
            assert sel.sum() > 100
            gap = np.linalg.norm(fr["pad"]["thumb"][sel] - fr["pad"][ev.target][sel], axis=1)
            want = pads["thumb"].half_thickness + pads[ev.target].half_thickness
            assert np.max(np.abs(gap - want)) < 0.1
            tips = np.linalg.norm(fr["tip"]["thumb"][sel] - fr["tip"][ev.target][sel], axis=1)
            assert np.all((tips >= 12.0) & (tips <= 18.0))
        # Key pinches stay out of events.csv but are in the truth: the thumb pulp on the
        # index's side.
        keys = [c for c in sim.truth.contacts if c["kind"] == "key_pinch"]
        assert len(keys) == 3 and not any(c["in_events_csv"] for c in keys)
        for c in keys:
            assert (
                c["distance_max_mm"] - c["gap_mm"] < 0.1
                and c["gap_mm"] - c["distance_min_mm"] < 0.1
            )


def test_thumb_protocols_excite_both_cmc_axes() -> None:
    sim = _whole("realistic")
    for k in ("cmc", "cmc_abduction"):
        values = np.concatenate(
            [sim.truth.frames[n]["angles"]["thumb"][k] for n in THUMB_PROTOCOLS]
        )
        assert np.degrees(np.ptp(values)) >= 20.0
        circ = sim.truth.frames["thumb_circumduction.csv"]["angles"]["thumb"][k]
        assert np.degrees(np.ptp(circ)) >= 20.0
    # Every digit moves in the opposition recording.
    opp = sim.truth.frames["thumb_opposition.csv"]["angles"]
    for d in HAND:
        assert max(np.degrees(np.ptp(v)) for v in opp[d].values()) > 15.0


def test_the_thumb_leaves_the_fingers_truth_unchanged() -> None:
    from fingerfit.simulate import SimConfig, simulate_subject

    with_thumb = simulate_subject(SimConfig(fingers=("thumb", "index"), targets=False), 5)
    without = simulate_subject(SimConfig(fingers=("index",), targets=False), 5)
    for name in ("reference.csv", "grasp.csv", "test.csv"):
        a, b = with_thumb.truth.frames[name], without.truth.frames[name]
        assert np.array_equal(a["tip"]["index"], b["tip"]["index"])
        for s, pose in without.session.recording(name).poses.items():
            assert np.array_equal(
                with_thumb.session.recording(name).poses[s].position, pose.position
            )
    for k, v in without.session.landmarks.items():
        assert np.array_equal(with_thumb.session.landmarks[k], v)
    assert without.session.fingers == ["index"] and with_thumb.session.fingers == ["thumb", "index"]


def test_written_whole_hand_session_and_truth(tmp_path) -> None:
    import json

    import pandas as pd

    from fingerfit.io.sessiondir import load_session
    from fingerfit.simulate import write_subject

    sim = _whole("realistic")
    write_subject(sim, tmp_path / "S01")
    back = load_session(tmp_path / "S01")
    assert back.fingers == list(HAND)
    assert [r.name for r in back.grasp] == ["grasp.csv", *THUMB_PROTOCOLS]
    pinch_rows = [(e.recording, e.finger, e.target) for e in back.events if e.is_pinch]
    assert pinch_rows[0] == ("thumb_opposition.csv", "thumb", "index")
    for lm in ("cmc", "mcp", "ip", "tip", "pad"):
        assert f"thumb.{lm}" in back.landmarks
    doc = json.loads((tmp_path / "S01" / "truth.json").read_text())
    thumb = doc["fingers"]["thumb"]
    assert set(thumb["joints"]) == {"cmc", "cmc_abduction", "mcp", "mcp_abduction", "ip"}
    assert thumb["axis_order"]["cmc"] == ["cmc", "cmc_abduction"]
    assert thumb["axis_offset_mm"]["cmc"] == pytest.approx(sim.truth.thumb.offset("cmc"))
    assert np.allclose(thumb["pad"], sim.truth.pads["thumb"].surface)
    table = pd.read_csv(tmp_path / "S01" / "truth" / "pinch.csv")
    for col in (
        "thumb.cmc",
        "thumb.cmc_abduction",
        "thumb.mcp_abduction",
        "thumb.pad.z",
        "thumb.pad_distance.index",
    ):
        assert col in table.columns
    fr = sim.truth.frames["pinch.csv"]
    assert np.allclose(
        table["thumb.cmc_abduction"], np.degrees(fr["angles"]["thumb"]["cmc_abduction"])
    )
    # The skin pad point moves with the distal phalanx, the half-thickness from the centre.
    skin = table[["thumb.pad.x", "thumb.pad.y", "thumb.pad.z"]].to_numpy()
    d = np.linalg.norm(skin - fr["pad"]["thumb"], axis=1)
    assert np.allclose(d, sim.truth.pads["thumb"].half_thickness)


def test_whole_hand_fits_a_liberty_and_names_thumb_channels() -> None:
    from fingerfit.session import sensor_name
    from fingerfit.simulate.trackerfiles import c3d_label, station_map

    sensors = ["hand"] + [
        sensor_name(d, s)
        for d in reversed(HAND)
        for s in (
            ("metacarpal", "proximal", "distal")
            if d == "thumb"
            else ("proximal", "middle", "distal")
        )
    ]
    stations = station_map(sensors)
    assert len(stations) == 16
    assert [stations[i] for i in (1, 2, 3, 4, 5)] == [
        "hand",
        "thumb.metacarpal",
        "thumb.proximal",
        "thumb.distal",
        "index.proximal",
    ]
    assert c3d_label("thumb.metacarpal") == "THUMB_MC" and c3d_label("thumb.distal") == "THUMB_DIST"
