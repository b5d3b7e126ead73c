"""Plain-data formats and run directories; knows no domain type.

* :mod:`~virtus.io.safeio` -- guarded readers of every user file (JSON, YAML, .npy/.npz, sizes
  bounded first).
* :mod:`~virtus.io.npyfile` -- ``.npy``/``.npz`` headers parsed and bounded by virtus itself.
* :mod:`~virtus.io.safewrite` -- what a write may replace (regular files only, links never
  followed).
* :mod:`~virtus.io.jsonio` -- JSON written one way (numpy values, paths; atomic replace).
* :mod:`~virtus.io.images` -- camera image files (8-16-bit PNG/TIFF/BMP), natural sort.
* :mod:`~virtus.io.ply` -- binary PLY point clouds.
* :mod:`~virtus.io.runs` -- run ownership of output directories: lock, record, atomic files.
"""

from virtus.io.images import (
    frame_name,
    image_size,
    list_images,
    natural_key,
    pool_size,
    read_image,
    read_images,
    write_frames,
)
from virtus.io.jsonio import (
    json_default,
    write_json,
)
from virtus.io.ply import (
    PlyError,
    PointCloud,
    read_ply,
    write_ply,
)
from virtus.io.runs import (
    RunDirectory,
    atomic_write,
    atomic_write_files,
    canonical,
    claim_run,
    config_digest,
    directory_lock,
    file_digest,
    first_difference,
    json_text,
    write_json_atomic,
)
from virtus.io.safeio import (
    MAX_ARRAY_BYTES,
    MAX_CONFIG_BYTES,
    MAX_DEPTH,
    MAX_YAML_ALIASES,
    MAX_YAML_NODES,
    check_file,
    check_keys,
    closest_key,
    load_npy,
    load_npz,
    parse_json,
    parse_yaml,
    read_json,
    read_text,
    read_yaml,
)
from virtus.io.safewrite import check_replaceable

__all__ = [
    "MAX_ARRAY_BYTES",
    "MAX_CONFIG_BYTES",
    "MAX_DEPTH",
    "MAX_YAML_ALIASES",
    "MAX_YAML_NODES",
    "PlyError",
    "PointCloud",
    "RunDirectory",
    "atomic_write",
    "atomic_write_files",
    "canonical",
    "check_file",
    "check_keys",
    "check_replaceable",
    "claim_run",
    "closest_key",
    "config_digest",
    "directory_lock",
    "file_digest",
    "first_difference",
    "frame_name",
    "image_size",
    "json_default",
    "json_text",
    "list_images",
    "load_npy",
    "load_npz",
    "natural_key",
    "parse_json",
    "parse_yaml",
    "pool_size",
    "read_image",
    "read_images",
    "read_json",
    "read_ply",
    "read_text",
    "read_yaml",
    "write_frames",
    "write_json",
    "write_json_atomic",
    "write_ply",
]
