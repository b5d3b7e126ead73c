"""A sample's arrays made on the device that rendered it: the GPU path of dataset labels.

:func:`device_sample_arrays` is :func:`virtus.data.labels.sample_arrays` for a rendering
that stayed on the device (:class:`virtus.render.renderer.DeviceRendering`). The
pixel-centre ground truth (:class:`virtus.render.jit.tracing.DeviceTruth`), the phase labels,
the modulation, the masks and the object ids are computed where the frames are, in the
store's precision, and each array crosses to the host once, in its stored dtype, straight
into its slot of the shard buffer. On a GPU this takes the labels (about 0.2 CPU-seconds of
a 960 x 960 sample) and the float64 ground-truth copies off the host, whose cores are left
to checksum and compress. When the GPU compresses as well, the arrays are made in one
evaluation into a device shard buffer that the compressor reads, and copied from it into a
page-locked host buffer (``on_device``, :mod:`virtus.data.devicebuffers`).

The formulas are the host's, shared where they are not numpy-specific
(:func:`virtus.data.labels.surface_distance`, the decoder's
:func:`virtus.render.jit.decode.wrapped_phase_set` and
:func:`~virtus.render.jit.decode.wrap_phase`). On ``llvm_ad_rgb`` the same code runs on the
CPU, which is how the test suite checks it against :func:`sample_arrays`: masks, fringe
orders and object ids are equal, the float64 phase and geometry labels agree to the
stored precision, and the float32 modulation, numerator and denominator to float32
rounding (the device's ``sin``, ``cos`` and fused multiply-adds are not numpy's).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from virtus.data.devicebuffers import copy_to_host
from virtus.data.labels import (
    DIRECTION_LABELS,
    DIRECTIONS,
    MASKS,
    OBJECT_TOLERANCE_M,
    ArrayOps,
    ArraySpec,
    surface_distance,
)
from virtus.data.sampling import SampleSpec
from virtus.errors import VirtusError
from virtus.patterns import phase as _phase
from virtus.render.jit.decode import FrameReader, wrap_phase, wrapped_phase_set
from virtus.render.jit.tracing import flat_array, to_host

__all__ = ["device_sample_arrays"]


#: One array (or one channel of it) to be made on the device: (name, channel or None, the
#: device type it is converted to, its components (P,) each, whether they are stacked
#: component-major, :func:`virtus.render.jit.tracing.flat_array`).
_Copy = tuple[str, "int | None", Any, list[Any], bool]


def device_sample_arrays(
    rendering: Any,
    spec: SampleSpec,
    layout: tuple[ArraySpec, ...],
    out: dict[str, np.ndarray] | None = None,
    *,
    on_device: dict[str, Any] | None = None,
) -> dict[str, np.ndarray]:
    """Every array of one sample (:mod:`virtus.data.labels`), computed on the device.

    Parameters
    ----------
    rendering : the sample's :class:`~virtus.render.renderer.DeviceRendering` (traced with
        its ground truth: ``render_device`` keeps it).
    spec : its specification (scanner, objects, cam2world).
    layout : the store's arrays (:func:`virtus.data.labels.array_layout`).
    out : name -> writable host array of the layout's per-sample shape and dtype (e.g. one
        sample's slot of a shard buffer); every element is written. Default: new arrays.
    on_device : name -> torch tensor of the layout's per-sample shape on the rendering's
        device (one slot of a :func:`virtus.data.devicebuffers.device_shard_buffer`): the
        arrays are made there, in one evaluation, and each is then copied once into
        ``out``; they stay for the GPU compressor. None: each array is copied to the host
        as it is made.

    Returns
    -------
    ``out``.
    """
    trace, frames = rendering.trace, rendering.frames
    if trace.device_truth is None:
        raise VirtusError("device_sample_arrays needs a device trace with its ground truth")
    specs = {array.name: array for array in layout}
    if out is None:
        out = {a.name: np.empty(a.shape, dtype=a.dtype) for a in layout}
    mi, dr = trace.modules()
    real = mi.Float if specs["depth"].dtype == "float32" else mi.Float64
    truth = trace.device_truth()
    reader = FrameReader(mi, dr, frames.data, trace.n_pixels, specs["depth"].dtype)
    copies = _label_copies(mi, dr, real, reader, rendering, spec, truth)
    if on_device is not None:
        _make_on_device(mi, dr, copies, frames, specs, on_device)
        copy_to_host(on_device, out)
        return out
    frames_out = out["frames"]
    frames_out[: frames.n_frames] = frames.numpy()
    frames_out[frames.n_frames :] = 0
    for name in DIRECTION_LABELS:
        out[name].fill(specs[name].fill)
    for name, channel, kind, components, stacked in copies:
        target = out[name] if channel is None else out[name][channel]
        host = to_host(components, kind, stacked=stacked)
        np.copyto(target, host.reshape(target.shape), casting="unsafe")  # uint32 ids -> uint16
    return out


def _label_copies(
    mi: Any, dr: Any, real: Any, reader: FrameReader, rendering: Any, spec: SampleSpec,
    truth: Any,
) -> list[_Copy]:  # fmt: skip
    """Every array of a sample but the frames, as device arrays still to be evaluated (the
    direction labels only for the directions the sample's sequence has)."""
    trace, frames = rendering.trace, rendering.frames
    saturated = dr.full(mi.Bool, False, trace.n_pixels)
    for index in range(frames.n_frames):  # some frame at full scale (as the host's max)
        saturated |= reader.at_least(index, rendering.sensor.full_scale)
    planes = {
        "valid": truth.valid, "hit": truth.hit, "shadow": truth.shadow,
        "outside": truth.outside, "multibounce": trace.multibounce(), "saturated": saturated,
    }  # fmt: skip
    copies: list[_Copy] = [
        ("masks", None, mi.Bool, [planes[name] for name in MASKS], True),
        ("depth", None, real, [truth.points[2]], False),
        ("points", None, real, list(truth.points), False),
        ("normals", None, real, list(truth.normals), False),
        ("proj_uv", None, real, list(truth.proj_uv), False),
    ]
    sequence = spec.scanner.sequence
    for direction in sequence.directions:
        labels = _direction_labels(mi, dr, real, reader, sequence, truth, direction)
        channel = DIRECTIONS.index(direction)
        for name in DIRECTION_LABELS:
            kind = mi.Int32 if name == "order" else real
            copies.append((name, channel, kind, [labels[name]], False))
    copies.append(("object_id", None, mi.UInt32, [_object_ids(mi, dr, spec, truth)], False))
    return copies


def _make_on_device(
    mi: Any, dr: Any, copies: list[_Copy], frames: Any, specs: dict[str, ArraySpec],
    on_device: dict[str, Any],
) -> None:  # fmt: skip
    """Evaluate ``copies`` in one launch and write them, with the frames, into the torch
    tensors ``on_device`` (DLPack: no copy between Dr.Jit and torch). Masks cross as UInt8
    and 32-bit unsigned values as Int32 (torch's dtypes; the same bytes once narrowed)."""
    import torch

    as_torch = {mi.Bool: mi.UInt8, mi.UInt32: mi.Int32}
    flats = [
        flat_array(components, as_torch.get(kind, kind), stacked=stacked)
        for _, _, kind, components, stacked in copies
    ]
    stored = frames.data if dr.type_v(frames.data) == dr.VarType.UInt8 else mi.Int32(frames.data)
    dr.eval(stored, *flats)
    dr.sync_thread()  # torch reads them on its own stream
    frames_out = on_device["frames"]
    count = frames.n_frames
    frames_out[:count].copy_(torch.from_dlpack(stored).view(frames_out[:count].shape))
    frames_out[count:] = 0
    for name in DIRECTION_LABELS:
        on_device[name].fill_(specs[name].fill)
    for (name, channel, _, _, _), flat in zip(copies, flats, strict=True):
        target = on_device[name] if channel is None else on_device[name][channel]
        if target.dtype == torch.bool:
            target = target.view(torch.uint8)
        target.copy_(torch.from_dlpack(flat).view(target.shape))


def _direction_labels(
    mi: Any, dr: Any, real: Any, reader: FrameReader, sequence: Any, truth: Any, direction: str
) -> dict[str, Any]:
    """The :data:`DIRECTION_LABELS` of one direction as device arrays (as the host's
    ``_direction_labels``: phase, wrap and order in float64, the rest in ``real``)."""
    period = sequence.periods(direction)[0]
    scale = sequence.axis_scale(direction)
    finest = sequence.plan(direction).sets[0]  # the phase set of the finest period
    valid = truth.valid
    pattern = scale * truth.proj_uv[0 if direction == "v" else 1]  # pattern units
    absolute = pattern * (_phase.TWO_PI / period)  # phase.coordinate_to_phase
    wrapped = wrap_phase(dr, absolute)
    order = dr.round((absolute - wrapped) / _phase.TWO_PI)
    nan = float("nan")
    wrapped_out = dr.select(valid, real(wrapped), nan)
    _, _, modulation = wrapped_phase_set(reader, finest)
    amplitude = (0.5 * finest.coding.steps) * real(modulation)
    return {
        "phase": dr.select(valid, real(absolute), nan),
        "wrapped": wrapped_out,
        "order": dr.select(valid, mi.Int32(order), -1),
        "numerator": amplitude * dr.sin(wrapped_out),
        "denominator": amplitude * dr.cos(wrapped_out),
        "modulation": real(modulation),
    }


def _object_ids(mi: Any, dr: Any, spec: SampleSpec, truth: Any) -> Any:
    """UInt32 (P,) object id of each pixel's surface point, 0 for none (as
    :func:`virtus.data.labels.object_ids`: the nearest surface, the first on a tie)."""
    pixels = dr.width(truth.hit)
    ids = dr.zeros(mi.UInt32, pixels)
    if not spec.objects:
        return ids
    ops = ArrayOps.of(dr)
    x, y, z = truth.points
    nearest = None
    for record in spec.objects:
        pose = record.pose.inverse() @ spec.cam2world  # camera frame -> object frame
        R, t = pose.R, pose.t  # noqa: N806
        local = [x * float(R[i, 0]) + y * float(R[i, 1]) + z * float(R[i, 2]) + float(t[i])
                 for i in range(3)]  # fmt: skip
        distance = surface_distance(record, *local, ops)
        if nearest is None:
            nearest, ids = distance, dr.full(mi.UInt32, record.id, pixels)
            continue
        closer = distance < nearest
        ids = dr.select(closer, record.id, ids)
        nearest = dr.select(closer, distance, nearest)
    return dr.select(truth.hit & (nearest <= OBJECT_TOLERANCE_M), ids, 0)
