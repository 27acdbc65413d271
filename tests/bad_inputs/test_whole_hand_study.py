"""``fingerfit study`` with a truth file that does not match its recording: refused in one
line naming the file (the truth is compared frame by frame), nothing written."""

from __future__ import annotations

import shutil

from fingerfit.simulate import write_subject

from ..conftest import subject
from ._cli import listing, refused, run


def test_truth_rows_must_match_the_recording(tmp_path) -> None:
    src = write_subject(subject("realistic", 2), tmp_path / "src" / "P01")
    copy = shutil.copytree(src, tmp_path / "P01")
    truth = copy / "truth" / "test.csv"
    lines = truth.read_text().splitlines(keepends=True)
    truth.write_text("".join(lines[:-5]))  # five frames short
    before = listing(tmp_path)
    refused(
        run("study", copy, "--out", tmp_path / "out"),
        str(truth),
        f"has {len(lines) - 6} rows but the recording 'test.csv' has {len(lines) - 1} frames",
    )
    assert listing(tmp_path) == before
    assert not (tmp_path / "out").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]
