"""Marker sessions: the marker map (``markers.toml``) and its refusals, marker recordings
in ``fingerfit.session/1`` (``fingerfit session --markers``, load, save as TRC, read back
to the bit), and the rules that replace the sensors' (no landmarks needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from fingerfit.cli import app
from fingerfit.errors import FingerfitError
from fingerfit.io import load_session
from fingerfit.io.markers.markermap import read_marker_map
from fingerfit.io.sessiondir import save_session

from .test_io_markers import EXCERPT, LABELS, hand_points, trc_text, write

DFKI_MAP = EXCERPT.parent / "markers.toml"
MAP = '[markers]\nhand = ["H1", "H2", "H3"]\n"index.proximal" = ["F1"]\n'


def map_file(tmp_path: Path, text: str = MAP, name: str = "map.toml") -> Path:
    return write(tmp_path, name, text)


@pytest.mark.parametrize(
    ("text", "pieces"),
    [
        (
            '[markers]\nhand = ["H1", "H2", "H3"]\n"index.proximl" = ["F1"]\n',
            ("field 'markers.index.proximl'", "unknown segment", "did you mean 'index.proximal'"),
        ),
        (
            '[markers]\nhand = ["H1", "H2", "H3"]\n"index.distal" = []\n',
            ("field 'markers.index.distal'", "segment 'index.distal' has no markers"),
        ),
        (
            '[markers]\nhand = ["H1", "H2"]\n"index.distal" = ["F1"]\n',
            ("field 'markers.hand'", "the hand needs 3 or more markers, found 2"),
        ),
        ('[markers]\n"index.distal" = ["F1"]\n', ("field 'markers.hand'", "found 0")),
        (
            '[markers]\nhand = ["H1", "H2", "H3"]\n"index.distal" = ["H2"]\n',
            (
                "field 'markers.index.distal'",
                "marker 'H2' is listed under 'hand' and 'index.distal'",
            ),
        ),
        ('[markers]\nhand = ["H1", "H2", "H3", "H1"]\n', ("marker 'H1' is listed twice",)),
        ('[markers]\nhand = ["H1", "H2", 3]\n', ("field 'markers.hand'", "non-empty strings")),
        ('[marker]\nhand = ["H1", "H2", "H3"]\n', ("field 'marker'", "unknown key")),
        ('hand = ["H1", "H2", "H3"]\n', ("field 'hand'", "unknown key")),
        ('[markers]\nhand = ["H1", "H2"\n', ("invalid TOML",)),
        ('[markers]\nstylus = ["S1"]\nhand = ["H1", "H2", "H3"]\n', ("unknown segment 'stylus'",)),
    ],
)
def test_bad_maps_are_refused_in_one_line(tmp_path, text, pieces) -> None:
    path = map_file(tmp_path, text)
    with pytest.raises(FingerfitError) as exc:
        read_marker_map(path)
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(str(path)), msg
    for piece in pieces:
        assert piece in msg, msg


def test_the_dfki_map_reads() -> None:
    m = read_marker_map(DFKI_MAP)
    assert m["hand"] == ("hand_top", "hand_left", "hand_right")
    assert m["index.proximal"] == ("index_middle",) and m["thumb.distal"] == ("thumb_tip",)
    assert len(m) == 11


def session_args(tmp_path: Path, out: str = "S", *, map_text: str = MAP, **files: str) -> list[str]:
    """``fingerfit session`` of three synthetic TRC recordings and a map in ``tmp_path``."""
    src = tmp_path / "src"
    src.mkdir(exist_ok=True)
    texts = {"reference.trc": trc_text(hand_points(5)), "grasp.trc": trc_text(hand_points(8))}
    texts["free.trc"] = trc_text(hand_points(6), cells={(1, 11): "", (1, 12): "", (1, 13): ""})
    texts |= files
    for name, text in texts.items():
        write(src, name, text)
    map_file(src, map_text)
    args = ["session", str(tmp_path / out), "--subject", "M1", "--hand", "right", "--units"]
    args += ["mm", "--rate", "100", "--fingers", "index", "--markers", str(src / "map.toml")]
    args += ["--reference", str(src / "reference.trc"), "--grasp", str(src / "grasp.trc")]
    return [*args, "--test", str(src / "free.trc")]


def run(args: list[str]) -> tuple[int, str]:
    res = CliRunner().invoke(app, args)
    return res.exit_code, res.output


def test_a_marker_session_is_built_loaded_and_saved_to_the_bit(tmp_path) -> None:
    code, out = run(session_args(tmp_path))
    assert code == 0, out
    assert "note: free.trc: marker 'F1': 1 of 6 frames missing" in out
    s = load_session(tmp_path / "S")
    assert s.marker_map == {"hand": ("H1", "H2", "H3"), "index.proximal": ("F1",)}
    assert s.landmarks == {} and s.reference.poses == {}
    assert [p.name for p in s.files] == [
        "session.toml",
        "reference.trc",
        "grasp.trc",
        "free.trc",
        "markers.toml",
    ]
    assert 'markers = "markers.toml"' in (tmp_path / "S" / "session.toml").read_text()
    np.testing.assert_array_equal(s.grasp[0].markers["H2"], hand_points(8)[:, 1])
    assert np.isnan(s.test[0].markers["F1"][1]).all()
    save_session(s, tmp_path / "again")
    t = load_session(tmp_path / "again")
    assert t.marker_map == s.marker_map and t.test[0].notes == s.test[0].notes
    for a, b in zip(s.recordings(), t.recordings(), strict=True):
        assert a.name == b.name
        np.testing.assert_array_equal(a.time, b.time)
        assert list(a.markers) == list(b.markers) == LABELS
        for lb in LABELS:
            np.testing.assert_array_equal(a.markers[lb], b.markers[lb])


def test_saving_qtm_and_c3d_recordings_writes_trc(tmp_path) -> None:
    args = session_args(tmp_path)
    args[args.index("--reference") + 1] = str(EXCERPT)
    args[args.index("--markers") + 1] = str(DFKI_MAP)
    args[args.index("--fingers") + 1] = "thumb,index,middle,ring,little"
    src = tmp_path / "src"
    for flag in ("--grasp", "--test"):
        args[args.index(flag) + 1] = str(src / f"{flag[2:]}.tsv")
        (src / f"{flag[2:]}.tsv").write_bytes(EXCERPT.read_bytes())
    code, out = run(args)
    assert code == 0, out
    s = load_session(tmp_path / "S")
    save_session(s, tmp_path / "T")
    t = load_session(tmp_path / "T")
    assert [r.name for r in t.recordings()] == ["excerpt.trc", "grasp.trc", "test.trc"]
    for a, b in zip(s.recordings(), t.recordings(), strict=True):
        for lb in a.markers:
            np.testing.assert_array_equal(a.markers[lb], b.markers[lb])


def refused(args: list[str], *pieces: str) -> str:
    code, out = run(args)
    assert code == 2, out
    errors = [ln for ln in out.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, out
    line = errors[0]
    for piece in pieces:
        assert piece in line, line
    return line


def test_a_map_that_does_not_fit_the_session_is_refused(tmp_path) -> None:
    unknown = MAP.replace('["F1"]', '["F2"]')
    refused(
        session_args(tmp_path, "a", map_text=unknown),
        "map.toml",
        "field 'markers.index.proximal'",
        "unknown marker 'F2': not in recording",
        "src/reference.trc",
    )
    other = MAP + '"ring.distal" = ["F1b"]\n'
    refused(
        session_args(tmp_path, "b", map_text=other),
        "map.toml",
        "field 'markers.ring.distal'",
        "digit 'ring', which is not one of the session's fingers (index)",
    )
    args = session_args(tmp_path, "c")
    args[args.index("--fingers") + 1] = "index,middle"
    refused(args, "map.toml", "finger 'middle'", "has no markers")
    assert not list(tmp_path.glob("[abc]*")) and not list(tmp_path.glob(".[abc]*"))


def test_unseen_markers_units_and_rates_are_refused(tmp_path) -> None:
    blind = trc_text(hand_points(8), cells={(k, c): "" for k in range(8) for c in (11, 12, 13)})
    refused(
        session_args(tmp_path, "a", **{"grasp.trc": blind}),
        "grasp.trc",
        "no samples for marker 'F1' (segment 'index.proximal' in map.toml)",
    )
    cm = {n: trc_text(hand_points(k) / 10) for n, k in (("reference.trc", 5), ("grasp.trc", 8))}
    refused(
        session_args(tmp_path, "b", **cm),
        "reference.trc",
        "field 'units'",
        "span of the mapped markers 6.403 mm",
        "the units the file states",
    )
    args = session_args(tmp_path, "c")
    args[args.index("--rate") + 1] = "120"
    refused(args, "reference.trc", "frame rate 100 Hz, not the session's rate_hz 120")


def test_pose_and_marker_files_do_not_mix(tmp_path) -> None:
    args = session_args(tmp_path, "a")
    args[args.index("--grasp") + 1] = str(tmp_path / "src" / "grasp.csv")
    (tmp_path / "src" / "grasp.csv").write_text("time,sensor,x,y,z,qw,qx,qy,qz\n")
    refused(args, "grasp.csv", "not a marker recording")
    i = args.index("--markers")
    no_map = args[:i] + args[i + 2 :] + ["--landmarks", str(tmp_path / "src" / "l.csv")]
    no_map[no_map.index("--grasp") + 1] = str(tmp_path / "src" / "grasp.trc")
    refused(no_map, "reference.trc", "is a marker recording: give its marker map (--markers)")
    refused(args[:i] + args[i + 2 :], "field '--landmarks'", "unless --markers")


def test_session_toml_refusals_of_a_marker_session(tmp_path) -> None:
    assert run(session_args(tmp_path))[0] == 0
    folder = tmp_path / "S"
    toml = folder / "session.toml"
    text = toml.read_text()
    toml.write_text(text.replace('markers = "markers.toml"\n', ""))
    with pytest.raises(
        FingerfitError,
        match=r"session.toml: field 'recordings.reference': "
        r"'reference.trc' is a marker recording: name the marker map too",
    ):
        load_session(folder)
    toml.write_text(text.replace('"markers.toml"', '"../map.toml"'))
    with pytest.raises(
        FingerfitError, match=r"field 'markers': '../map.toml' leaves the session folder"
    ):
        load_session(folder)
    toml.write_text(text)
    (folder / "landmarks.csv").write_text("name,x,y,z\nindex.tip,1,2,3\n")
    assert load_session(folder).landmarks["index.tip"].tolist() == [1.0, 2.0, 3.0]
    assert (folder / "landmarks.csv") in load_session(folder).files
