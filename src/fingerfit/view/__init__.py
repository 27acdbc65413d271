"""The person's fitted hand, frame by frame, in the Rerun viewer (``fingerfit view``).

:func:`hand_scene` computes, with NumPy over the whole recording, everything the view
shows of the person: the joint centres and axes carried through the model's chain (the
same turns that move the tips in :mod:`fingerfit.kinematics`), the tips and pads of both
model variants, the joint angles and the sensors. :func:`robot_scene` poses a robot hand
by the retarget of the same frames. :func:`log_scene` sends it all to a Rerun recording
stream, each entity as whole columns (``send_columns``), on the time lines ``frame``
(0-based) and ``time`` (s, the recording's own).

Units and frames (``docs/view.md``): millimetres in the tracker frame, as everywhere in
fingerfit (``docs/conventions.md``); the robot is placed beside the person in the
person's palm frame and moves with the hand. Rerun (the extra ``view``) is imported by
:func:`require_rerun` only.

Modules: :mod:`.scene` (what the view shows, computed over whole recordings),
:mod:`.rerunlog` (the scene into a Rerun stream or ``.rrd``), :mod:`.live` (the view of a
live stream, logged by a process of its own); every name is importable from here.
:mod:`.evidence` (``capture --view``: the capture's evidence, logged by its evidence
process), :mod:`.webserve` (``--web``: the web viewer to the browser from ``127.0.0.1`` with a
Content-Security-Policy) and :mod:`.webshot` (a screenshot of it in headless Chromium)
are imported by their own names.
"""

from __future__ import annotations

from .live import (
    FILE_BATCH_FRAMES as FILE_BATCH_FRAMES,
)
from .live import (
    VIEW_NICE as VIEW_NICE,
)
from .live import (
    VIEW_QUEUE_BLOCKS as VIEW_QUEUE_BLOCKS,
)
from .live import (
    LiveView as LiveView,
)
from .live import (
    RobotSpec as RobotSpec,
)
from .rerunlog import (
    _arrows as _arrows,
)
from .rerunlog import (
    _indexes as _indexes,
)
from .rerunlog import (
    _padded as _padded,
)
from .rerunlog import (
    _points as _points,
)
from .rerunlog import (
    _static as _static,
)
from .rerunlog import (
    _strips as _strips,
)
from .rerunlog import (
    _truth_digits as _truth_digits,
)
from .rerunlog import (
    blueprint as blueprint,
)
from .rerunlog import (
    close_view as close_view,
)
from .rerunlog import (
    log_frames as log_frames,
)
from .rerunlog import (
    log_robot_frames as log_robot_frames,
)
from .rerunlog import (
    log_robot_static as log_robot_static,
)
from .rerunlog import (
    log_scene as log_scene,
)
from .rerunlog import (
    log_static as log_static,
)
from .rerunlog import (
    new_stream as new_stream,
)
from .rerunlog import (
    open_view as open_view,
)
from .rerunlog import (
    save_rrd as save_rrd,
)
from .scene import (
    _COLOURS as _COLOURS,
)
from .scene import (
    _SENSOR_AXIS_COLOURS as _SENSOR_AXIS_COLOURS,
)
from .scene import (
    APPLICATION_ID as APPLICATION_ID,
)
from .scene import (
    AXIS_ARROW_MM as AXIS_ARROW_MM,
)
from .scene import (
    EXTRA as EXTRA,
)
from .scene import (
    NO_ANALYTICS_ENV as NO_ANALYTICS_ENV,
)
from .scene import (
    ROBOT_OFFSET_MM as ROBOT_OFFSET_MM,
)
from .scene import (
    SENSOR_AXIS_MM as SENSOR_AXIS_MM,
)
from .scene import (
    RobotPlacement as RobotPlacement,
)
from .scene import (
    RobotScene as RobotScene,
)
from .scene import (
    Scene as Scene,
)
from .scene import (
    _carry as _carry,
)
from .scene import (
    hand_scene as hand_scene,
)
from .scene import (
    has_display as has_display,
)
from .scene import (
    no_usage_reporting as no_usage_reporting,
)
from .scene import (
    require_rerun as require_rerun,
)
from .scene import (
    robot_scene as robot_scene,
)
from .scene import (
    truth_tips as truth_tips,
)
