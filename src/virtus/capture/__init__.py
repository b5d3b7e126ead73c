"""The seam: captures, rendered or imported, and the scan directory; never imports
:mod:`virtus.render`.

* :mod:`~virtus.capture.capture` -- ``Capture``: the frames of one pose and what decodes them.
* :mod:`~virtus.capture.groundtruth` -- per-pixel ground truth of a rendered pose.
* :mod:`~virtus.capture.scandir` -- the one owner of a scan directory: its files, what each
  holds, and the checksums that tie derived files to their inputs.
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
from virtus.capture.scandir import (
    DERIVED_FILES,
    SCAN_LAYOUT,
    check_points_current,
    frames_checksum,
    load_decoded,
    save_decoded,
    save_reconstruction,
)

__all__ = [
    "DERIVED_FILES",
    "SCAN_LAYOUT",
    "Capture",
    "GroundTruth",
    "bit_depth_of",
    "capture_bytes",
    "check_capture_bytes",
    "check_points_current",
    "frames_checksum",
    "import_capture",
    "load_decoded",
    "rendered_provenance",
    "save_decoded",
    "save_reconstruction",
]
