"""``fingerfit study`` on awkward studies: one subject, mixed sessions, failing sessions,
unusable output folders, bad or repeated subject IDs, forced fits.

Item 5 and the study part of item 10 of the trust issue. Sessions reuse the cached
simulated subjects of ``tests/conftest.py``:

* ``P01`` -- realistic subject 2: grasp, targets, test recording, ground truth;
* ``P02`` -- exact subject 11 with only reference and grasp (no targets, no truth);
* ``P07`` -- P02 whose grasp recording is the static reference: cannot be fitted;
* ``P09`` -- an exact subject whose joints barely move: fitted only with ``--force``.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import pandas as pd
import pytest

from fingerfit.io.sessiondir import save_session
from fingerfit.simulate import SimConfig, simulate_subject, write_subject

from ..conftest import subject
from ._cli import listing, refused, run


def _set_subject(folder: Path, subject_id: str) -> Path:
    toml = folder / "session.toml"
    text = re.sub(r'(?m)^subject = ".*"$', f"subject = {json.dumps(subject_id)}", toml.read_text())
    toml.write_text(text)
    return folder


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("sessions")
    p01 = _set_subject(write_subject(subject("realistic", 2), root / "P01"), "P01")
    exact = subject("exact", 11).session
    bare = dataclasses.replace(exact, subject="P02", targets=[], test=[], events=[], path=None)
    p02 = save_session(bare, root / "P02")
    static = dataclasses.replace(exact.reference, name="grasp.csv")
    p07 = save_session(dataclasses.replace(bare, subject="P07", grasp=[static]), root / "P07")
    small = simulate_subject(SimConfig.exact(rom_scale=0.07, targets=False, test=False), 11, "P09")
    p09 = save_session(small.session, root / "P09")
    return {"P01": p01, "P02": p02, "P07": p07, "P09": p09}


def _summary(out: Path) -> dict:
    def no_nan(value: str):
        raise AssertionError(f"summary.json holds {value}")

    return json.loads((out / "summary.json").read_text(), parse_constant=no_nan)


def _no_leftovers(parent: Path, before: dict) -> None:
    """Nothing new below ``parent`` (no staging folder, no partial output)."""
    assert listing(parent) == before
    assert not [p for p in parent.iterdir() if p.name.startswith(".")], list(parent.iterdir())


def test_one_subject_study(sessions, tmp_path) -> None:
    out = tmp_path / "one"
    res = run("study", sessions["P01"], "--out", out, "--method", "tang2018")
    assert res.exit_code == 0, res.output
    sm = _summary(out)
    skipped = {d["statistic"]: d["reason"] for d in sm["skipped"]}
    assert (
        skipped["max_flexion.anova_model_x_subject"] == "needs at least 2 levels of subject, has 1"
    )
    assert skipped["targets.anova_model_x_subject"] == "needs at least 2 levels of subject, has 1"
    # One touch per target and model: no replicate in any model x target cell.
    assert "no repeated observations" in skipped["targets.anova_model_x_target"]
    assert sm["max_flexion"]["anova_model_x_subject"] == {
        "skipped": "needs at least 2 levels of subject, has 1"
    }
    # What one subject does support is computed: 10 cycles, 7 targets.
    assert sm["max_flexion"]["paired_t_test"]["df"] == 9
    assert sm["targets"]["paired_t_test"]["df"] == 6
    targets = pd.read_csv(out / "targets.csv")
    user = targets.loc[targets.source == "user_axis", "error_mm"]
    assert sm["targets"]["user_axis"]["mean_mm"] == pytest.approx(user.mean())
    report = (out / "report.html").read_text()
    assert "fingerfit study — 1 subject<" in report
    assert "Statistics not computed" in report
    assert "maximal flexion: ANOVA model × subject: needs at least 2 levels of subject" in report
    assert "p 0.000" not in report and "p = 0.000" not in report


def test_mixed_two_subject_study(sessions, tmp_path) -> None:
    """With and without targets, test recordings and truth: each part uses the sessions that
    have it; the exact subject's user-axis error at maximal flexion is zero."""
    out = tmp_path / "mixed"
    res = run("study", sessions["P01"], sessions["P02"], "--out", out, "--method", "tang2018")
    assert res.exit_code == 0, res.output
    sm = _summary(out)
    assert sm["subjects"] == ["P01", "P02"]
    assert sm["targets"]["subjects"] == ["P01"]
    assert sm["truth"]["subjects"] == ["P01"]
    assert sm["sessions"]["P02"] == {
        "path": str(sessions["P02"]),
        "fingers": ["index"],
        "has_targets": False,
        "has_truth": False,
    }
    per = sm["max_flexion"]["per_subject"]
    assert per["P02"]["user_axis_mean_mm"] < 1e-6 < per["P02"]["orthogonal_mean_mm"]
    assert per["P01"]["n"] == per["P02"]["n"] == 10
    anova = sm["max_flexion"]["anova_model_x_subject"]
    assert anova["Residual"]["df"] == 4 * 10 - 4  # 2 models x 2 subjects x 10 cycles
    flex = pd.read_csv(out / "max_flexion.csv")
    assert len(flex) == 20 and sm["max_flexion"]["user_axis"]["mean_mm"] == pytest.approx(
        flex.user_axis.mean()
    )
    report = (out / "report.html").read_text()
    assert "Subjects without target recordings (not included): P02." in report
    assert sorted(p.name for p in (out / "models").iterdir()) == ["P01.json", "P02.json"]


