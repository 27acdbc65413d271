"""The individual hand model (five digits at most) and its file format ``fingerfit.model/1`` (JSON).

Everything geometric is stored in **tracker coordinates at the reference
posture, in mm** (and, for each joint, also in its parent sensor's frame),
with the reference sensor poses needed to compute angles. The file is
self-contained: :mod:`fingerfit.kinematics` needs nothing else.
See ``docs/formats.md`` and ``docs/conventions.md``.

:mod:`.hand` holds the model and its geometry, :mod:`.file` the JSON file; every name is
importable from here.
"""

from .file import FORMAT, MAX_MODEL_MM, load_model, model_to_dict, save_model
from .hand import (
    ANGLE_METHODS,
    PAD_FROM_TIP,
    PAD_SOURCES,
    VARIANTS,
    DigitModel,
    HandModel,
    JointModel,
    JointQuality,
    PinchContact,
    SegmentFrame,
    assemble_digit,
    estimated_pad,
    orthogonal_axis,
    orthogonal_second_axis,
    with_fixed_centres,
)
from .tracking import AngleRange, SensorSpread, TrackingStats

__all__ = [
    "ANGLE_METHODS",
    "FORMAT",
    "MAX_MODEL_MM",
    "PAD_FROM_TIP",
    "PAD_SOURCES",
    "VARIANTS",
    "AngleRange",
    "DigitModel",
    "HandModel",
    "JointModel",
    "JointQuality",
    "PinchContact",
    "SegmentFrame",
    "SensorSpread",
    "TrackingStats",
    "assemble_digit",
    "estimated_pad",
    "load_model",
    "model_to_dict",
    "orthogonal_axis",
    "orthogonal_second_axis",
    "save_model",
    "with_fixed_centres",
]
