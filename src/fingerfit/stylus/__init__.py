"""The stylus: its pivot calibration (:mod:`.pivot`), its file (:mod:`.file`) and the
landmarks it digitises (:mod:`.landmarks`). See ``docs/lab.md``."""

from .file import STYLUS_FORMAT as STYLUS_FORMAT
from .file import StylusCalibration as StylusCalibration
from .file import read_stylus as read_stylus
from .file import write_stylus as write_stylus
from .pivot import MAX_TIP_CI_MM as MAX_TIP_CI_MM
from .pivot import PivotFit as PivotFit
from .pivot import fit_pivot as fit_pivot