def test_failing_session_is_named_and_nothing_is_left(sessions, tmp_path) -> None:
    before = listing(tmp_path)
    out = tmp_path / "out"
    line = refused(
        run("study", sessions["P01"], sessions["P07"], "--out", out),
        "P07: index mp: only 0 grasp cycle(s) found",
    )
    assert line.startswith("error: P07: ")
    assert not out.exists()
    _no_leftovers(tmp_path, before)


def test_keep_going_fits_what_it_can(sessions, tmp_path) -> None:
    out = tmp_path / "out"
    res = run("study", sessions["P07"], sessions["P01"], "--out", out, "--keep-going")
    assert res.exit_code == 0, res.output
    assert "warning: skipped P07: index mp: only 0 grasp cycle(s) found" in res.output
    sm = _summary(out)
    assert sm["subjects"] == ["P01"]
    assert sm["failed"] == [
        {
            "session": str(sessions["P07"]),
            "subject": "P07",
            "error": "P07: index mp: only 0 grasp cycle(s) found (need 3)",
        }
    ]
    report = (out / "report.html").read_text()
    assert "Sessions that failed" in report and "P07: index mp: only 0 grasp" in report
    assert sorted(p.name for p in (out / "models").iterdir()) == ["P01.json"]


def test_keep_going_with_no_success_is_an_error(sessions, tmp_path) -> None:
    before = listing(tmp_path)
    refused(
        run("study", sessions["P07"], tmp_path / "nosuch", "--out", tmp_path / "o", "--keep-going"),
        "no session could be fitted and evaluated",
        "P07: index mp",
        "nosuch",
    )
    _no_leftovers(tmp_path, before)


def test_out_is_an_existing_file(sessions, tmp_path) -> None:
    target = tmp_path / "results.txt"
    target.write_text("mine\n")
    before = listing(tmp_path)
    refused(run("study", sessions["P02"], "--out", target), str(target), "not a folder")
    _no_leftovers(tmp_path, before)


def test_out_not_empty_needs_overwrite(sessions, tmp_path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "old.txt").write_text("old\n")
    before = listing(tmp_path)
    refused(run("study", sessions["P02"], "--out", out), str(out), "--overwrite")
    _no_leftovers(tmp_path, before)
    res = run("study", sessions["P02"], "--out", out, "--overwrite")
    assert res.exit_code == 0, res.output
    assert not (out / "old.txt").exists() and (out / "report.html").is_file()
    assert [p.name for p in tmp_path.iterdir()] == ["out"]


def test_out_must_not_replace_an_input_session(sessions, tmp_path) -> None:
    src = shutil.copytree(sessions["P02"], tmp_path / "P02")
    before = listing(tmp_path)
    refused(
        run("study", src, "--out", src, "--overwrite"), "would replace the input session", str(src)
    )
    refused(run("study", src, "--out", tmp_path, "--overwrite"), "would replace the input session")
    _no_leftovers(tmp_path, before)


def test_keep_going_overwrite_never_replaces_a_failed_or_unreadable_session(
    sessions, tmp_path
) -> None:
    failing = shutil.copytree(sessions["P07"], tmp_path / "P07")  # fits no grasp cycle
    unreadable = tmp_path / "broken"
    unreadable.mkdir()
    (unreadable / "notes.txt").write_text("not a session")
    before = listing(tmp_path)
    for victim in (failing, unreadable):
        res = run("study", sessions["P01"], victim, "--out", victim, "--keep-going", "--overwrite")
        refused(res, "would replace the input session", str(victim))
    _no_leftovers(tmp_path, before)


