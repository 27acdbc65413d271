"""Tracking with the model: joint angles and fingertips from fewer sensors than phalanges.

The fitted axes, centres and segment lengths make a digit's sensor poses a function of its
joint angles; where a frame lacks a sensor (absent from the recording, a dropout, or left
out with ``--sensors``), the angles that best explain the sensors present are found by
weighted least squares (inverse kinematics), vectorised over frames
(``docs/tracking.md``):

* :mod:`.chains` -- the digits as chains of axes, posed for a batch of frames;
* :mod:`.solver` -- the cost and Levenberg-Marquardt per frame;
* :mod:`.smoother` -- the temporal prior over consecutive frames;
* :mod:`.packed` -- every frame's normal matrix as its upper triangle;
* :mod:`.weights` -- the cost's weights from the model's calibration statistics;
* :mod:`.statistics` -- those statistics, measured when the model is fitted;
* :mod:`.layout` -- which sensors determine which joints;
* :mod:`.recording` -- a whole recording (``fingerfit angles``);
* :mod:`.live` -- one frame at a time (``fingerfit stream``).
"""

from .layout import DigitLayout, check_layout
from .recording import DigitTrack, Tracked, select_sensors, track_recording
from .statistics import tracking_statistics
from .weights import TrackOptions

__all__ = [
    "DigitLayout",
    "DigitTrack",
    "TrackOptions",
    "Tracked",
    "check_layout",
    "select_sensors",
    "track_recording",
    "tracking_statistics",
]
