"""``study --tables parquet``: each table a Parquet dataset partitioned by subject, the same
rows as the CSV tables (at full precision), readable by pandas and dask."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.estimate import FitOptions
from fingerfit.evaluate import run_study
from fingerfit.io import parquet as fpq
from fingerfit.simulate import SimConfig, simulate_cohort, write_subject

from .bad_inputs._cli import refused, run


@pytest.fixture(scope="module")
def studies(tmp_path_factory) -> tuple[Path, Path, list[Path]]:
    root = tmp_path_factory.mktemp("pq")
    config = SimConfig(fingers=("index", "thumb"))
    dirs = [write_subject(s, root / s.session.subject) for s in simulate_cohort(config, 2, 3)]
    opts = FitOptions(method="tang2018")
    run_study(dirs, root / "csv", opts)
    r = run(
        "study", *dirs, "--out", root / "pq", "--method", "tang2018", "--tables", "parquet", "-q"
    )
    assert r.exit_code == 0, r.output
    return root / "csv", root / "pq", dirs


def test_tables_are_datasets_partitioned_by_subject(studies) -> None:
    csv_dir, pq_dir, _ = studies
    names = sorted(p.stem for p in csv_dir.glob("*.csv"))
    assert names and sorted(p.stem for p in pq_dir.glob("*.parquet") if p.is_dir()) == names
    assert not list(pq_dir.glob("*.csv"))
    for name in names:
        want = pd.read_csv(csv_dir / f"{name}.csv")
        files = sorted((pq_dir / f"{name}.parquet").rglob("*.parquet"))
        if want.empty:
            assert [f.name for f in files] == ["empty.parquet"]
            continue
        subjects = sorted(want["subject"].astype(str).unique())
        assert [f.parent.name for f in files] == [f"subject={s}" for s in subjects]
        assert all(f.name == "part-0.parquet" for f in files)
        meta = pq.read_schema(files[0]).metadata
        assert meta[b"fingerfit.format"] == fpq.STUDY_TABLE.encode()
        assert meta[b"fingerfit.table"] == name.encode()
        got = pd.read_parquet(pq_dir / f"{name}.parquet")
        assert sorted(got.columns) == sorted(want.columns), name
        got = got[list(want.columns)].astype({"subject": str})
        got = got.sort_values(list(want.columns[:1]), kind="stable").reset_index(drop=True)
        want = want.sort_values(list(want.columns[:1]), kind="stable").reset_index(drop=True)
        assert len(got) == len(want), name
        for c in want.columns:
            if want[c].dtype.kind == "f":  # the CSV holds 6 significant digits
                np.testing.assert_allclose(got[c].to_numpy(float), want[c], rtol=5e-6, atol=1e-300)
            else:
                assert got[c].astype(str).tolist() == want[c].astype(str).tolist(), (name, c)


def test_dask_reads_the_datasets(studies) -> None:
    dd = pytest.importorskip("dask.dataframe")
    _, pq_dir, _ = studies
    flex = dd.read_parquet(str(pq_dir / "max_flexion.parquet")).compute()
    assert len(flex) == len(pd.read_parquet(pq_dir / "max_flexion.parquet")) > 0
    assert set(flex["subject"].astype(str)) == {"S01", "S02"}


def test_unknown_table_format_is_refused(studies, tmp_path) -> None:
    _, _, dirs = studies
    with pytest.raises(FingerfitError, match="field '--tables': must be csv or parquet"):
        run_study(dirs, tmp_path / "x", tables_format="xlsx")
    refused(run("study", *dirs, "--out", tmp_path / "y", "--tables", "xlsx"), "field '--tables'")
    assert not (tmp_path / "x").exists() and not (tmp_path / "y").exists()


def test_datasets_are_written_as_subjects_arrive(studies, tmp_path, monkeypatch) -> None:
    """Each subject's rows go to the datasets when its result arrives; once all have
    arrived nothing is written again (the tables with rows), and the datasets are those of
    the fixture's study."""
    from fingerfit.evaluate import gather
    from fingerfit.io import parquet as iopq

    _, pq_dir, dirs = studies
    added: list[str] = []
    real_add = gather.StudyTables.add

    def add(self, order, result):
        before = {n: set(w) for n, w in self.written.items()}
        light = real_add(self, order, result)
        new = {n: set(w) - before.get(n, set()) for n, w in self.written.items()}
        assert any(result.subject in s for s in new.values())
        for n, subjects in new.items():
            for s in subjects:
                assert self.written[n][s].is_file()
        added.append(result.subject)
        return light

    rewritten: list[str] = []
    real_partitioned = iopq.write_partitioned

    def partitioned(folder, chunks, schema, meta, **kw):
        rewritten.append(Path(folder).name)
        return real_partitioned(folder, chunks, schema, meta, **kw)

    monkeypatch.setattr(gather.StudyTables, "add", add)
    monkeypatch.setattr(iopq, "write_partitioned", partitioned)
    out = tmp_path / "pq"
    run_study(dirs, out, FitOptions(method="tang2018"), tables_format="parquet")
    assert sorted(added) == ["S01", "S02"]
    for folder in sorted(out.glob("*.parquet")):
        files = sorted(folder.rglob("*.parquet"))
        if [f.name for f in files] == ["empty.parquet"]:
            assert folder.name in rewritten
            continue
        assert folder.name not in rewritten, folder.name
        old = pd.read_parquet(pq_dir / folder.name)
        new = pd.read_parquet(folder)
        pd.testing.assert_frame_equal(new, old[list(new.columns)], check_categorical=False)
