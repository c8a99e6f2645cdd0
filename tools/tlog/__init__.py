"""flowgap-tlog: analyse MAVLink telemetry logs (.tlog) from flowgap, PX4 or ArduPilot flights.

Library API: :func:`analyse_tlog` (→ :class:`Report`), :func:`write_outputs`, :func:`summary_text`;
console entry :func:`main` (``flowgap-tlog``). Module map: ``framing`` (fast packet scan, CRC, numpy
payload decoding), ``analysis`` (metrics), ``truth`` (truth sources, tracking error), ``plots``, ``output``
(report.md, metrics.json, CSV), ``cli``.
"""

from tools.tlog.analysis import Report, analyse_tlog
from tools.tlog.cli import main
from tools.tlog.output import summary_text, write_outputs
from tools.tlog.truth import TRUTH_SOURCES, TruthSource

__all__ = ["TRUTH_SOURCES", "Report", "TruthSource", "analyse_tlog", "main", "summary_text", "write_outputs"]
