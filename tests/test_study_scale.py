"""A study's memory per subject and its inputs made on the worker (large cohorts)."""

from __future__ import annotations

import contextlib
import functools
import json
import pickle
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions, fit_session
from fingerfit.evaluate import figures as figs
from fingerfit.evaluate import run_study
from fingerfit.evaluate.gather import (
    PackedSubjects,
    StudyTables,
    _categorical,
    _join_categorical,
)
from fingerfit.evaluate.subject import (
    MODEL_COLUMNS,
    SUBJECT_TABLES,
    SubjectResult,
    concat_tables,
    model_geometry,
)
from fingerfit.model import HandModel
from fingerfit.simulate import SimConfig, simulate_subject, write_subject
from fingerfit.simulate.source import simulated_cohort

CONFIG = SimConfig.exact(fingers=("index",))


@functools.cache
def _model() -> HandModel:
    """A fitted one-finger model (the fake results' tables come with a real model)."""
    return fit_session(simulate_subject(CONFIG, 1).session, FitOptions(method="tang2018"))


def _fake(subject: str, rng: np.random.Generator, truth: bool) -> SubjectResult:
    """A SubjectResult whose tables hold random rows (only the tables and model are read)."""
    n = int(rng.integers(1, 6))
    flex = pd.DataFrame(
        {
            "subject": subject,
            "finger": "index",
            "cycle": np.arange(1, n + 1),
            "user_axis": rng.normal(size=n),
            "orthogonal": rng.normal(size=n),
        }
    )
    empty_targets = pd.DataFrame(columns=SUBJECT_TABLES["targets"])
    tips = pd.DataFrame(
        [(subject, "index", "test.csv", "user_axis", rng.normal(), rng.normal())],
        columns=SUBJECT_TABLES["truth_tips"],
    )
    return SubjectResult(
        subject,
        None,  # type: ignore[arg-type]
        replace(_model(), subject=subject),
        {},
        flex,
        empty_targets,
        flex.rename(columns={"user_axis": "distance_mm"}).assign(joint="mp"),
        None,
        truth_tips=tips if truth else None,
    )


def test_study_tables_are_the_subjects_rows_in_order_on_disk_in_chunks(tmp_path) -> None:
    rng = np.random.default_rng(3)
    results = [_fake(f"S{i:02d}", rng, truth=i % 3 == 0) for i in range(75)]
    tables = StudyTables(folder=tmp_path, chunk=8)
    for i in rng.permutation(len(results)):  # arriving in any order
        light = tables.add(int(i), results[i])
        assert all(getattr(light, k) is None for k in SUBJECT_TABLES)
    assert tables.finish(range(len(results))) is tables  # joined in the order given
    # Only the tables that apply: no truth axes, angles, thumb or pinch here.
    assert list(tables) == ["max_flexion", "axis_quality", "targets", "truth_fingertip", "models"]
    fields = {"axis_quality": "distances", "truth_fingertip": "truth_tips"}
    for name in tables:
        if name == "models":
            want = concat_tables([model_geometry(r) for r in results], MODEL_COLUMNS)
        else:
            field = fields.get(name, name)
            rows = [getattr(r, field) for r in results if getattr(r, field) is not None]
            want = concat_tables(rows, SUBJECT_TABLES[field])
        got = tables[name]
        text = {c: t for c, t in want.dtypes.items() if isinstance(t, pd.StringDtype)}
        assert text or want.empty, name
        for c in text:  # categorical, categories sorted as text sorts
            cats = list(got[c].cat.categories)
            assert cats == sorted(cats) == sorted(set(want[c])), (name, c)
        pd.testing.assert_frame_equal(got.astype(text), want, check_exact=True)
        if text:  # a fraction of the memory of Arrow text (0.35x on 100 subjects' tables)
            used = got[list(text)].memory_usage(deep=True).sum()
            assert used < 0.8 * want[list(text)].memory_usage(deep=True).sum(), name
        # Chunks of up to 8 whole subjects, in order.
        chunks = [list(dict.fromkeys(c["subject"].astype(str))) for c in tables.chunks(name)]
        assert all(0 < len(c) <= 8 for c in chunks), name
        assert [s for c in chunks for s in c] == list(dict.fromkeys(want["subject"])), name
    assert tables["targets"].empty and list(tables.empty("targets")) == SUBJECT_TABLES["targets"]
    assert len(list(tables.chunks("max_flexion"))) == 10  # 75 subjects, 8 per chunk
    assert "truth_axes" not in tables and list(tables.chunks("truth_axes")) == []
    with pytest.raises(KeyError):
        tables["pinch"]
    if sys.platform == "linux":  # O_TMPFILE: never a name in the folder
        assert list(tmp_path.iterdir()) == []
    with pytest.raises(TypeError, match="cannot be pickled"):
        pickle.dumps(tables)


