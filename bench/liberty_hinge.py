"""Real Polhemus Liberty logs: repeated rows and the hinge axis of sensor 2 about sensor 1.

Run ``.venv/bin/python bench/liberty_hinge.py``. Reads the three ``rotate-90deg-*.csv``
logs of ``../shared/data/polhemus-liberty`` (beside the repository) and prints the table
of ``docs/readers.md``: rows, repeated rows dropped, frames, the largest rotation from the
first frame, the hinge axis of each half against the other and the SARA axis against the
dominant rotation axis (deg). The measurements are ``tests/_shared_recordings.py``'s,
which ``tests/test_real_data.py`` asserts.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests._shared_recordings import LIBERTY, LIBERTY_FILES, liberty


def main() -> None:
    """Print the Markdown table of ``docs/readers.md``."""
    if not all((LIBERTY / f).is_file() for f in LIBERTY_FILES):
        sys.exit(f"real Polhemus Liberty recordings not found in {LIBERTY}")
    print("| file | rows | repeated rows dropped | frames | largest rotation from the first frame (deg) | "
          "hinge axis, half 1 vs half 2 (deg) | SARA vs dominant axis (deg) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name in LIBERTY_FILES:
        r = liberty(name)
        print(
            f"| {name} | {r['rows']} | {r['duplicates']} | {r['recording'].n_frames} | "
            f"{r['range_deg']:.1f} | {r['halves_deg']:.2f} | {r['dominant_deg']:.3f} |"
        )


if __name__ == "__main__":
    main()
