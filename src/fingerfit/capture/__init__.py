"""Guided capture: a protocol recording taken into a session folder, with the evidence
the fit needs shown per joint while it is recorded (``fingerfit capture``).

Modules: :mod:`.protocols` (what each protocol records and shows), :mod:`.folder` (the
session folder: every check before the source opens, the files written together after),
:mod:`.recorder` (the recorder every protocol shares: frames kept as they arrive, the
evidence computed beside them in a child process), :mod:`.table` (the evidence
table). The evidence itself is the fit's: :mod:`fingerfit.estimate.evidence`.
"""

from ..estimate.evidence import JointEvidence as JointEvidence
from ..estimate.evidence import evidence as evidence
from ..estimate.evidence import thresholds as thresholds
from .folder import CapturePlan as CapturePlan
from .folder import check_sensors as check_sensors
from .folder import plan_capture as plan_capture
from .folder import write_capture as write_capture
from .protocols import PROTOCOLS as PROTOCOLS
from .protocols import RECORDING_LIST as RECORDING_LIST
from .recorder import UPDATE_S as UPDATE_S
from .recorder import Accumulator as Accumulator
from .recorder import EvidenceProcess as EvidenceProcess
from .recorder import record as record
from .table import NUMERIC_COLUMNS as NUMERIC_COLUMNS
from .table import TABLE_COLUMNS as TABLE_COLUMNS
from .table import markdown_table as markdown_table
from .table import table_cells as table_cells
from .table import table_title as table_title
