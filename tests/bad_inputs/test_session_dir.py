"""Session directories: subject IDs, files contained in the folder, unknown keys.

Items 10 (session part) and 11 of the trust issue. Every refusal is one ``error:`` line
naming ``session.toml`` and the field, exit status 2, nothing written, and no content of
a file outside the session folder in the message.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from fingerfit.errors import FingerfitError
from fingerfit.io import load_session
from fingerfit.session import check_subject_id
from fingerfit.simulate import write_subject

from ..conftest import subject
from ._cli import listing, refused, run


@pytest.fixture(scope="module")
def session_src(tmp_path_factory) -> Path:
    return write_subject(subject("realistic", 2), tmp_path_factory.mktemp("sess") / "S01")


@pytest.fixture
def sess(tmp_path, session_src) -> Path:
    d = tmp_path / "S01"
    shutil.copytree(session_src, d)
    return d


def _set(d: Path, key: str, line: str) -> None:
    """Replace the ``key = ...`` line of session.toml (or append ``line`` under it)."""
    toml = d / "session.toml"
    lines = toml.read_text().splitlines()
    hits = [i for i, ln in enumerate(lines) if ln.startswith(f"{key} =")]
    if hits:
        lines[hits[0]] = line
    else:
        lines.append(line)
    toml.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize(
    "value",
    ["../../../evil", "..", ".hidden", "a/b", "", "x" * 65, "tab\there", "é", "a b"],
)
def test_check_subject_id_refuses(value) -> None:
    with pytest.raises(FingerfitError, match="field 'subject': subject ID") as err:
        check_subject_id(value, path="study.toml")
    assert "\n" not in str(err.value) and str(err.value).startswith("study.toml: ")


@pytest.mark.parametrize("value", ["P07", "S01", "a.b-c_d", "7", "x" * 64, "Sub_3.left"])
def test_check_subject_id_accepts(value) -> None:
    assert check_subject_id(value) == value


def test_session_command_refuses_an_unsafe_subject(tmp_path, session_src) -> None:
    out = tmp_path / "work" / "out"
    out.parent.mkdir()
    before = listing(tmp_path)
    res = run(
        "session", out, "--subject", "../../../evil",
        "--reference", session_src / "reference.csv", "--grasp", session_src / "grasp.csv",
        "--landmarks", session_src / "landmarks.csv", "--fingers", "index",
    )  # fmt: skip
    refused(res, "field '--subject': subject ID '../../../evil' must be 1-64 letters")
    assert listing(tmp_path) == before
    assert not list(tmp_path.parent.glob("evil*"))


def test_session_toml_subject_is_checked(sess) -> None:
    _set(sess, "subject", 'subject = "../../x"')
    before = listing(sess.parent)
    refused(run("fit", sess), f"{sess / 'session.toml'}: field 'subject': subject ID '../../x'")
    assert listing(sess.parent) == before


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ('reference = "/etc/passwd"', "field 'recordings.reference': '/etc/passwd' is an absolute"),
        ('reference = "../outside.csv"', "field 'recordings.reference': '../outside.csv' leaves"),
        (
            'reference = "a/../../outside.csv"',
            "field 'recordings.reference': 'a/../../outside.csv' leaves",
        ),
        ('grasp = ["grasp.csv", "/tmp/x.csv"]', "field 'recordings.grasp': '/tmp/x.csv' is an"),
        ('events = "../outside.csv"', "field 'recordings.events': '../outside.csv' leaves"),
        ('test = ["."]', "field 'recordings.test': is not a regular file: '.'"),
    ],
)
def test_recordings_must_stay_inside(sess, line, expected) -> None:
    outside = sess.parent / "outside.csv"
    shutil.copyfile(sess / "reference.csv", outside)
    _set(sess, line.split(" =")[0], line)
    before = listing(sess.parent)
    msg = refused(run("fit", sess), f"{sess / 'session.toml'}: {expected}")
    assert "root:" not in msg and "time,sensor" not in msg
    assert listing(sess.parent) == before


def test_symlinks_pointing_outside_are_refused(sess) -> None:
    outside = sess.parent / "elsewhere"
    outside.mkdir()
    shutil.move(sess / "grasp.csv", outside / "grasp.csv")
    os.symlink(outside / "grasp.csv", sess / "grasp.csv")
    before = listing(sess.parent)
    refused(
        run("fit", sess),
        f"{sess / 'session.toml'}: field 'recordings.grasp': 'grasp.csv' is a link to a file "
        "outside the session folder",
    )
    assert listing(sess.parent) == before
    # the fixed landmarks.csv too, and a link into /etc is never read
    shutil.move(outside / "grasp.csv", sess / "grasp.csv")
    (sess / "landmarks.csv").unlink()
    os.symlink("/etc/passwd", sess / "landmarks.csv")
    msg = refused(run("fit", sess), "field 'landmarks.csv': 'landmarks.csv' is a link")
    assert "root:" not in msg


def test_symlinks_inside_the_folder_are_fine(sess) -> None:
    (sess / "raw").mkdir()
    shutil.move(sess / "grasp.csv", sess / "raw" / "grasp-take1.csv")
    os.symlink("raw/grasp-take1.csv", sess / "grasp.csv")
    s = load_session(sess)
    assert s.grasp[0].name == "grasp.csv" and s.grasp[0].n_frames > 100


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        (
            'grsp = ["grasp.csv"]',
            "field 'recordings.grsp': unknown key 'grsp' in [recordings], did you mean 'grasp'?",
        ),
        ('subjet = "S01"', "field 'subjet': unknown key 'subjet' in session.toml, did you mean"),
        ("colour = 3", "field 'colour': unknown key 'colour' in session.toml (known: format, "),
        ("[recordings.extra]\nx = 1", "field 'recordings.extra': unknown key 'extra' in [rec"),
    ],
)
def test_unknown_keys_are_errors(sess, line, expected) -> None:
    toml = sess / "session.toml"
    text = toml.read_text()
    if line.startswith("subjet") or line.startswith("colour"):
        text = line + "\n" + text
    else:
        text = text + line + "\n"
    toml.write_text(text)
    refused(run("fit", sess), f"{toml}: {expected}")
    assert not (sess / "model.json").exists()


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("rate_hz = inf", "field 'rate_hz': must be positive and at most 1e+06 Hz"),
        ("rate_hz = 1e400", "field 'rate_hz': must be positive"),
        ("rate_hz = 99999999999999999999999999", "field 'rate_hz': must be positive"),
        ('hand = "left\\nright"', "field 'hand': must be 'left' or 'right', not 'left\\nright'"),
        ("fingers = [[1], 2]", "field 'fingers': must be a non-empty list of distinct names"),
        ("grasp = []", "field 'recordings.grasp': needs at least one grasp recording"),
        ('grasp = "a\\u0001b"', "field 'recordings.grasp': 'a\\x01b' contains control characters"),
    ],
)
def test_odd_toml_values(sess, line, expected) -> None:
    _set(sess, line.split(" =")[0], line)
    refused(run("fit", sess), f"{sess / 'session.toml'}: {expected}")


def test_not_a_session_directory(tmp_path) -> None:
    refused(run("fit", tmp_path), f"{tmp_path}: not a session directory (no session.toml)")
    assert not list(tmp_path.iterdir())
