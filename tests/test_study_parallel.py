"""The study in worker processes and on a Dask cluster gives exactly the serial study."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.simulate import write_subject

from .conftest import subject


@pytest.fixture(scope="module")
def cohort(tmp_path_factory):
    """Three sessions: two realistic (targets, test, truth), one exact."""
    root = tmp_path_factory.mktemp("parallel")
    dirs = []
    for i, (kind, seed) in enumerate((("realistic", 2), ("exact", 11), ("realistic", 2))):
        d = write_subject(subject(kind, seed), root / f"P{i + 1:02d}")
        toml = d / "session.toml"
        text = toml.read_text()
        toml.write_text(
            text.replace(
                f'subject = "{subject(kind, seed).session.subject}"', f'subject = "P{i + 1:02d}"'
            )
        )
        dirs.append(d)
    return root, dirs


def _study(out, dirs, *extra):
    res = CliRunner().invoke(
        app, ["study", *map(str, dirs), "--out", str(out), "--method", "tang2018", *extra]
    )
    assert res.exit_code == 0, res.output
    doc = json.loads((out / "summary.json").read_text())
    doc.pop("created")
    return doc, sorted(p.name for p in out.rglob("*"))


def _same_tables(a, b) -> None:
    for name in ("max_flexion.csv", "targets.csv", "axis_quality.csv", "models.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    for m in (a / "models").iterdir():
        assert m.read_bytes() == (b / "models" / m.name).read_bytes(), m.name


def test_jobs_2_gives_the_serial_study(cohort) -> None:
    root, dirs = cohort
    serial, files = _study(root / "serial", dirs)
    parallel, pfiles = _study(root / "jobs2", dirs, "--jobs", "2")
    assert parallel == serial and pfiles == files
    assert serial["subjects"] == ["P01", "P02", "P03"]  # the order given, not completion order
    assert "fig09_trajectories_P02.png" in files
    _same_tables(root / "serial", root / "jobs2")


def test_local_dask_cluster_gives_the_serial_study(cohort) -> None:
    distributed = pytest.importorskip("distributed")
    root, dirs = cohort
    serial, files = _study(root / "serial-d", dirs[:2])
    with distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        host="127.0.0.1",
        protocol="tcp",
        dashboard_address=None,
    ) as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        dask_doc, dfiles = _study(root / "dask", dirs[:2], "--scheduler", cluster.scheduler_address)
    assert dask_doc == serial and dfiles == files
    _same_tables(root / "serial-d", root / "dask")


def test_jobs_2_keep_going_names_the_failed_session(cohort, tmp_path) -> None:
    _root, dirs = cohort
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "session.toml").write_text("format = 'nope'\n")
    res = CliRunner().invoke(
        app,
        [
            "study",
            str(dirs[1]),
            str(broken),
            "--out",
            str(tmp_path / "o"),
            "--jobs",
            "2",
            "--keep-going",
        ],
    )
    assert res.exit_code == 0, res.output
    doc = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert doc["subjects"] == ["P02"] and doc["failed"][0]["session"] == str(broken)


def test_unreachable_scheduler_is_one_line(tmp_path, cohort) -> None:
    pytest.importorskip("distributed")
    _root, dirs = cohort
    res = CliRunner().invoke(
        app,
        ["study", str(dirs[1]), "--out", str(tmp_path / "o"), "--scheduler", "tcp://127.0.0.1:9"],
    )
    assert res.exit_code == 2 and "--scheduler" in res.output and "Traceback" not in res.output
    assert not (tmp_path / "o").exists()
