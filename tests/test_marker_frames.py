"""Each frame of a marker recording solved on its own (``estimate/markers/frames.py``): the
same angles whether a frame is solved alone, in a block or in the whole recording, deep
flexion included, every frame converged, and an unconverged frame reported."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.estimate.markers import frames
from fingerfit.estimate.markers.angles import marker_angles
from fingerfit.io.markers import read_marker_recording
from fingerfit.model import load_model

from .test_live_markers import marker_subject

#: Deep flexion in the test recording of :func:`marker_subject` (PIP 70-89 deg): these
#: frames stopped unconverged when all frames shared one damping and one stopping rule.
DEEP = slice(3240, 3580)


@pytest.fixture(scope="module")
def solved():
    d, model_path = marker_subject()
    model = load_model(model_path)
    rec = read_marker_recording(d / "test.trc")
    return model, rec, marker_angles(model, rec)["index"]


def test_deep_flexion_is_in_the_recording(solved):
    """The recording reaches the deep flexion the tests below need."""
    _, _, whole = solved
    pip = np.degrees(whole.angles[DEEP, whole.names.index("pip")])
    assert np.nanmax(pip) > 70.0


def test_every_frame_converges(solved):
    _, rec, whole = solved
    assert whole.unconverged == 0
    assert np.isfinite(whole.angles).all() and whole.angles.shape == (rec.n_frames, 3)


@pytest.mark.parametrize("size", [1, 7, 37, 500])
def test_a_frame_is_the_same_alone_in_a_block_or_in_the_whole(solved, size):
    """Blocks of ``size`` frames give the whole recording's angles and tips to rounding:
    single frames every 7th of the deep flexion and every 199th elsewhere, blocks of 7
    and 37 over the deep flexion, blocks of 500 over the whole recording."""
    model, rec, whole = solved
    if size == 1:
        starts = [*range(DEEP.start, DEEP.stop, 7), *range(0, rec.n_frames, 199)]
    elif size < 500:
        starts = list(range(DEEP.start - 3, DEEP.stop, size))
    else:
        starts = list(range(0, rec.n_frames, size))
    for i in starts:
        part = rec.slice(slice(i, min(i + size, rec.n_frames)))
        got = marker_angles(model, part)["index"]
        np.testing.assert_allclose(got.angles, whole.angles[i : i + size], atol=1e-6, rtol=0)
        np.testing.assert_allclose(got.tip, whole.tip[i : i + size], atol=1e-4, rtol=0)


def test_an_unconverged_frame_is_counted_and_said(solved, tmp_path, monkeypatch):
    """With too few steps allowed the deep-flexion frames stop unconverged: counted in
    ``DigitAngles.unconverged`` and said by ``fingerfit angles``."""
    model, rec, _ = solved
    monkeypatch.setattr(frames, "MAX_STEPS", 3)
    part = rec.slice(DEEP)
    got = marker_angles(model, part)["index"]
    assert 0 < got.unconverged <= part.n_frames
    d, model_path = marker_subject()
    res = CliRunner().invoke(
        app, ["angles", str(model_path), str(d / "test.trc"), "-o", str(tmp_path / "a.csv")]
    )
    assert res.exit_code == 0, res.output
    assert "frames unconverged" in res.output