def test_packed_subjects_live_in_an_unnamed_file(tmp_path) -> None:
    rng = np.random.default_rng(2)
    results = [_fake(f"S{i:02d}", rng, truth=False) for i in range(5)]
    packed = PackedSubjects(folder=tmp_path)
    for r in results:
        packed.append(r)
    assert len(packed) == 5 and [s.subject for s in packed] == [r.subject for r in results]
    pd.testing.assert_frame_equal(packed[3].max_flexion, results[3].max_flexion)
    assert [s.subject for s in packed[-2:]] == ["S03", "S04"] and packed[-1].subject == "S04"
    packed.select([4, 0, 2])  # e.g. the order given, without a failed session
    assert [s.subject for s in packed] == ["S04", "S00", "S02"]
    packed.append(results[1])
    assert [s.subject for s in packed] == ["S04", "S00", "S02", "S01"]
    with pytest.raises(IndexError):
        packed[4]
    if sys.platform == "linux":  # O_TMPFILE: never a name in the folder
        assert list(tmp_path.iterdir()) == []
    with pytest.raises(TypeError, match="cannot be pickled"):
        pickle.dumps(packed)


def test_simulated_on_the_worker_is_the_study_of_the_written_folders(tmp_path) -> None:
    sources = simulated_cohort(CONFIG, 2, 41)
    dirs = [
        write_subject(simulate_subject(s.config, s.seed, s.subject), tmp_path / "in" / s.subject)
        for s in sources
    ]
    opts = FitOptions(method="tang2018")
    run_study(dirs, tmp_path / "folders", opts)
    made = run_study(sources, tmp_path / "made", opts)
    for name in ("max_flexion", "axis_quality", "targets", "models", "truth_axes"):
        a = (tmp_path / "folders" / f"{name}.csv").read_bytes()
        assert a == (tmp_path / "made" / f"{name}.csv").read_bytes(), name
    for m in (tmp_path / "folders" / "models").iterdir():
        assert m.read_bytes() == (tmp_path / "made" / "models" / m.name).read_bytes()
    a, b = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("folders", "made"))
    for doc in (a, b):
        doc.pop("created")
        for s in doc["sessions"].values():
            s.pop("path")
    assert a == b and a["truth"]["subjects"] == ["S01", "S02"]  # the truth came along
    assert [s.session.path for s in made.subjects] == [None, None]
    frames = sum(r.n_frames for d in dirs for r in _load(d).recordings())
    assert sum(s.frames for s in made.subjects) == frames > 0


def _load(folder: Path):
    from fingerfit.io import load_session

    return load_session(folder)


@dataclass(frozen=True)
class _Broken:
    """A source whose session cannot be made."""

    name: str

    def __str__(self) -> str:
        return f"broken {self.name}"

    @contextlib.contextmanager
    def open(self):
        raise OSError("no space left on device")
        yield Path()  # pragma: no cover


def test_a_source_that_cannot_be_made_is_named(tmp_path) -> None:
    good = simulated_cohort(CONFIG, 1, 5)
    res = run_study([*good, _Broken("B1")], tmp_path / "o", keep_going=True)
    assert [f.message for f in res.failures] == [
        "broken B1: could not be made (no space left on device)"
    ]
    with pytest.raises(FingerfitError, match=r"^broken B1: could not be made") as err:
        run_study([_Broken("B1"), *good], tmp_path / "p")
    assert "\n" not in str(err.value) and not (tmp_path / "p").exists()


