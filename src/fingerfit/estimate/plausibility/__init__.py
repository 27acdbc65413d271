"""Physical plausibility: units and the quaternion convention (``docs/plausibility.md``).

A recording in the wrong units or with quaternions in the wrong order fits without any
numerical complaint and gives a plausible-looking wrong model. These checks compare the
data with what a hand can be and with itself:

* **units** -- lengths against physiological bounds (:data:`SEGMENT_FRACTION` of a hand
  length in :data:`HAND_LENGTH_MM`, with the margins :data:`MARGIN`): neighbouring sensor
  distances in every recording, landmark distances, landmarks against the sensors of their
  segments, and the fitted model's segment lengths, finger length, landmark-to-centre and
  sensor-to-centre distances. A length out of bounds names the unit mistake that would
  bring it into range (ratios 1000, 100, 39.37, 25.4, 10, 2.54 and their inverses);
* **quaternion convention** -- the pivot residual: a joint's parent and child sensors must
  agree on one joint centre, ``R_p c_p + t_p = R_c c_c + t_c`` for every grasp frame
  (O'Brien et al. 2000). The residual is also evaluated with the quaternions conjugated,
  in ``x,y,z,w`` order, and both, and an alternative that fits far better is named;
* **a recording against a model** (``fingerfit angles``) -- the same pivot equation with
  the model's centre, and the scale factor that would fit;
* **any joint between two segments** (``fingerfit joint``) -- the distance from the joint
  to the farther segment origin against :data:`JOINT_REACH_MM`, and the pivot residual with
  one position axis negated (a mirrored frame, :data:`MIRRORS`).

Every check returns :class:`Problem` records; :func:`enforce` raises the first as a
:class:`PlausibilityError` (one line) unless ``force``, in which case each is warned about
as a :class:`PlausibilityWarning`. Lengths are mm, positions tracker coordinates, rotation
matrices sensor -> tracker (``docs/conventions.md``); quaternions ``(w, x, y, z)``.

Modules: :mod:`.bounds` (what a hand can be, the thresholds), :mod:`.problems` (the
records, :func:`enforce`, the unit mistake that explains a length), :mod:`.units`,
:mod:`.convention` and :mod:`.checks` (the entry points); every name is importable from
here.
"""

from .bounds import CONVENTION_RATIO as CONVENTION_RATIO
from .bounds import (
    HAND_LENGTH_MM,
    JOINT_REACH_MM,
    MARGIN,
    SEGMENT_FRACTION,
    Bound,
    finger_length_bound,
    neighbour_bound,
    segment_bound,
)
from .bounds import LANDMARK_TO_CENTRE_MAX_MM as LANDMARK_TO_CENTRE_MAX_MM
from .bounds import PIVOT_FLOOR_MM as PIVOT_FLOOR_MM
from .bounds import PIVOT_MIN_MM as PIVOT_MIN_MM
from .bounds import PIVOT_NOISE_FACTOR as PIVOT_NOISE_FACTOR
from .bounds import RECORDING_RESIDUAL_MM as RECORDING_RESIDUAL_MM
from .bounds import SCALE_TOLERANCE as SCALE_TOLERANCE
from .bounds import SENSOR_HEIGHT_MM as SENSOR_HEIGHT_MM
from .bounds import UNIT_NAMES as UNIT_NAMES
from .checks import (
    RecordingCheck,
    check_recording,
    check_session,
    check_tracking,
    recording_checks,
)
from .convention import (
    CONVENTIONS,
    MIRRORS,
    PivotCheck,
    convention_checks,
    convention_problems,
    pivot_residuals,
)
from .problems import PlausibilityError, PlausibilityWarning, Problem, enforce, unit_cause
from .problems import explaining_units as explaining_units
from .problems import fmt_mm as fmt_mm
from .units import SWAP_RATIO as SWAP_RATIO
from .units import (
    check_landmarks,
    check_model,
    check_recording_units,
    joint_reach_problems,
    landmark_scale,
)

__all__ = [
    "CONVENTIONS",
    "HAND_LENGTH_MM",
    "JOINT_REACH_MM",
    "MARGIN",
    "MIRRORS",
    "SEGMENT_FRACTION",
    "Bound",
    "PivotCheck",
    "PlausibilityError",
    "PlausibilityWarning",
    "Problem",
    "RecordingCheck",
    "check_landmarks",
    "check_model",
    "check_recording",
    "check_recording_units",
    "check_session",
    "check_tracking",
    "convention_checks",
    "convention_problems",
    "enforce",
    "finger_length_bound",
    "joint_reach_problems",
    "landmark_scale",
    "neighbour_bound",
    "pivot_residuals",
    "recording_checks",
    "segment_bound",
    "unit_cause",
]
