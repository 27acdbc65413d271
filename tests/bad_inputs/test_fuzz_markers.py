"""Property-based fuzzing of the marker readers (TRC, Qualisys TSV) and the marker map:
mutated files are read with their invariants intact or refused in one line naming the
file (the rules of ``test_fuzz_readers.py``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fingerfit.io.markers import read_marker_recording
from fingerfit.io.markers.markermap import read_marker_map
from fingerfit.io.opensim import write_markers
from fingerfit.session import Recording

from .test_fuzz_readers import FUZZ, check_recording, mutate_text, outcome

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "dfki-hand-embodiment"


def check_markers(rec: Recording) -> None:
    """Invariants of a marker recording: time-first, each sample complete or all NaN,
    finite coordinates within 1000 km."""
    check_recording(rec)
    assert rec.poses == {}
    for p in rec.markers.values():
        assert p.shape == (rec.n_frames, 3)
        ok = np.isfinite(p).all(axis=1)
        assert np.isnan(p[~ok]).all()
        assert (np.abs(p[ok]) <= 1e9).all()


@pytest.fixture(scope="module")
def small_tsv(tmp_path_factory) -> Path:
    """The first 60 frames of the dfki excerpt (QTM TSV, 13 markers, gaps included)."""
    lines = (EXCERPT / "excerpt.tsv").read_bytes().split(b"\r\n")
    lines[0] = b"NO_OF_FRAMES\t60"
    out = tmp_path_factory.mktemp("tsv") / "small.tsv"
    out.write_bytes(b"\r\n".join(lines[:72]) + b"\r\n")
    return out


@pytest.fixture(scope="module")
def small_trc(tmp_path_factory, small_tsv) -> Path:
    rec = read_marker_recording(small_tsv)
    return write_markers(tmp_path_factory.mktemp("trc") / "small.trc", rec, units="mm")


def test_fuzz_marker_inputs_are_valid(small_tsv, small_trc) -> None:
    for path in (small_tsv, small_trc):
        rec = read_marker_recording(path)
        check_markers(rec)
        assert rec.n_frames == 60 and len(rec.markers) == 13
    assert len(read_marker_map(EXCERPT / "markers.toml")) == 11


@settings(FUZZ, max_examples=120)
@given(data=st.data(), kind=st.sampled_from(["tsv", "trc"]))
def test_fuzz_marker_recordings(tmp_path, small_tsv, small_trc, data, kind) -> None:
    base = (small_tsv if kind == "tsv" else small_trc).read_bytes()
    path = tmp_path / f"m.{kind}"
    path.write_bytes(mutate_text(data.draw, base, sep=b"\t"))
    rec = outcome(lambda: read_marker_recording(path), path)
    if rec is not None:
        check_markers(rec)


@settings(FUZZ, max_examples=80)
@given(data=st.data())
def test_fuzz_marker_map(tmp_path, data) -> None:
    path = tmp_path / "map.toml"
    base = (EXCERPT / "markers.toml").read_bytes()
    path.write_bytes(mutate_text(data.draw, base, sep=b" "))
    got = outcome(lambda: read_marker_map(path), path)
    if got is not None:
        assert len(got["hand"]) >= 3
        labels = [lb for v in got.values() for lb in v]
        assert len(labels) == len(set(labels)) and all(isinstance(x, str) for x in labels)
