"""Sources of live frames: a recording replayed, a Polhemus Liberty, an LSL stream.

Every source yields :class:`Block` s: the frames that arrived together, as a
:class:`~fingerfit.session.Recording` (positions mm, rotations sensor -> tracker, the
same object the file readers return) with each frame's arrival time. Source specs:

* ``replay:FILE[@SPEED]`` -- a pose CSV as ``fingerfit angles`` reads it, played at its
  own rate (or ``SPEED`` times faster); each frame "arrives" at its due time;
* ``liberty:PORT[@BAUD]`` -- a Liberty on a serial port (:mod:`.liberty_serial`);
* ``lsl:NAME`` -- an LSL stream of type ``MoCap`` whose channels are labelled
  ``<sensor>.x|y|z`` (position, unit in the channel metadata) and
  ``<sensor>.qw|qx|qy|qz`` (quaternion, scalar first); for a model fitted from markers,
  marker positions ``<marker>_X|_Y|_Z`` or ``<marker>.x|y|z`` (:func:`.lsl.marker_layout`),
  and a replay a marker recording (:mod:`fingerfit.live.markers`).

The live sources survive an outage: a serial port that fails is reopened, an LSL stream
that goes away is looked for again, for up to ``reconnect`` s (``--reconnect``), with one
warning per outage; meanwhile they yield None, and the stream's watchdog marks the
silence.

Modules: :mod:`.common` (the block, counts, spec parsing, reconnect loop, replay),
:mod:`.liberty` (the serial Liberty), :mod:`.lsl` (an LSL stream); every name is
importable from here.
"""

from __future__ import annotations

from .common import (
    _CM_TO_MM as _CM_TO_MM,
)
from .common import (
    DEFAULT_RECONNECT_S as DEFAULT_RECONNECT_S,
)
from .common import (
    LIBERTY_RATE_HZ as LIBERTY_RATE_HZ,
)
from .common import (
    MAX_BLOCK as MAX_BLOCK,
)
from .common import (
    NO_DATA_SECONDS as NO_DATA_SECONDS,
)
from .common import (
    POLL_S as POLL_S,
)
from .common import (
    RECONNECT_BACKOFF_S as RECONNECT_BACKOFF_S,
)
from .common import (
    Block as Block,
)
from .common import (
    ReplaySource as ReplaySource,
)
from .common import (
    SourceStats as SourceStats,
)
from .common import (
    _number as _number,
)
from .common import (
    _recording as _recording,
)
from .common import (
    _retry as _retry,
)
from .common import (
    _stderr_warning as _stderr_warning,
)
from .common import (
    check_reconnect as check_reconnect,
)
from .common import (
    default_stations as default_stations,
)
from .common import (
    parse_liberty as parse_liberty,
)
from .common import (
    parse_replay as parse_replay,
)
from .common import (
    parse_stations as parse_stations,
)
from .common import (
    split_spec as split_spec,
)
from .liberty import (
    LibertySource as LibertySource,
)
from .lsl import (
    _QUAT as _QUAT,
)
from .lsl import (
    _UNIT_MM as _UNIT_MM,
)
from .lsl import (
    LSL_CONNECT_S as LSL_CONNECT_S,
)
from .lsl import (
    LSL_FORMATS as LSL_FORMATS,
)
from .lsl import (
    LslSource as LslSource,
)
from .lsl import (
    _format_name as _format_name,
)
from .lsl import (
    _lsl_lost_error as _lsl_lost_error,
)
from .lsl import (
    marker_layout as marker_layout,
)
from .lsl import (
    mocap_layout as mocap_layout,
)