def test_subject_ids_must_be_unique(sessions, tmp_path) -> None:
    other = _set_subject(shutil.copytree(sessions["P02"], tmp_path / "again"), "P01")
    before = listing(tmp_path)
    line = refused(
        run("study", sessions["P01"], other, "--out", tmp_path / "out", "--keep-going"),
        "subject ID 'P01' is used by two sessions",
    )
    assert str(sessions["P01"]) in line and str(other) in line
    _no_leftovers(tmp_path, before)


@pytest.mark.parametrize("bad", ["../../evil", "/tmp/evil", ".hidden", "a" * 65, "P 1"])
def test_subject_id_never_leaves_the_output_folder(sessions, tmp_path, bad) -> None:
    src = _set_subject(shutil.copytree(sessions["P02"], tmp_path / "s"), bad)
    before = listing(tmp_path)
    refused(run("study", src, "--out", tmp_path / "out"), str(src / "session.toml"), "subject")
    _no_leftovers(tmp_path, before)


def test_a_refused_study_leaves_no_new_parent_folders(sessions, tmp_path) -> None:
    """``--out a/b/c/out`` whose parents are new: a refusal removes them again (a folder
    that was there before, or that holds something else meanwhile, stays)."""
    src = _set_subject(shutil.copytree(sessions["P02"], tmp_path / "s"), "../../../evil")
    (tmp_path / "kept").mkdir()
    before = listing(tmp_path)
    for out in ("a/b/c/out", "kept/b/out"):
        refused(run("study", src, "--out", tmp_path / out), "subject")
        _no_leftovers(tmp_path, before)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["kept", "s"]
    refused(run("study", tmp_path / "kept", "--out", tmp_path / "x/y/out"), "no session.toml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept", "s"]


def test_bad_subject_id_skipped_with_keep_going(sessions, tmp_path) -> None:
    src = _set_subject(shutil.copytree(sessions["P02"], tmp_path / "s"), "../escape")
    out = tmp_path / "out"
    res = run("study", src, sessions["P02"], "--out", out, "--keep-going")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "s"]
    assert not (tmp_path / "escape.json").exists()
    assert _summary(out)["failed"][0]["session"] == str(src)


def test_force_shows_the_warnings(sessions, tmp_path) -> None:
    before = listing(tmp_path)
    refused(
        run("study", sessions["P09"], "--out", tmp_path / "o"),
        "P09: index mp: the joint barely moved: median range of motion",
        "--force",
    )
    _no_leftovers(tmp_path, before)
    out = tmp_path / "forced"
    res = run("study", sessions["P09"], "--out", out, "--force")
    assert res.exit_code == 0, res.output
    assert "warning: P09: index mp: the joint barely moved" in res.output
    sm = _summary(out)
    assert sm["forced"] is True
    assert any("barely moved" in w for w in sm["warnings"]["P09"])
    report = (out / "report.html").read_text()
    assert "<h2 id=warnings>Warnings</h2>" in report
    assert re.search(
        r"<li>P09: index mp: the joint barely moved: median range of motion [\d.]+ deg is below 5",
        report,
    )


def test_broken_truth_file_is_named(sessions, tmp_path) -> None:
    src = shutil.copytree(sessions["P01"], tmp_path / "P01")
    (src / "truth.json").write_text("{")
    before = listing(tmp_path)
    refused(
        run("study", src, "--out", tmp_path / "out"),
        "P01: ",
        str(src / "truth.json"),
        "not valid JSON",
    )
    _no_leftovers(tmp_path, before)


@pytest.mark.parametrize("damage", ["text", "column"])
def test_broken_truth_table_is_named_with_its_line(sessions, tmp_path, damage) -> None:
    src = shutil.copytree(sessions["P01"], tmp_path / "P01")
    path = src / "truth" / "grasp.csv"
    rows = [ln.split(",") for ln in path.read_text().splitlines()]
    k = rows[0].index("index.tip.y")
    if damage == "text":
        rows[4][k] = "oops"  # line 5 of the file
        expected = (f"{path}:5: ", "field 'index.tip.y': 'oops' is not a number")
    else:
        rows = [r[:k] + r[k + 1 :] for r in rows]
        expected = (f"{path}:1: ", "missing column 'index.tip.y'")
    path.write_text("\n".join(",".join(r) for r in rows) + "\n")
    before = listing(tmp_path)
    refused(run("study", src, "--out", tmp_path / "out"), "P01: ", *expected)
    _no_leftovers(tmp_path, before)
