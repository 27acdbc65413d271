"""How ``excerpt.tsv`` was made from the original (``README.md``).

    python tests/data/dfki-hand-embodiment/make_excerpt.py recording.tsv

``recording.tsv`` is ``test/data/recording.tsv`` of github.com/dfki-ric/hand_embodiment
(commit dc57460). Frames 3101-3400 (3 s at 100 Hz, chosen for their gaps) and the 13
markers of the hand are kept, every line as in the original (its cells, ``\\r\\n`` ends
and the trailing tab of the header line); the metadata lines say so.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
FRAMES = range(3101, 3401)
MARKERS = 13  # hand_top ... index_middle: the hand's markers come first in the file


def main(source: str) -> None:
    lines = Path(source).read_bytes().decode("utf-8").split("\r\n")
    meta, header, data = lines[:11], lines[11], lines[12:]
    keep = 2 + 3 * MARKERS
    out = []
    for line in meta:
        key, *values = line.split("\t")
        if key == "NO_OF_FRAMES":
            values = [str(len(FRAMES))]
        elif key == "NO_OF_MARKERS":
            values = [str(MARKERS)]
        elif key in ("MARKER_NAMES", "TRAJECTORY_TYPES"):
            values = values[:MARKERS]
        out.append("\t".join([key, *values]))
    out.append("\t".join(header.split("\t")[:keep]) + "\t")
    rows = {int(line.split("\t", 1)[0]): line for line in data if line}
    out += ["\t".join(rows[f].split("\t")[:keep]) for f in FRAMES]
    (HERE / "excerpt.tsv").write_bytes(("\r\n".join(out) + "\r\n").encode("utf-8"))


if __name__ == "__main__":
    main(sys.argv[1])