def test_a_study_keeps_its_subjects_compact_and_on_disk(tmp_path) -> None:
    """What the study keeps per subject, pickled on disk: the model, the landmarks and
    names (measured: 6.8 KB pickled here, 21 KB with 4 fingers); its rows are in the
    study's tables, also on disk."""
    res = run_study(simulated_cohort(CONFIG, 2, 9), tmp_path / "o", FitOptions())
    assert isinstance(res.subjects, PackedSubjects) and isinstance(res.tables, StudyTables)
    for s in res.subjects:
        assert all(getattr(s, k) is None for k in SUBJECT_TABLES)
        assert s.grasp == {} and all(r.n_frames == 0 for r in s.session.recordings())
        assert len(pickle.dumps(s)) < 15_000
        assert set(s.truth.document["fingers"]["index"]) <= {"axis_offset_mm", "axes_angle_deg"}
    assert len(res.tables["max_flexion"]) == 20  # 2 subjects x 10 cycles


def test_one_box_per_subject_stops_widening() -> None:
    rng = np.random.default_rng(0)
    subject = np.repeat([f"S{i:03d}" for i in range(120)], 3)
    flex = pd.DataFrame(
        {"subject": subject, "user_axis": rng.random(360), "orthogonal": rng.random(360)}
    )
    fig = figs.make_paired_boxes(flex, "subject", "t", "mm", xlabel="subject")
    try:
        assert fig.get_size_inches()[0] == figs.MAX_WIDTH_IN  # was 1.2 * 120 + 3 = 147 in
        labels = [t.get_text() for t in fig.axes[0].get_xticklabels()]
        assert labels[0] == "S000" and len(labels) == 120  # 0.5 in each: all shown
    finally:
        plt.close(fig)
    few = figs.make_paired_boxes(flex[flex.subject < "S010"], "subject", "t", "mm")
    try:
        assert few.get_size_inches()[0] == pytest.approx(1.2 * 10 + 3)  # unchanged
    finally:
        plt.close(few)


def test_a_dask_worker_does_not_keep_the_results_read(tmp_path) -> None:
    """Each finished task's future is dropped once its outcome is read, so the cluster's
    workers hold at most the results not yet read (they kept every one before)."""
    distributed = pytest.importorskip("distributed")
    held: list[int] = []
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None
    ) as cluster:
        worker = next(iter(cluster.workers.values()))

        def step(msg: str) -> None:
            if msg.startswith("fitted"):
                # Releasing a dropped future reaches the worker asynchronously: give it
                # up to 5 s to fall to the one result being read.
                deadline = time.monotonic() + 5.0
                while len(worker.data) > 1 and time.monotonic() < deadline:
                    time.sleep(0.01)
                held.append(len(worker.data))

        run_study(
            simulated_cohort(CONFIG, 3, 17),
            tmp_path / "o",
            progress=step,
            scheduler=cluster.scheduler_address,
        )
    assert len(held) == 3
    assert held == [1, 1, 1], held  # before: 1, 2, 3 (every result kept)


def _cohort(n_subjects: int, per: int = 7, seed: int = 3) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "subject": np.repeat([f"S{i:04d}" for i in range(n_subjects)], per),
            "user_axis": rng.gamma(2.0, 1.0, n_subjects * per),
            "orthogonal": rng.gamma(3.0, 1.0, n_subjects * per),
        }
    )


