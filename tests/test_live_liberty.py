"""`fingerfit stream --source liberty:PORT` against a Liberty emulated on a pseudo-terminal.

The emulator answers the set-up commands (output list, units, binary format) the way the
device does, so a missing or wrong command gives wrong numbers here; it streams 240 Hz
binary records and injects garbage (with a fake header in it), dropped bytes and an unplug.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from fingerfit.io.liberty import liberty_binary_bytes, parse_liberty_binary, records_to_recording
from fingerfit.live.liberty_serial import ITEMS, RECORD, parse_records
from fingerfit.live.stream import model_sensors
from fingerfit.model import load_model

from ._live import angles_of, fitted, short_recording, stream_counts, until
from .bad_inputs._cli import refused, run
from .liberty_emulator import Faults, LibertyEmulator

pytest.importorskip("serial")

N = 240  # one second at 240 Hz


def _expected(emu: LibertyEmulator, model, n: int) -> pd.DataFrame:
    """`fingerfit angles` of the frames the emulator sent, read back by the file reader."""
    data = b"".join(
        liberty_binary_bytes(emu.records(i, ITEMS, "cm"), family="LY") for i in range(n)
    )
    recs = parse_liberty_binary("emulated.bin", ITEMS, data=data)
    rec = records_to_recording(
        recs, "emulated.bin", units="cm", rate_hz=240.0, sensors=emu.stations
    )
    return angles_of(model, rec)[0]


def test_liberty_stream_resynchronises_and_ends_on_unplug(tmp_path) -> None:
    _, model_path = fitted()
    model = load_model(model_path)
    stations = {i + 1: s for i, s in enumerate(model_sensors(model))}
    rec = short_recording(N + 10)
    faults = Faults(
        garbage={30: b"\x00\xffLY\x01C\x00\x00\x20\x00junk", 60: b"\r\n\xfe" * 7},
        drop={100: (2, 20), 150: (len(stations) - 1, RECORD.itemsize - 1), 200: (0, 0)},
        unplug_after=N,
    )
    emu = LibertyEmulator(rec, stations, faults)
    out = tmp_path / "live.csv"
    try:
        res = run(
            "stream", model_path, "--source", f"liberty:{emu.port}", "--record", out,
            "--reconnect", "0.5", "-q",
        )  # fmt: skip
    finally:
        emu.close()
    line = refused(res, emu.port, "device disconnected", "not back within 0.5 s", "kept")
    assert "Traceback" not in res.output
    # One warning for the outage, then the port was tried again for 0.5 s.
    assert res.output.count("reopening the port (up to 0.5 s)") == 1
    # The set-up the docs list, in order, before any data.
    assert emu.commands[:5] == [b"P", b"O*,2,7,9", b"U1", b"F1", b"C"]
    frames = int(re.search(r"after (\d+) frames", line).group(1))
    got = pd.read_csv(out)
    assert frames == len(got) == N  # no frame lost: faults cost only the damaged records
    want = _expected(emu, model, N)
    assert list(got.columns) == list(want.columns)
    np.testing.assert_allclose(got["time"], np.arange(N) / 240.0, rtol=0, atol=1e-12)
    damaged = {100, 150, 200}
    keep = [i for i in range(N) if i not in damaged]
    cols = [c for c in want.columns if c != "time"]
    np.testing.assert_allclose(
        got.loc[keep, cols].to_numpy(), want.loc[keep, cols].to_numpy(), rtol=0, atol=1e-9
    )
    # A damaged record's sensor is missing in that frame only: the model solves frames 100
    # and 150 (index.proximal, index.distal missing), nothing can solve 200 (no hand).
    for i in (100, 150):
        assert np.isfinite(got.loc[i, cols].to_numpy(float)).all()
    # Without the hand: the MP and the tips are empty, PIP and DIP (their sensors there)
    # computed directly.
    assert got.loc[200, ["index.mp", "index.tip.x", "index.ik_rms_mm"]].isna().all()
    assert np.isfinite(got.loc[200, ["index.pip", "index.dip"]].to_numpy(float)).all()
    assert not np.isfinite(want.loc[keep, "index.ik_rms_mm"]).any()


def test_liberty_stream_stops_cleanly_after_duration(tmp_path) -> None:
    _, model_path = fitted()
    stations = {i + 1: s for i, s in enumerate(model_sensors(load_model(model_path)))}
    emu = LibertyEmulator(short_recording(2 * N), stations)
    try:
        res = run(
            "stream",
            model_path,
            "--source",
            f"liberty:{emu.port}@115200",
            "--duration",
            "0.3",
            "--record",
            tmp_path / "a.csv",
            "-q",
        )
        assert res.exit_code == 0, res.output
        until(lambda: emu.commands[-1:] == [b"P"])  # the stop reaches the emulator's reader
    finally:
        emu.close()
    assert emu.commands[-1] == b"P" and not emu.continuous
    # It streamed for its --duration (from the first frame), however many frames a loaded
    # machine handed over meanwhile, and every frame received is in the file.
    seconds = float(re.search(r"frames received in ([0-9.]+) s", res.output).group(1))
    assert seconds >= 0.3
    got = pd.read_csv(tmp_path / "a.csv")
    assert 0 < len(got) == stream_counts(res.output)["recorded"] < 2 * N
    angles = got[[c for c in got.columns if "ik_rms" not in c]]
    assert np.isfinite(angles.to_numpy()).all()
    assert got["index.ik_rms_mm"].isna().all()  # every frame computed from its sensors


def test_parser_resynchronises_after_every_kind_of_damage() -> None:
    """Unit test of the framing: garbage, a lost byte anywhere in a record, a bad header."""
    rng = np.random.default_rng(0)
    stations = np.array([1, 2, 3])
    recs = np.zeros(30, RECORD)
    recs["magic"] = b"LY"
    recs["station"] = np.tile(stations, 10)
    recs["command"] = ord("C")
    recs["size"] = RECORD.itemsize - 8
    recs["position"] = rng.normal(0, 20, (30, 3))
    q = rng.normal(size=(30, 4))
    recs["quaternion"] = q / np.linalg.norm(q, axis=1, keepdims=True)
    recs["frame"] = 100 + np.repeat(np.arange(10), 3)
    size = RECORD.itemsize
    for off in range(size):  # drop byte `off` of record 7: only record 7 is lost
        raw = bytearray(recs.tobytes())
        del raw[7 * size + off]
        raw[0:0] = b"garbage LY\x00"
        got = parse_records(raw, stations)
        assert got.consumed == len(raw)
        assert got.station.size == 29, off
        np.testing.assert_array_equal(got.frame, np.delete(recs["frame"], 7))
        np.testing.assert_allclose(
            got.position, np.delete(recs["position"], 7, axis=0).astype(float)
        )
    # An incomplete last record stays in the buffer for the next read.
    raw = recs.tobytes()
    got = parse_records(raw[: 5 * size + 10], stations)
    assert got.station.size == 5 and got.consumed == 5 * size
