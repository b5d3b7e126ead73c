"""Reports: one self-contained HTML page for the directory of any run (``virtus report``).

* :mod:`virtus.report.runs` -- which kind of run a directory holds; refuses non-runs,
  half-finished and tampered runs (:func:`check_run`).
* :mod:`virtus.report.figures` -- matplotlib PNGs, one colour map and unit per quantity.
* :mod:`virtus.report.viewer` -- the offline WebGL point-cloud view and its still image.
* :mod:`virtus.report.html` -- page assembly (figures inlined, no network).
* :mod:`virtus.report.scan`, :mod:`~virtus.report.calibration`, :mod:`~virtus.report.others`
  -- the sections of each kind of run.
* :mod:`virtus.report.build` -- :func:`write_report`, the job.

Units as the figures label them: millimetres for lengths and errors, pixels, radians.
"""

from virtus.report.build import REPORT_FILE, Report, build_page, describe, write_report
from virtus.report.runs import KINDS, RunInfo, check_run

__all__ = [
    "KINDS",
    "REPORT_FILE",
    "Report",
    "RunInfo",
    "build_page",
    "check_run",
    "describe",
    "write_report",
]
