"""Marker recordings: TRC, Qualisys TSV and C3D read into ``Recording.markers`` (mm, NaN
gaps counted), every refusal one line naming the file and the line or field, the unit
check, and the TRC writer read back to the bit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fingerfit.errors import FingerfitError
from fingerfit.io.markers import read_marker_recording
from fingerfit.io.opensim import write_markers
from fingerfit.session import PoseSeries, Recording

from ._shared_recordings import DATA

EXCERPT = Path(__file__).resolve().parent / "data" / "dfki-hand-embodiment" / "excerpt.tsv"
DFKI = DATA / "dfki-hand-embodiment" / "recording.tsv"
LABELS = ["H1", "H2", "H3", "F1"]
#: A hand plate and one finger marker (mm): 30-64 mm apart.
SHAPE = np.array([[0.0, 0, 0], [40, 0, 0], [0, 30, 0], [60, 20, 10]])


def hand_points(n: int = 5) -> np.ndarray:
    """``(n, 4, 3)`` mm: the shape moving 1 mm per frame, 0.25 away from round numbers."""
    return SHAPE[None] + np.array([100.25, 200.5, 300.75]) + np.arange(n)[:, None, None]


def trc_text(
    points: np.ndarray,
    *,
    units: str = "mm",
    labels: list[str] = LABELS,
    time: np.ndarray | None = None,
    cells: dict[tuple[int, int], str] | None = None,
    n_frames: int | None = None,
) -> str:
    """A TRC file as an optical system writes it; ``cells`` replaces data cells (row,
    column of the data line, both from 0) by text."""
    n, m, _ = points.shape
    time = np.arange(n) / 100.0 if time is None else time
    lines = [
        "PathFileType\t4\t(X/Y/Z)\tt.trc",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"100\t100\t{n if n_frames is None else n_frames}\t{m}\t{units}\t100\t1\t{n}",
        "Frame#\tTime\t" + "\t\t\t".join(labels) + "\t\t",
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, m + 1)),
        "",
    ]
    for k in range(n):
        row = [str(k + 1), repr(float(time[k]))] + [repr(float(v)) for v in points[k].ravel()]
        for (r, c), text in (cells or {}).items():
            if r == k:
                row[c] = text
        lines.append("\t".join(row))
    return "\n".join(lines) + "\n"


def qtm_text(points: np.ndarray, *, labels: list[str] = LABELS, meta: dict | None = None) -> str:
    """A QTM TSV export (``\\r\\n``, lines ending in a tab as QTM writes the header)."""
    n, m, _ = points.shape
    head = {
        "NO_OF_FRAMES": str(n),
        "NO_OF_CAMERAS": "7",
        "NO_OF_MARKERS": str(m),
        "FREQUENCY": "100",
        "DATA_INCLUDED": "3D",
        "MARKER_NAMES": "\t".join(labels),
    } | (meta or {})
    lines = [f"{k}\t{v}" for k, v in head.items()]
    lines.append("Frame\tTime\t" + "\t".join(f"{lb} {a}" for lb in labels for a in "XYZ") + "\t")
    for k in range(n):
        lines.append(f"{k + 1}\t{k / 100:.5f}\t" + "\t".join(f"{v:.3f}" for v in points[k].ravel()))
    return "\r\n".join(lines) + "\r\n"


def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8", newline="")
    return p


def refused(path: Path, *pieces: str, **kw) -> str:
    with pytest.raises(FingerfitError) as exc:
        read_marker_recording(path, **kw)
    msg = str(exc.value)
    assert "\n" not in msg and str(path) in msg, msg
    for piece in pieces:
        assert piece in msg, msg
    return msg


def test_trc_values_time_and_units(tmp_path) -> None:
    pts = hand_points()
    rec = read_marker_recording(write(tmp_path, "a.trc", trc_text(pts)))
    assert rec.name == "a.trc" and rec.poses == {} and rec.notes == []
    assert list(rec.markers) == LABELS
    np.testing.assert_array_equal(rec.time, np.arange(5) / 100.0)
    for j, lb in enumerate(LABELS):
        np.testing.assert_array_equal(rec.markers[lb], pts[:, j])  # repr text: to the bit
    rec_m = read_marker_recording(write(tmp_path, "m.trc", trc_text(pts / 1000, units="m")))
    np.testing.assert_allclose(rec_m.markers["F1"], pts[:, 3], rtol=1e-15)
    rec_cm = read_marker_recording(tmp_path / "a.trc", units="cm")  # overrides Units
    np.testing.assert_allclose(rec_cm.markers["F1"], 10 * pts[:, 3])


def test_trc_gaps_partial_samples_lost_frames_and_duplicates_are_counted(tmp_path) -> None:
    pts = hand_points(6)
    # Marker F1 (columns 11-13): empty cells in frame 2, NaN in frame 3; H2's Y empty in
    # frame 4 (a partial sample); frame 5 lost (time jumps by two periods); frame 1
    # repeated exactly.
    cells = {(1, 11): "", (1, 12): "", (1, 13): "", (2, 11): "NaN", (2, 12): "nan"}
    cells |= {(2, 13): "NaN", (3, 6): ""}
    text = trc_text(pts, cells=cells, time=np.array([0, 0.01, 0.02, 0.03, 0.05, 0.06]))
    lines = text.splitlines()
    text = "\n".join([*lines[:7], lines[6], *lines[7:]]) + "\n"  # data line 1 twice
    text = text.replace("\t6\t4\tmm", "\t7\t4\tmm")
    rec = read_marker_recording(write(tmp_path, "g.trc", text))
    assert rec.n_frames == 7
    np.testing.assert_allclose(rec.time, np.arange(7) / 100.0, atol=1e-15)
    assert rec.notes == [
        "1 exact duplicate rows dropped",
        "1 frames missing for every marker (kept as NaN rows)",
        "1 samples with empty fields treated as missing",
        "marker 'H1': 1 of 7 frames missing",
        "marker 'H2': 2 of 7 frames missing",
        "marker 'H3': 1 of 7 frames missing",
        "marker 'F1': 3 of 7 frames missing",
    ]
    f1 = rec.markers["F1"]
    assert np.isnan(f1[[1, 2, 4]]).all() and np.isfinite(np.delete(f1, [1, 2, 4], axis=0)).all()
    assert np.isnan(rec.markers["H2"][[3, 4]]).all()
    np.testing.assert_array_equal(rec.markers["H1"][5], pts[4, 0])  # after the lost frame


@pytest.mark.parametrize(
    ("edit", "pieces"),
    [
        (
            lambda t: t.replace("\tmm\t", "\tfurlong\t"),
            ("field 'Units'", "unknown units 'furlong'"),
        ),
        (lambda t: t.replace("\tH3\t", "\tH1\t"), (":4:", "marker name 'H1' given twice")),
        (lambda t: t.replace("\t5\t4\tmm", "\t5\t5\tmm"), ("field 'NumMarkers'",)),
        (lambda t: t.replace("\t5\t4\tmm", "\t6\t4\tmm"), ("field 'NumFrames'", "holds 5 frames")),
        (lambda t: t.replace("PathFileType", "Path"), (":1:", "not a TRC file")),
        (lambda t: t.replace("100\t100\t5", "0\t100\t5"), ("field 'DataRate'",)),
    ],
)
def test_trc_header_refusals(tmp_path, edit, pieces) -> None:
    refused(write(tmp_path, "b.trc", edit(trc_text(hand_points()))), *pieces)


def test_trc_data_refusals_name_the_line_and_column(tmp_path) -> None:
    pts = hand_points()
    refused(
        write(tmp_path, "c.trc", trc_text(pts, cells={(2, 6): "12,5"})),
        ":9:",
        "field 'H2 Y'",
        "'12,5'",
    )
    refused(
        write(tmp_path, "i.trc", trc_text(pts, cells={(0, 2): "inf"})),
        ":7:",
        "field 'H1 X'",
        "finite",
    )
    text = trc_text(pts).splitlines()
    text[8] = "\t".join(text[8].split("\t")[:-2])  # a truncated line
    refused(write(tmp_path, "t.trc", "\n".join(text) + "\n"), ":9:", "12 fields, expected 14")
    text = trc_text(pts).splitlines()
    text[8] += "\t7.5"  # a cell too many
    refused(write(tmp_path, "x.trc", "\n".join(text) + "\n"), ":9:", "15 fields, expected 14")
    back = trc_text(pts, time=np.array([0, 0.01, 0.02, 0.01, 0.04]))
    refused(write(tmp_path, "r.trc", back), ":10:", "time goes backwards")
    refused(write(tmp_path, "n.trc", trc_text(pts[:0], n_frames=0)), "no frames")


def test_a_unit_mistake_is_refused(tmp_path) -> None:
    pts = hand_points()
    # Metres declared as millimetres: markers 0.03-0.06 mm apart.
    msg = refused(write(tmp_path, "m.trc", trc_text(pts / 1000)), "field 'units'")
    assert "marker spacing 0.03 mm" in msg and "2-300 mm" in msg
    # Millimetres declared as metres: 300 m from the origin.
    refused(write(tmp_path, "k.trc", trc_text(pts, units="m")), "field 'units'", "from the origin")
    # The same file with the right units passes.
    read_marker_recording(tmp_path / "m.trc", units="m")


def test_qtm_tsv_values_gaps_and_refusals(tmp_path) -> None:
    pts = hand_points(4)
    text = qtm_text(pts)
    rec = read_marker_recording(write(tmp_path, "q.tsv", text))
    np.testing.assert_array_equal(rec.markers["H3"], np.round(pts[:, 2], 3))
    np.testing.assert_array_equal(rec.time, [0, 0.01, 0.02, 0.03])
    gappy = text.replace("\t" + "\t".join(f"{v:.3f}" for v in pts[2, 3]), "\t\t\t")
    rec = read_marker_recording(write(tmp_path, "gap.tsv", gappy))
    assert (
        rec.notes == ["marker 'F1': 1 of 4 frames missing"] and np.isnan(rec.markers["F1"][2]).all()
    )
    refused(
        write(tmp_path, "n.tsv", qtm_text(pts, meta={"NO_OF_MARKERS": "5"})),
        "field 'NO_OF_MARKERS'",
    )
    refused(
        write(tmp_path, "f.tsv", qtm_text(pts, meta={"NO_OF_FRAMES": "9"})), "field 'NO_OF_FRAMES'"
    )
    refused(
        write(tmp_path, "d.tsv", qtm_text(pts, meta={"DATA_INCLUDED": "6D"})),
        "field 'DATA_INCLUDED'",
    )
    dup = qtm_text(pts).replace("MARKER_NAMES\tH1\tH2", "MARKER_NAMES\tH1\tH1")
    refused(write(tmp_path, "u.tsv", dup), ":6:", "field 'MARKER_NAMES'", "'H1' given twice")
    bad = qtm_text(pts).replace("H2 Y", "H2 Q")
    refused(write(tmp_path, "h.tsv", bad), ":7:", "header column 7 is 'H2 Q', expected 'H2 Y'")
    refused(
        write(tmp_path, "r.tsv", qtm_text(pts, meta={"FREQUENCY": "fast"})), "field 'FREQUENCY'"
    )
    no_names = "\r\n".join(
        ln for ln in qtm_text(pts).split("\r\n") if not ln.startswith("MARKER_NAMES")
    )
    refused(write(tmp_path, "m.tsv", no_names), "field 'MARKER_NAMES'", "missing")
    refused(write(tmp_path, "x.txt", text), "not a marker recording")


def test_the_dfki_excerpt_reads_as_the_file_says() -> None:
    rec = read_marker_recording(EXCERPT)
    assert rec.n_frames == 300 and len(rec.markers) == 13
    np.testing.assert_allclose(rec.time, 31.0 + np.arange(300) / 100.0, rtol=0, atol=1e-12)
    assert rec.notes == [
        "marker 'thumb_tip': 18 of 300 frames missing",
        "marker 'ring_tip': 42 of 300 frames missing",
        "marker 'middle_tip': 47 of 300 frames missing",
    ]
    # The file's first data line (frame 3101) and the last (frame 3400).
    np.testing.assert_array_equal(rec.markers["hand_top"][0], [305.406, 219.025, 290.649])
    np.testing.assert_array_equal(rec.markers["thumb_tip"][0], [277.506, 289.785, 176.440])
    last = EXCERPT.read_text().splitlines()[-1].split("\t")
    assert last[0] == "3400"
    np.testing.assert_array_equal(rec.markers["index_middle"][-1], [float(v) for v in last[-3:]])
    # thumb_tip's gap: frames 3138-3155 (0-based 3137-3154 of the whole file).
    gap = np.flatnonzero(np.isnan(rec.markers["thumb_tip"][:, 0]))
    np.testing.assert_array_equal(gap, np.arange(37, 55))


@pytest.mark.skipif(not DFKI.is_file(), reason="needs ../shared/data/dfki-hand-embodiment")
def test_the_whole_dfki_recording() -> None:
    rec = read_marker_recording(DFKI)
    assert rec.n_frames == 6000 and len(rec.markers) == 21
    np.testing.assert_allclose(np.diff(rec.time), 0.01, atol=1e-9)
    assert rec.notes == [
        "marker 'thumb_tip': 493 of 6000 frames missing",
        "marker 'ring_tip': 42 of 6000 frames missing",
        "marker 'middle_tip': 78 of 6000 frames missing",
    ]
    np.testing.assert_array_equal(rec.markers["pillow_right"][0], [371.959, 289.915, 223.330])


def test_c3d_markers_through_the_c3d_reader(tmp_path) -> None:
    pytest.importorskip("ezc3d")
    from .test_io_c3d import write_c3d

    pts = hand_points(6) / 10.0
    pts[2, 3] = np.nan  # F1 unseen in frame 3
    path = write_c3d(tmp_path / "a.c3d", LABELS, pts, rate=100.0, units="cm")
    rec = read_marker_recording(path)
    assert rec.notes == ["marker 'F1': 1 of 6 frames missing"]
    np.testing.assert_allclose(rec.markers["H2"], 10 * pts[:, 1], rtol=1e-6)  # float32 in C3D
    np.testing.assert_allclose(rec.time, np.arange(6) / 100.0)
    dup = write_c3d(tmp_path / "d.c3d", ["H1", "H2", "H1", "F1"], pts, units="cm")
    refused(dup, "field 'POINT:LABELS'", "'H1' given twice")
    refused(write_c3d(tmp_path / "m.c3d", LABELS, pts / 100, units="cm"), "field 'units'")


def test_trc_writer_round_trip_to_the_bit(tmp_path) -> None:
    rec = read_marker_recording(EXCERPT)
    out = write_markers(tmp_path / "r.trc", rec, units="mm")
    back = read_marker_recording(out)
    assert back.notes == rec.notes
    np.testing.assert_array_equal(back.time, rec.time)
    for lb, p in rec.markers.items():
        np.testing.assert_array_equal(back.markers[lb], p)
    # A 6-DOF recording's sensor origins still go out as <sensor>_imu markers (metres).
    six = Recording(
        "s",
        rec.time,
        {"hand": PoseSeries(rec.markers["hand_top"], np.tile(np.eye(3), (300, 1, 1)))},
    )
    back = read_marker_recording(write_markers(tmp_path / "s.trc", six, units="m"), units=None)
    assert list(back.markers) == ["hand_imu"]


def test_opensim_reads_a_marker_recording_written(tmp_path) -> None:
    osim = pytest.importorskip("opensim")
    rec = read_marker_recording(EXCERPT)
    table = osim.TimeSeriesTableVec3(str(write_markers(tmp_path / "r.trc", rec, units="mm")))
    assert list(table.getColumnLabels()) == list(rec.markers)
    assert table.getTableMetaDataString("Units") == "mm"
    col = table.getDependentColumn("thumb_tip")
    got = np.array([[col[i].get(k) for k in range(3)] for i in range(table.getNumRows())])
    np.testing.assert_array_equal(got, rec.markers["thumb_tip"])  # NaN where unseen
