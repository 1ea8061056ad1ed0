"""``companion replay``: recorded flights (.tlog) re-run and measured (pure cores).

- ``run``: a whole replay over a file's byte chunks (``replay_chunks``, ``find_setup``);
- ``session``: the record-by-record driver of a ``FlightCore`` and the comparison;
- ``compare``: computed vs recorded outputs, field by field;
- ``metrics``: flight metrics from a recording alone (any MAVLink log);
- ``rebuild``: the recorded flight's core from its setup record.
"""

from .compare import OutputComparer
from .metrics import REPLAN_PREFIX, FlightMetrics, MetricsAccumulator, TrackingMetrics
from .rebuild import SetupCollector, build_core, runner_config, setup_mismatches
from .run import ReplayResult, find_setup, replay_chunks
from .session import Comparison, Divergence, ReplaySession

__all__ = ["Comparison", "Divergence", "FlightMetrics", "MetricsAccumulator", "OutputComparer", "REPLAN_PREFIX",
           "ReplayResult", "ReplaySession", "SetupCollector", "TrackingMetrics", "build_core", "find_setup",
           "replay_chunks", "runner_config", "setup_mismatches"]
