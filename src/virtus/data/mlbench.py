"""Export a store in FPP-ML-Bench's layout, and the one rule that picks a sample's input frame.

FPP-ML-Bench (arXiv 2601.08900; github.com/AnushLak/fpp-ml-bench, MIT) trains single-shot
networks on pairs of one fringe image and one depth map. Its ``dataset.py`` reads::

    <out>/training_data_depth{variant}/{train,val,test}/fringe/<stem>.png   8-bit grey
    <out>/training_data_depth{variant}/{train,val,test}/depth/<stem>.mat    key 'depth'

paired by stem, with ``variant`` one of ``_raw``, ``_global_normalized`` (its loader divides
by 65535) and ``_individual_normalized`` (by each map's maximum). Its loader normalises at
load time, so the three trees hold the same files (hard links where the file system allows,
else copies): written once, readable by their four models unchanged with any
``--dataset_type``. Its masked losses take ``depth > 0`` as the object, so a pixel without a
surface is 0.

What is written (all from the store's complete samples; stems are zero-padded sample
indices; splits are the store's, which are by object -- see :mod:`virtus.data.sampling`)::

    fringe/<stem>.png     (H, W) uint8   the chosen input frame; a uint16 store is scaled
                                         by 255 / (2**bit_depth - 1) and rounded
    depth/<stem>.mat      (H, W) float32 'depth', millimetres (their scale: 1.5-2.1 m is
                                         1500-2100, below 65535), 0 where no surface
    calibration/<split>/<stem>.json      the sample's rig (DESIGN section 3 schema), cam2world,
                                         sequence, sensor, projector, objects, the input
                                         frame index and its period in projector px
    export.json                          what was exported and how (units, frame rule)

Every sample is checked against its checksum as it is read; a damaged one stops the export
and nothing is written (everything is staged inside ``out`` and moved into place at the
end). Same store, same options -> the same bytes (the MAT header's creation time is fixed).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from virtus.data.store import DatasetStore
from virtus.errors import InputError

__all__ = [
    "MLBENCH_VARIANTS",
    "export_fpp_ml_bench",
    "input_frame_index",
    "mat_bytes",
]

#: FPP-ML-Bench's depth normalisation variants (their ``--dataset_type``).
MLBENCH_VARIANTS = ("_raw", "_global_normalized", "_individual_normalized")
#: The exported depth unit: their maps are millimetres (global normalisation by 65535).
DEPTH_SCALE_MM_PER_M = 1000.0
#: A fixed MAT-file header text (scipy writes the creation time there; the export is
#: byte-reproducible instead). 116 bytes, space padded, as MATLAB's level-5 format wants.
_MAT_HEADER = b"MATLAB 5.0 MAT-file, written by virtus (fpp-ml-bench export)".ljust(116)


def input_frame_index(
    record: dict[str, Any], frame: int | str = "auto", direction: str = "v"
) -> int:
    """The index of a sample's single-shot input frame in its sequence.

    Parameters
    ----------
    record : the sample's record (its ``sequence`` and ``n_frames``).
    frame : ``"auto"`` -- the first phase step of the finest vertical-fringe set (the
        frame FPP-ML-Bench's single-shot input corresponds to) -- or a frame index.
    direction : the fringe direction ``"auto"`` looks for (``"h"``: horizontal fringes,
        for rigs whose baseline is vertical).

    Raises
    ------
    InputError : the sequence has no phase frame of ``direction`` (``"auto"``), or the index is not
        a frame of this sample's sequence (named ``frame``).
    """
    frames = record["sequence"]["frames"]
    n_frames = int(record.get("n_frames", len(frames)))
    if frame == "auto":
        phase = [f for f in frames if f.get("kind") == "phase" and f.get("direction") == direction]
        if not phase:
            what = "vertical" if direction == "v" else "horizontal"
            raise InputError("frame", f"a sequence with {what} phase frames", "none")
        finest = min(float(f["period"]) for f in phase)
        first = [f for f in phase if float(f["period"]) == finest and int(f["step"]) == 1]
        return int((first or phase)[0]["index"])
    if isinstance(frame, bool) or not isinstance(frame, int | np.integer):
        raise InputError("frame", "'auto' or a frame index", frame)
    if not 0 <= int(frame) < n_frames:
        raise InputError(
            "frame", f"a frame of the sample's {n_frames}-frame sequence (0..{n_frames - 1})", frame
        )
    return int(frame)


def mat_bytes(depth_mm: np.ndarray) -> bytes:
    """A MATLAB level-5 file holding ``depth`` (float32), with a fixed header."""
    from scipy.io import savemat

    buffer = io.BytesIO()
    savemat(buffer, {"depth": np.ascontiguousarray(depth_mm, dtype=np.float32)})
    data = bytearray(buffer.getvalue())
    data[:116] = _MAT_HEADER
    return bytes(data)


def _png_bytes(image: np.ndarray) -> bytes:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(image, mode="L").save(buffer, format="PNG", optimize=False)
    return buffer.getvalue()


def _fringe_u8(frame: np.ndarray, bit_depth: int) -> np.ndarray:
    if frame.dtype == np.uint8:
        return frame
    full = float(2**bit_depth - 1)
    return np.clip(np.rint(frame.astype(np.float64) * (255.0 / full)), 0, 255).astype(np.uint8)


def _calibration(record: dict[str, Any], index: int, frame: int) -> dict[str, Any]:
    from virtus.patterns import PatternSequence

    sequence = PatternSequence.from_dict(record["sequence"])
    info = record["sequence"]["frames"][frame]
    direction = info.get("direction")
    period_px = None
    if info.get("kind") == "phase" and direction:
        period_px = float(info["period"]) / sequence.axis_scale(direction)
    keep = ("split", "seed", "rig", "cam2world", "sequence", "sensor", "projector", "objects")
    return {
        "format": "virtus.fpp_ml_bench_sample/1",
        "index": index,
        "input_frame": {"index": frame, **info, "period_px": period_px},
        "depth_unit": "mm",
        **{key: record[key] for key in keep if key in record},
    }


def _link_or_copy(source: Path, target: Path) -> None:
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def export_fpp_ml_bench(
    store_path: str | Path,
    out_dir: str | Path,
    *,
    frame: int | str = "auto",
    variants: tuple[str, ...] = MLBENCH_VARIANTS,
) -> dict[str, Any]:
    """Write the store's complete samples in FPP-ML-Bench's layout (module docstring).

    Parameters
    ----------
    store_path : the store.
    out_dir : folder to write into (created); it must not hold the export's trees yet.
    frame : the input frame, ``"auto"`` or an index (:func:`input_frame_index`).
    variants : which of :data:`MLBENCH_VARIANTS` trees to write (same files in each).

    Returns
    -------
    The summary written to ``export.json``: samples per split, variants, frame rule.

    Raises
    ------
    InputError : a bad argument, a store without ``frames`` or ``depth``, an output folder
        that already holds an export, a frame index outside a sample's sequence.
    DamagedSample : a sample does not read back intact (nothing is written).
    """
    if not variants or any(v not in MLBENCH_VARIANTS for v in variants):
        raise InputError("variants", f"names among {list(MLBENCH_VARIANTS)}", list(variants))
    store = DatasetStore.open(store_path)
    known = [a.name for a in store.layout]
    if "frames" not in known or "depth" not in known:
        raise InputError("store", "a store with frames and depth", known)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("out", "a folder for the export", f"a file {out}")
    names = [f"training_data_depth{v}" for v in variants] + ["calibration", "export.json"]
    taken = [n for n in names if (out / n).exists()]
    if taken:
        raise InputError("out", "a folder without an earlier export", f"{out} holds {taken[0]}")
    samples = store.samples()
    indices = {i: input_frame_index(m, frame) for i, m in samples.items()}
    made = not out.exists()
    out.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".virtus-export-", dir=out))
    try:
        counts = _write_trees(store, samples, indices, staging, variants)
        summary = {
            "format": "virtus.fpp_ml_bench_export/1",
            "source": "https://github.com/AnushLak/fpp-ml-bench (dataset.py layout)",
            "store": str(Path(store_path).resolve()),
            "frame": frame,
            "variants": list(variants),
            "depth": "float32 millimetres, key 'depth', 0 where no surface",
            "fringe": "uint8 grey PNG, the input frame",
            "samples": counts,
        }
        (staging / "export.json").write_text(json.dumps(summary, indent=2) + "\n")
        for name in names:
            os.replace(staging / name, out / name)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    shutil.rmtree(staging, ignore_errors=True)
    return summary


def _write_trees(
    store: DatasetStore,
    samples: dict[int, dict[str, Any]],
    indices: dict[int, int],
    staging: Path,
    variants: tuple[str, ...],
) -> dict[str, int]:
    first, *others = (staging / f"training_data_depth{v}" for v in variants)
    (staging / "calibration").mkdir()
    counts: dict[str, int] = {}
    for index, meta in samples.items():
        split = meta["split"]
        data = store.read_sample(index, ("frames", "depth"), checksum=meta["checksum"])
        stem = f"{index:06d}"
        fringe = _fringe_u8(data["frames"][indices[index]], int(meta.get("bit_depth", 8)))
        depth = np.nan_to_num(data["depth"].astype(np.float64) * DEPTH_SCALE_MM_PER_M, nan=0.0)
        files = {
            Path(split, "fringe", f"{stem}.png"): _png_bytes(fringe),
            Path(split, "depth", f"{stem}.mat"): mat_bytes(depth),
        }
        for relative, payload in files.items():
            (first / relative).parent.mkdir(parents=True, exist_ok=True)
            (first / relative).write_bytes(payload)
            for tree in others:
                (tree / relative).parent.mkdir(parents=True, exist_ok=True)
                _link_or_copy(first / relative, tree / relative)
        calibration = staging / "calibration" / split / f"{stem}.json"
        calibration.parent.mkdir(parents=True, exist_ok=True)
        calibration.write_text(
            json.dumps(_calibration(meta, index, indices[index]), indent=1) + "\n"
        )
        counts[split] = counts.get(split, 0) + 1
    for tree in (first, *others):  # their layout has all three splits, even if empty
        for split in ("train", "val", "test"):
            for kind in ("fringe", "depth"):
                (tree / split / kind).mkdir(parents=True, exist_ok=True)
    return counts
