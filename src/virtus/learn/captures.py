"""A trained model on captures (rendered or real, ``virtus import``), against the multi-step
phase of the same capture -- the field's practice for real benches.

For each capture directory: the model sees the chosen input frame (the run's
``input_frame``); the reference is the capture's own full decode (every phase step and the
code frames: :meth:`virtus.capture.Capture.decode`), triangulated with the capture's
calibration through the same :class:`~virtus.learn.triangulate.DepthLayer`. A phase model's
wrapped phase is unwrapped with the reference's fringe order (what the capture's code frames
give), so its phase error at the wrap shows as order errors. Metrics
(:mod:`virtus.learn.metrics`) count every reference-valid pixel as "object": phase RMSE
(rad), fringe-order error rate and depth MAE/RMSE (mm) against the multi-step depth. The
first :data:`~virtus.learn.training.MAP_SAMPLES` captures' predicted, reference and error
depth maps (mm) are saved beside the metrics, as for a store (``virtus report`` draws them).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.data import input_frame_index
from virtus.errors import InputError
from virtus.io.runs import write_json_atomic
from virtus.learn._torch import require_torch
from virtus.learn.metrics import MetricSums, sample_errors, wrap_to_pi

__all__ = ["evaluate_captures"]


def _capture_record(capture: Any) -> dict[str, Any]:
    return {"sequence": capture.sequence.to_dict(), "n_frames": len(capture.sequence)}


def _one(
    config: Any, model: Any, capture: Any, directory: Path
) -> tuple[dict[str, Any], np.ndarray]:
    """The errors of one capture and its ``(3, H, W)`` float32 depth maps in mm (predicted,
    multi-step reference, their difference; NaN where the reference is invalid)."""
    torch = require_torch()
    from virtus.learn.triangulate import DepthLayer

    if capture.calibration_source and capture.calibration_source.get("calibrated") is False:
        raise InputError(
            "captures", "captures with a calibration (virtus import --calibration)", str(directory)
        )
    try:
        frame = input_frame_index(_capture_record(capture), config.input_frame, config.direction)
    except InputError as error:
        raise InputError(
            "captures",
            f"a sequence with the model's input frame ({config.input_frame})",
            f"{directory}: {error}",
        ) from None
    decoded = capture.decode()
    d = config.direction
    period, mask, phase = (getattr(decoded, f"{k}_{d}") for k in ("period", "mask", "phase"))
    if period is None:
        what = "vertical" if d == "v" else "horizontal"
        raise InputError("captures", f"a sequence with {what} phase-shift frames", str(directory))
    period_px = period / capture.sequence.axis_scale(d)
    layer = DepthLayer(capture.rig, d)
    ref_abs = np.where(mask, phase, np.nan)
    device = next(model.parameters()).device
    with torch.no_grad():
        ref_depth = layer.depth(torch.from_numpy(ref_abs * period_px / (2 * np.pi))).numpy()
        image = capture.frames[frame].astype(np.float32) / capture.full_scale
        out = model(torch.from_numpy(image)[None, None].to(device))[0].float().cpu()
    valid = mask & np.isfinite(ref_depth)
    extra: dict[str, Any] = {}
    if config.model == "unet":
        pred = (out[0] * config.depth_range_m + config.depth_offset_m).numpy().astype(np.float64)
    else:
        wrapped = np.arctan2(out[0].numpy(), out[1].numpy()).astype(np.float64)
        ref_wrapped = wrap_to_pi(ref_abs)
        order = np.where(valid, np.rint((ref_abs - ref_wrapped) / (2 * np.pi)), -1).astype(np.int64)
        absolute = wrapped + 2 * np.pi * np.maximum(order, 0)
        with torch.no_grad():
            pred = layer.depth(torch.from_numpy(absolute * period_px / (2 * np.pi))).numpy()
        pred_order = order + np.rint((absolute - np.nan_to_num(ref_abs)) / (2 * np.pi)).astype(
            np.int64
        )
        extra = {
            "pred_wrapped": wrapped,
            "wrapped": np.nan_to_num(ref_wrapped),
            "pred_order": pred_order,
            "order": order,
            "valid": valid,
        }
    depth = np.where(valid, ref_depth, 0.0)
    maps = np.stack([np.where(valid, pred, np.nan), np.where(valid, ref_depth, np.nan)])
    maps = (np.concatenate([maps, maps[:1] - maps[1:]]) * 1e3).astype(np.float32)
    return sample_errors(pred, depth, valid, valid, **extra), maps


def evaluate_captures(
    run_dir: str | Path,
    captures: list[str | Path],
    *,
    device: str | None = None,
    name: str = "captures",
) -> dict[str, Any]:
    """Metrics of a run's model on capture directories against their multi-step phase,
    written to ``RUN/evaluations/<name>.json`` (module docstring).

    Raises
    ------
    InputError : no capture given, a capture without a calibration, or one whose sequence
        lacks the model's input frame or the phase frames of its ``direction``.
    """
    from virtus.capture import Capture
    from virtus.learn.training import MAP_SAMPLES, load_model, write_maps

    if not captures:
        raise InputError("captures", "at least one capture directory", "none")
    config, model = load_model(run_dir, device)
    model.eval()
    sums = MetricSums()
    maps: list[tuple[int, np.ndarray]] = []
    for position, directory in enumerate(captures):
        capture = Capture.load(directory)
        errors, depth_maps = _one(config, model, capture, Path(directory))
        sums.add(errors)
        if position < MAP_SAMPLES:
            maps.append((position, depth_maps))
    summary = {
        "captures": [str(Path(c).resolve()) for c in captures],
        "reference": "multi-step phase of the same capture",
        **sums.summary(),
    }
    summary["maps"] = write_maps(Path(run_dir) / "evaluations", name, maps)
    write_json_atomic(Path(run_dir) / "evaluations" / f"{name}.json", summary)
    return summary
