"""The seam: captures, rendered or imported, and the scan directory; never imports
:mod:`virtus.render`.

* :mod:`~virtus.capture.capture` -- ``Capture``: the frames of one pose and what decodes them.
* :mod:`~virtus.capture.groundtruth` -- per-pixel ground truth of a rendered pose.
* :mod:`~virtus.capture.scandir` -- the one owner of a scan directory's file names.
"""

from virtus.capture.capture import (
    Capture,
    bit_depth_of,
    capture_bytes,
    check_capture_bytes,
    import_capture,
    rendered_provenance,
)
from virtus.capture.groundtruth import (
    GroundTruth,
)

__all__ = [
    "Capture",
    "GroundTruth",
    "bit_depth_of",
    "capture_bytes",
    "check_capture_bytes",
    "import_capture",
    "rendered_provenance",
]
