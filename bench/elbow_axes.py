"""Real Optotrak arm trials: the elbow as one hinge or two axes, against the epicondyles.

Run ``.venv/bin/python bench/elbow_axes.py`` (needs the ``c3d`` extra, ezc3d). Reads the
wheelchair-propulsion and probing trials of ``../shared/data/optotrak-arm`` (beside the
repository) and prints the numbers of ``docs/readers.md``: cluster and probe residuals,
the probed medial epicondyle against the file's own reconstruction, the single-hinge
(SARA) and two-axis fits against the epicondyle line, over the whole trial and each half,
and the two-axis fit with its flexion axis forced onto the epicondyle line. The
measurements are ``tests/_shared_recordings.py``'s, which ``tests/test_real_data.py``
asserts; the axis helpers are ``tests/_axes.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests._axes import axis_angle_deg, dominant_axis, sara_axis, two_axis_fit, unit
from tests._shared_recordings import OPTOTRAK, elbow


def main() -> None:
    """Print the elbow's numbers, one per line."""
    if not (OPTOTRAK / "kinematics_racing_propulsion.c3d").is_file():
        sys.exit(f"real Optotrak C3D trials not found in {OPTOTRAK}")
    e = elbow()
    keys = [k for k in e if k not in ("rel", "epi")]
    for k in keys:
        v = e[k]
        print(f"{k}: {np.round(v, 3) if not isinstance(v, int) else v}")
    h = e["rel"].shape[0] // 2
    for part, sl in (("first half", slice(0, h)), ("second half", slice(h, None))):
        rel = e["rel"][sl]
        two = two_axis_fit(rel, dominant_axis(rel), n_starts=4)
        print(
            f"{part}: single hinge {axis_angle_deg(sara_axis(rel)[0], e['epi']):.1f} deg, "
            f"two-axis flexion {axis_angle_deg(two['a1'], e['epi']):.1f} deg "
            f"(rms {two['rms_deg']:.2f} deg)"
        )
    # Flexion axis forced onto the epicondyle line: how much worse does the model fit?
    forced = two_axis_fit(e["rel"], unit(e["epi"]), n_starts=4, fix_a1=True)
    print(f"two-axis with a1 = epicondyle line: rms {forced['rms_deg']:.2f} deg")


if __name__ == "__main__":
    main()
