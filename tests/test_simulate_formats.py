"""``fingerfit simulate --format``: tracker files without hardware, and the real-data round trip.

For each tracker format the subject is simulated through the CLI, the printed
``fingerfit convert`` / ``session`` / ``fit`` commands are run exactly as printed, and the
fitted model is compared with the one fitted from the CSV session of the same seed.

``bench/simulate_round_trip.py [N_SUBJECTS]`` prints the largest differences per format,
method and joint over N subjects (the table in ``docs/simulator.md``); both use
``tests/_round_trip.py``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.io import load_session
from fingerfit.io.liberty import parse_liberty_ascii, parse_liberty_binary
from fingerfit.model import HandModel
from fingerfit.simulate.trackerfiles import (
    LIBERTY_ITEM_CODES,
    c3d_label,
    station_map,
)

from ._round_trip import FORMATS, METHODS, model_differences, printed_commands, simulate_and_fit
from .bad_inputs._cli import listing, run

#: Tight tolerances of the round trip (every format): axis deg, centre mm, length mm.
AXIS_DEG, CENTRE_MM, LENGTH_MM = 0.2, 0.2, 0.2
_EXT = {"liberty-ascii": "txt", "liberty-binary": "bin", "c3d": "c3d"}


def _needs(fmt: str) -> None:
    if fmt == "c3d":
        pytest.importorskip("ezc3d", reason="the c3d extra (ezc3d) is not installed")


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("formats")


@pytest.fixture(scope="module")
def csv_models(work: Path) -> dict[str, list[HandModel]]:
    return simulate_and_fit(work, "csv")


_cache: dict[str, dict[str, list[HandModel]]] = {}


def tracker_models(work: Path, fmt: str) -> dict[str, list[HandModel]]:
    if fmt not in _cache:
        _cache[fmt] = simulate_and_fit(work, fmt)
    return _cache[fmt]


# ------------------------------------------------------------------ file layout and units


def test_station_map_and_channel_labels() -> None:
    sensors = ["middle.distal", "index.middle", "hand", "middle.proximal", "index.proximal"]
    sensors += ["index.distal", "middle.middle"]
    assert station_map(sensors) == {
        1: "hand",
        2: "index.proximal",
        3: "index.middle",
        4: "index.distal",
        5: "middle.proximal",
        6: "middle.middle",
        7: "middle.distal",
    }
    assert [c3d_label(s) for s in ("hand", "index.proximal", "little.distal")] == [
        "HAND",
        "INDEX_PROX",
        "LITTLE_DIST",
    ]
    with pytest.raises(FingerfitError, match="at most 16 stations"):
        station_map(["hand"] + [f"s{i}" for i in range(16)])


def test_liberty_ascii_layout_units_and_precision(work: Path, csv_models) -> None:
    tracker_models(work, "liberty-ascii")
    truth = load_session(work / "csv" / "S01")
    path = work / "liberty-ascii" / "S01" / "grasp.txt"
    raw = path.read_bytes()
    lines = raw.split(b"\r\n")
    assert lines[-1] == b"" and b"\n" not in raw.replace(b"\r\n", b"")  # CR/LF records
    # station, position x3 (3 decimals), quaternion x4 (4 decimals), frame count
    pat = re.compile(rb"^0[1-4]  ?-?\d+\.\d{3}( -?\d+\.\d{3}){2}( -?\d\.\d{4}){4} \d+$")
    assert all(pat.match(ln) for ln in lines[:-1]), lines[:4]
    recs = parse_liberty_ascii(path, LIBERTY_ITEM_CODES)
    stations = station_map(truth.grasp[0].sensors)
    rec = truth.grasp[0]
    n = rec.n_frames
    assert recs.n_records == 4 * n
    np.testing.assert_array_equal(recs.station, np.tile(list(stations), n))
    np.testing.assert_array_equal(recs.values["frame"], np.repeat(np.arange(n), 4))
    pos_mm = np.stack([rec.poses[s].position for s in stations.values()], axis=1).reshape(-1, 3)
    # inches, rounded to 0.001 in
    err = np.abs(recs.values["position"] - pos_mm / 25.4)
    assert err.max() <= 0.0005 + 1e-9
    assert err.max() > 1e-5  # really rounded, so really inches at 3 decimals
    # quaternion w,x,y,z at 4 decimals: rotation matches the session's to ~0.02 deg
    from fingerfit.transforms import matrix_from_quat_wxyz

    rot = np.stack([rec.poses[s].rotation for s in stations.values()], axis=1).reshape(-1, 3, 3)
    got = matrix_from_quat_wxyz(recs.values["quaternion"])
    cos = (np.einsum("nij,nij->n", got, rot) - 1) / 2
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.03


def test_liberty_binary_records(work: Path, csv_models) -> None:
    tracker_models(work, "liberty-binary")
    truth = load_session(work / "csv" / "S01")
    path = work / "liberty-binary" / "S01" / "reference.bin"
    raw = path.read_bytes()
    size = 8 + 4 * (3 + 4) + 4  # header, float32 position + quaternion, uint32 frame count
    n = truth.reference.n_frames
    assert len(raw) == 4 * n * size
    assert raw[:2] == b"LY" and raw[2] == 1 and int.from_bytes(raw[6:8], "little") == size - 8
    recs = parse_liberty_binary(path, LIBERTY_ITEM_CODES)
    pos_mm = np.stack(
        [truth.reference.poses[s].position for s in station_map(truth.reference.sensors).values()],
        axis=1,
    ).reshape(-1, 3)
    np.testing.assert_allclose(recs.values["position"] * 25.4, pos_mm, atol=1e-4)  # float32


def test_c3d_rotation_channels(work: Path, csv_models) -> None:
    _needs("c3d")
    import ezc3d

    tracker_models(work, "c3d")
    truth = load_session(work / "csv" / "S01")
    c = ezc3d.c3d(str(work / "c3d" / "S01" / "test.c3d"))
    sensors = list(station_map(truth.test[0].sensors).values())
    labels = [c3d_label(s) for s in sensors]
    assert list(c["parameters"]["ROTATION"]["LABELS"]["value"]) == labels
    assert c["parameters"]["POINT"]["UNITS"]["value"] == ["mm"]
    assert c["parameters"]["POINT"]["RATE"]["value"][0] == 240.0
    m = np.transpose(c["data"]["rotations"], (2, 3, 0, 1))  # (channel, frame, 4, 4)
    for k, s in enumerate(sensors):
        np.testing.assert_allclose(m[k, :, :3, 3], truth.test[0].poses[s].position, atol=1e-3)
        np.testing.assert_allclose(m[k, :, :3, :3], truth.test[0].poses[s].rotation, atol=1e-6)


# ------------------------------------------------------------------ round trip


@pytest.mark.parametrize("fmt", FORMATS)
def test_printed_commands_give_the_same_session(work: Path, csv_models, fmt: str) -> None:
    """Same frames, times, sensors, landmarks and events as the CSV session, within precision."""
    _needs(fmt)
    tracker_models(work, fmt)
    a = load_session(work / "csv" / "S01")
    b = load_session(work / fmt / "S01" / "session")
    assert b.landmarks.keys() == a.landmarks.keys()
    assert b.events == a.events
    pos_tol = {"liberty-ascii": 0.0127 + 1e-6, "liberty-binary": 1e-4, "c3d": 1e-4}[fmt]
    for ra, rb in zip(a.recordings(), b.recordings(), strict=True):
        assert ra.name == rb.name
        np.testing.assert_allclose(rb.time, ra.time, atol=1e-9)
        assert rb.sensors == ra.sensors
        for s in ra.sensors:
            np.testing.assert_allclose(rb.poses[s].position, ra.poses[s].position, atol=pos_tol)
    # the simulation wrote its files inside its output folder only, nothing half done
    assert not [p for p in (work / fmt).rglob("*") if ".part" in p.name]


def _assert_close(diff: dict[str, float], what: str) -> None:
    assert diff["axis_deg"] <= AXIS_DEG, f"{what}: axis {diff['axis_deg']:.3f} deg"
    assert diff["centre_mm"] <= CENTRE_MM, f"{what}: centre {diff['centre_mm']:.3f} mm"
    assert diff["length_mm"] <= LENGTH_MM, f"{what}: segment {diff['length_mm']:.3f} mm"


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("method", METHODS)
def test_round_trip_pip_dip(work: Path, csv_models, fmt: str, method: str) -> None:
    _needs(fmt)
    got = tracker_models(work, fmt)[method][0]
    diff = model_differences(csv_models[method][0], got)
    for j in ("pip", "dip"):
        _assert_close(diff[j], f"{fmt} {method} {j}")


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_mp_single_axis(work: Path, csv_models, fmt: str) -> None:
    _needs(fmt)
    diff = model_differences(csv_models["robust"][0], tracker_models(work, fmt)["robust"][0])
    _assert_close(diff["mp"], f"{fmt} robust mp")


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_mp_two_axis(work: Path, csv_models, fmt: str) -> None:
    _needs(fmt)
    diff = model_differences(csv_models["twoaxis"][0], tracker_models(work, fmt)["twoaxis"][0])
    _assert_close(diff["mp"], f"{fmt} twoaxis mp")
    _assert_close(diff["mp_abduction"], f"{fmt} twoaxis mp_abduction")


def test_nothing_outside_the_output_folder(tmp_path: Path) -> None:
    (tmp_path / "keep.txt").write_text("x")
    before = listing(tmp_path)
    res = run("simulate", "out", "--subjects", 1, "--seed", 1, "--format", "liberty-ascii",
              cwd=tmp_path)  # fmt: skip
    assert res.exit_code == 0, res.output
    after = listing(tmp_path)
    new = sorted(set(after) - set(before))
    assert all(Path(p).is_relative_to(tmp_path / "out") for p in new)
    assert {k: v for k, v in after.items() if k in before} == before
    names = {Path(p).relative_to(tmp_path / "out").as_posix() for p in new}
    assert {"commands.sh", "S01/grasp.txt", "S01/landmarks.csv", "S01/events.csv"} <= names
    assert not [n for n in names if ".part" in n or "/." in n]
    script = (tmp_path / "out" / "commands.sh").read_text().splitlines()
    assert script[2:] == printed_commands(res.output)
    # a second run refuses to replace the subject folder, and changes nothing
    again = run("simulate", "out", "--subjects", 1, "--seed", 2, "--format", "c3d", cwd=tmp_path)
    assert again.exit_code == 2 and "pass --overwrite" in again.output
    assert listing(tmp_path) == after
