"""The study-wide figures drawn as study tasks are the figures the study process would draw,
and each subject's Fig. 9 is linked from the report, not embedded."""

from __future__ import annotations

import io

import pytest

from fingerfit.estimate import FitOptions
from fingerfit.evaluate import figures
from fingerfit.evaluate.study import (
    draw_study_figure,
    figure_builders,
    figure_tables,
    run_study,
)
from fingerfit.simulate import write_subject

from .conftest import subject


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("figtasks")
    d = write_subject(subject("realistic", 2), root / "S01")
    return run_study([d], root / "out", FitOptions(method="tang2018"), jobs=1)


def test_a_figure_task_gives_the_same_png_as_drawing_it_here(study) -> None:
    built = figure_builders(study.subjects, study.tables)
    keys = [k for k in built if not k.startswith("fig09")]
    assert {"fig08", "fig10", "fig11", "fig12", "truth"} <= set(keys)
    for key in keys:
        here = io.BytesIO()
        figures.save_to(built[key][1](), here)
        task = draw_study_figure(key, study.tables)
        assert task[:8] == b"\x89PNG\r\n\x1a\n", key
        assert task == here.getvalue(), key
        assert (study.out_dir / built[key][0]).read_bytes() == task, key
        # The study sends each task only the figure's own table: the same PNG.
        sent = figure_tables(key, study.tables)
        assert sum(len(t) for t in sent.values()) < sum(len(t) for t in study.tables.values())
        assert draw_study_figure(key, sent) == task, key


def test_fig09_is_linked_and_the_rest_embedded(study) -> None:
    html = study.report.read_text()
    assert 'src="fig09_trajectories_S01.png"' in html
    assert (study.out_dir / "fig09_trajectories_S01.png").stat().st_size > 10_000
    assert html.count("data:image/png;base64,") == 5  # Figs. 8, 10, 11, 12, truth
