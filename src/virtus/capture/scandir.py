"""File names inside a scan directory (one place, so every command agrees).

A scan directory is a capture directory (the layout of ``virtus capture``: frames,
``capture.json`` with the rig, scene and sequence, ground truth) plus what the pipeline adds::

    DIR/decoded/phase_v.npy     (H, W) float64 absolute phase of vertical fringes, rad, NaN invalid
    DIR/decoded/phase_h.npy     (H, W) float64 absolute phase of horizontal fringes, rad
    DIR/decoded/proj_uv.npy     (H, W, 2) float64 projector coordinates (u_p, v_p), px
    DIR/decoded/mask.npy        (H, W) bool, decoded in every direction
    DIR/decoded/modulation.npy  (H, W) float64 fringe amplitude B, frame units
    DIR/decoded/flagged.npy     (H, W) bool, valid pixels whose fringe order looks wrong
    DIR/decoded/summary.json    valid and flagged shares, modulation percentiles
    DIR/decoded/source.json     the capture's SHA-256 and the decode options (written last:
                                decoded/ is stale when the checksum no longer matches)
    DIR/reconstruction/points.npy  (H, W, 3) float64 camera frame, metres, NaN invalid
    DIR/reconstruction/depth.npy   (H, W) float64 camera-frame z, metres, NaN invalid
    DIR/reconstruction/mask.npy    (H, W) bool, pixels with a point
    DIR/reconstruction/rig.json    the rig the points were triangulated with (rig schema)
    DIR/reconstruction/source.json the checksums of the capture, the rig and points.ply: a
                                   reconstruction of other inputs is stale
    DIR/points.ply              binary PLY, metres, camera frame, with normals
    DIR/evaluation.json         C2M, with the SHA-256 of the cloud it measured (``virtus evaluate``)
"""

from __future__ import annotations

DECODED_DIR = "decoded"
DECODED_FILES = ("phase_v", "phase_h", "proj_uv", "mask", "modulation", "flagged")
DECODE_SUMMARY = "summary.json"
DECODED_SOURCE = "source.json"
RECONSTRUCTION_DIR = "reconstruction"
POINTS_PLY = "points.ply"
EVALUATION_JSON = "evaluation.json"
