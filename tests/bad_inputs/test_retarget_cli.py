"""``fingerfit retarget`` refuses bad maps, robots and options: one line, exit 2, nothing written."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

pytest.importorskip("mujoco")
pytest.importorskip("pinocchio")

from ..conftest import subject
from ..test_retarget import MAP, ROBOT_XML
from ._cli import listing, refused, run


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    from fingerfit.estimate import fit_session
    from fingerfit.io.posewrite import write_pose_csv
    from fingerfit.model import save_model

    sub = subject("exact", 11)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = fit_session(sub.session)
    d = tmp_path_factory.mktemp("rt")
    save_model(model, d / "model.json")
    write_pose_csv(d / "grasp.csv", sub.session.grasp[0], units=model.session_units)
    (d / "toy.xml").write_text(ROBOT_XML)
    (d / "toy.toml").write_text(MAP)
    return d


def _refused(d: Path, args: list[str], *fragments: str) -> None:
    out = d / "out"
    out.mkdir(exist_ok=True)
    before = listing(d)
    r = run("retarget", d / "model.json", d / "grasp.csv", "-o", out / "q.csv", *args)
    refused(r, *fragments)
    assert listing(d) == before


@pytest.mark.parametrize(
    ("edit", "fragments"),
    [
        (
            ('tip = "a_tip"', 'tip = "nope"'),
            ("bad.toml", "digits.index.tip", "unknown robot frame"),
        ),
        (
            ('mp = "b_mp"', 'mp = "b_xx"'),
            ("bad.toml", "digits.middle.joints.mp.robot", "unknown robot joint"),
        ),
        (("[robot]", "[robot\n"), ("bad.toml", "not valid TOML")),
        (('file = "toy.xml"', 'file = "gone.xml"'), ("bad.toml", "robot.file", "not found")),
        (("range = [0.0, 0.2]", 'range = "x"'), ("bad.toml", "coupling[0].range")),
    ],
)
def test_bad_map(inputs, edit, fragments):
    (inputs / "bad.toml").write_text(MAP.replace(*edit))
    try:
        _refused(
            inputs,
            ["--robot", str(inputs / "toy.xml"), "--map", str(inputs / "bad.toml")],
            *fragments,
        )
    finally:
        (inputs / "bad.toml").unlink()


def test_robot_file_needs_a_map(inputs):
    _refused(inputs, ["--robot", str(inputs / "toy.xml")], "--map")


def test_unknown_robot_name(inputs):
    _refused(inputs, ["--robot", "optimus"], "--robot", "unknown robot 'optimus'")


def test_unknown_method(inputs):
    _refused(inputs, ["--method", "magic"], "--method")


def test_figure_frame_past_the_end(inputs):
    _refused(inputs, ["--robot", "allegro", "--figure", "0,99999999"], "--figure", "past")


def test_output_onto_an_input_is_refused(inputs):
    before = listing(inputs)
    r = run("retarget", inputs / "model.json", inputs / "grasp.csv", "-o", inputs / "grasp.csv")
    refused(r)
    assert listing(inputs) == before