def test_large_cohort_boxes_are_collections_with_boxplot_statistics() -> None:
    """Beyond SUMMARY_ABOVE groups a box plot is a few collections: the same number of
    artists for 100 and 1000 subjects, and the boxes, medians and whiskers drawn are
    matplotlib's boxplot statistics of each subject's values (1.5 IQR whiskers)."""
    from matplotlib.cbook import boxplot_stats
    from matplotlib.collections import LineCollection, PolyCollection

    counts = []
    for n in (figs.SUMMARY_ABOVE + 40, 1000):
        data = _cohort(n)
        fig = figs.make_paired_boxes(data, "subject", "t", "mm")
        try:
            ax = fig.axes[0]
            counts.append(len(ax.get_children()))
            # matplotlib's boxplot limits: the outer boxes' positions +- 0.5, no margin
            assert np.allclose(ax.get_xlim(), (-0.19 - 0.5, n - 1 + 0.19 + 0.5))
            polys = [c for c in ax.collections if isinstance(c, PolyCollection)]
            lines = [c for c in ax.collections if isinstance(c, LineCollection)]
            assert len(polys) == len(lines) == 2  # one of each per model
            for src, poly, line in zip(("user_axis", "orthogonal"), polys, lines, strict=True):
                stats = [boxplot_stats(g[src].to_numpy())[0] for _, g in data.groupby("subject")]
                boxes = np.array([p.vertices[:4] for p in poly.get_paths()])
                assert np.allclose(boxes[:, 0, 1], [s["q1"] for s in stats])
                assert np.allclose(boxes[:, 2, 1], [s["q3"] for s in stats])
                q = np.quantile(data.loc[data.subject == "S0007", src], [0.25, 0.75])
                assert np.allclose(boxes[7, [0, 2], 1], q)  # and those are the quartiles
                segs = line.get_segments()
                assert np.allclose([g[0, 1] for g in segs[:n]], [s["whislo"] for s in stats])
                assert np.allclose([g[1, 1] for g in segs[n : 2 * n]], [s["whishi"] for s in stats])
                assert np.allclose([g[0, 1] for g in segs[2 * n :]], [s["med"] for s in stats])
            points = [ln for ln in ax.lines if len(ln.get_xdata())]
            assert sum(len(ln.get_ydata()) for ln in points) == 2 * len(data)  # every value
        finally:
            plt.close(fig)
    assert counts[0] == counts[1]  # nothing per subject


def test_small_cohort_boxes_are_matplotlib_boxplots() -> None:
    data = _cohort(figs.SUMMARY_ABOVE)
    fig = figs.make_paired_boxes(data, "subject", "t", "mm")
    try:
        ax = fig.axes[0]
        assert not ax.collections  # matplotlib's own boxes (patches), as before
        assert np.allclose(ax.get_xlim(), (-0.19 - 0.5, figs.SUMMARY_ABOVE - 1 + 0.19 + 0.5))
        assert len(ax.patches) == 2 * figs.SUMMARY_ABOVE
    finally:
        plt.close(fig)


def test_axis_quality_of_a_large_cohort_draws_nothing_per_subject() -> None:
    rng = np.random.default_rng(4)
    counts = []
    for n in (figs.SUMMARY_ABOVE + 1, 600):
        joints = ["dip", "pip", "mp", "cmc", "mcp", "ip"]
        d = pd.DataFrame(
            {
                "subject": np.repeat([f"S{i:04d}" for i in range(n)], 6 * 5),
                "finger": "index",
                "joint": np.tile(np.repeat(joints, 5), n),
                "distance_mm": rng.gamma(2.0, 0.5, n * 30),
            }
        )
        d.loc[::11, "distance_mm"] = 25.0  # outliers, drawn as fliers
        fig = figs.make_axis_quality(d)
        try:
            counts.append([len(ax.get_children()) for ax in fig.axes])
            fliers = sum(len(ln.get_ydata()) for ax in fig.axes for ln in ax.lines)
            assert fliers >= (d.distance_mm == 25.0).sum() * 0.9
        finally:
            plt.close(fig)
    assert counts[0] == counts[1]


def test_chunks_join_over_their_categories_even_when_one_chunk_has_no_text() -> None:
    a = _categorical(pd.DataFrame({"subject": ["S2", "S1"], "note": ["x", None], "v": [1.0, 2]}))
    b = _categorical(pd.DataFrame({"subject": ["S3"], "note": [np.nan], "v": [3.0]}))
    assert b["note"].dtype == float  # all missing in this chunk: no text to make categories
    got = _join_categorical([b, a], ["subject", "note", "v"])
    assert list(got["subject"].cat.categories) == ["S1", "S2", "S3"]
    assert list(got["note"].cat.categories) == ["x"]
    assert got["subject"].tolist() == ["S3", "S2", "S1"]
    assert got["note"].isna().tolist() == [True, False, True]
    assert got["v"].tolist() == [3.0, 1.0, 2.0]
