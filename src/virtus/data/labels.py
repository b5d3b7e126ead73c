"""The arrays of one sample: frames and exact labels from the capture's ground truth.

Labels are computed from :class:`virtus.groundtruth.GroundTruth` (the surface seen through
each camera pixel centre and its exact projector coordinates), never by decoding the
frames. Every array of a sample, by name (``H x W`` camera pixels indexed ``[row, col]``;
per-direction labels stack the directions ``(v, h)`` on their first axis: index 0 is
vertical fringes (along ``u_p``), index 1 horizontal fringes (along ``v_p``))::

    frames       (F, H, W)  uint8|uint16  digital numbers, sequence order; frames past the
                                          sample's own count (``n_frames``) are 0
    depth        (H, W)     real  m       z along the camera axis; NaN: no surface
    points       (H, W, 3)  real  m       camera frame (OpenCV); NaN: no surface
    normals      (H, W, 3)  real          unit, camera frame, toward the camera
    proj_uv      (H, W, 2)  real  px      projector (u_p, v_p), pixel-centre convention;
                                          finite wherever the point is in front of the
                                          projector (also in shadow / outside its image)
    phase        (2, H, W)  real  rad     absolute phase 2 pi w / T of the direction's
                                          finest period T (w = scale * u_p, pattern units)
    wrapped      (2, H, W)  real  rad     phase wrapped to [-pi, pi)
    order        (2, H, W)  int32         fringe order k = (phase - wrapped) / 2 pi,
                                          i.e. floor(w / T + 1/2); -1 where invalid
    numerator    (2, H, W)  real  DN      (N/2) B sin(wrapped)   } atan2(numerator,
    denominator  (2, H, W)  real  DN      (N/2) B cos(wrapped)   } denominator) = wrapped
    modulation   (2, H, W)  real  DN      B of the finest phase set, least squares over
                                          its N frames (a property of the images)
    masks        (6, H, W)  bool          :data:`MASKS`: valid (hit, lit by the projector,
                                          inside its image), hit, shadow, outside,
                                          multibounce (ground truth), saturated (some frame
                                          of the sample at full scale)
    object_id    (H, W)     uint16        1-based index into the sample's object table;
                                          0: no surface

``real`` is the store's ``label_dtype`` (float32 by default). The phase labels, the fringe
order and numerator/denominator are NaN (order -1) outside the valid mask and for a
direction the sample's sequence does not have. ``numerator``/``denominator`` use the exact
wrapped phase and the measured modulation ``B`` (the amplitude a network sees), in the
sign convention of :mod:`virtus.phase`: ``I_n = A + B cos(phi + 2 pi n / N)`` gives
``-sum I_n sin(2 pi n/N) = (N/2) B sin(phi)`` and ``sum I_n cos(2 pi n/N) = (N/2) B cos(phi)``.
Each stacked array records its channel names (``ArraySpec.channels``) in ``dataset.json``
and in its Zarr attributes.

``object_id`` is exact for spheres, boxes, planes and boards (the surface within
:data:`OBJECT_TOLERANCE_M` of the point); a point on a mesh object is attributed to the
mesh whose bounding box holds it (two meshes with overlapping boxes: the nearer centre).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus import phase as _phase
from virtus.data.sampling import ObjectRecord, SampleSpec
from virtus.transforms import Pose

__all__ = [
    "DIRECTIONS",
    "DIRECTION_LABELS",
    "MASKS",
    "OBJECT_TOLERANCE_M",
    "ArraySpec",
    "array_layout",
    "sample_arrays",
    "sample_checksum",
]

#: Labels made per fringe direction, stacked (v, h) on their first axis.
DIRECTION_LABELS = ("phase", "wrapped", "order", "numerator", "denominator", "modulation")
#: Channels of those labels.
DIRECTIONS = ("v", "h")
#: Channels of the ``masks`` array.
MASKS = ("valid", "hit", "shadow", "outside", "multibounce", "saturated")
#: A point within this distance of an analytic surface belongs to it (metres): Mitsuba
#: intersects in float32 (~1e-7 relative at 1 m); surfaces of different objects that come
#: this close are indistinguishable anyway.
OBJECT_TOLERANCE_M = 5e-4
#: Camera rows per block when the modulation is computed (keeps its float64 copies of
#: the frames small instead of a (N, H, W) float64 copy: 133 MB at 960 x 960, N = 18).
_BLOCK_ROWS = 32
#: The "distance" of a point inside a mesh object's bounding box: analytic surfaces nearer
#: than this win over it.
_MESH_BOX_DISTANCE_M = 2e-4


@dataclass(frozen=True)
class ArraySpec:
    """One per-sample array of a store.

    Attributes
    ----------
    name : array name (module docstring).
    shape : per-sample shape (the store adds the sample axis in front).
    dtype : numpy dtype name.
    unit : ``"m"``, ``"rad"``, ``"px"``, ``"DN"`` or ``""``.
    fill : value of unwritten / invalid entries.
    channels : names along the first per-sample axis of a stacked array (``DIRECTIONS``,
        ``MASKS``), else empty.
    """

    name: str
    shape: tuple[int, ...]
    dtype: str
    unit: str
    fill: Any
    channels: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        fill = self.fill
        if isinstance(fill, float) and np.isnan(fill):
            fill = "NaN"
        return {
            "name": self.name,
            "shape": list(self.shape),
            "dtype": self.dtype,
            "unit": self.unit,
            "fill": fill,
            "channels": list(self.channels),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> ArraySpec:
        fill = float("nan") if data["fill"] == "NaN" else data["fill"]
        return cls(
            data["name"], tuple(data["shape"]), data["dtype"], data["unit"], fill,
            tuple(data.get("channels", ())),
        )  # fmt: skip

    @property
    def nbytes(self) -> int:
        """Bytes of one sample's array."""
        return int(np.prod(self.shape)) * np.dtype(self.dtype).itemsize


def array_layout(
    frames: int, height: int, width: int, bit_depth: int, label_dtype: str
) -> tuple[ArraySpec, ...]:
    """The arrays of every sample of a store (module docstring), in checksum order.

    Parameters
    ----------
    frames : the frame axis length (the longest candidate sequence).
    height, width : camera image size, px.
    bit_depth : largest sensor bit depth (8: uint8 frames, else uint16).
    label_dtype : ``"float32"`` or ``"float64"``.
    """
    nan = float("nan")
    real = label_dtype
    image = (height, width)
    specs = [
        ArraySpec("frames", (frames, *image), "uint8" if bit_depth == 8 else "uint16", "DN", 0),
        ArraySpec("depth", image, real, "m", nan),
        ArraySpec("points", (*image, 3), real, "m", nan),
        ArraySpec("normals", (*image, 3), real, "", nan),
        ArraySpec("proj_uv", (*image, 2), real, "px", nan),
    ]
    units = {"phase": "rad", "wrapped": "rad"}
    for label in DIRECTION_LABELS:
        if label == "order":
            specs.append(ArraySpec("order", (2, *image), "int32", "", -1, DIRECTIONS))
        else:
            unit = units.get(label, "DN")
            specs.append(ArraySpec(label, (2, *image), real, unit, nan, DIRECTIONS))
    specs.append(ArraySpec("masks", (len(MASKS), *image), "bool", "", False, MASKS))
    specs.append(ArraySpec("object_id", image, "uint16", "", 0))
    return tuple(specs)


def _finest_phase_frames(sequence: Any, direction: str) -> tuple[list[int], Any]:
    """Frame indices (step order) and coding of ``direction``'s finest phase set."""
    period = sequence.periods(direction)[0]
    frames = [
        (f.step, i)
        for i, f in enumerate(sequence.frames)
        if f.kind == "phase" and f.direction == direction and f.period == period
    ]
    indices = [i for _, i in sorted(frames)]
    return indices, sequence.frames[indices[0]].coding()


def _direction_labels(
    sequence: Any, frames: np.ndarray, proj_uv: np.ndarray, valid: np.ndarray, direction: str
) -> dict[str, np.ndarray]:
    """The :data:`DIRECTION_LABELS` of one direction (float64 / int32), invalid filled."""
    axis = 0 if direction == "v" else 1
    period = sequence.periods(direction)[0]
    pattern = sequence.axis_scale(direction) * np.where(valid, proj_uv[..., axis], 0.0)
    absolute = _phase.coordinate_to_phase(pattern, period)
    wrapped = _phase.wrap(absolute)
    order = np.rint((absolute - wrapped) / _phase.TWO_PI)
    indices, coding = _finest_phase_frames(sequence, direction)
    modulation = np.empty(frames.shape[1:])
    for row in range(0, frames.shape[1], _BLOCK_ROWS):  # blocks: small float64 temporaries
        block = frames[indices, row : row + _BLOCK_ROWS]
        modulation[row : row + _BLOCK_ROWS] = coding.wrapped(block)[2]
    amplitude = 0.5 * coding.steps * modulation
    nan = np.nan
    return {
        "phase": np.where(valid, absolute, nan),
        "wrapped": np.where(valid, wrapped, nan),
        "order": np.where(valid, order, -1).astype(np.int32),
        "numerator": np.where(valid, amplitude * np.sin(wrapped), nan),
        "denominator": np.where(valid, amplitude * np.cos(wrapped), nan),
        "modulation": modulation,
    }


def _surface_distance(record: ObjectRecord, points: np.ndarray) -> np.ndarray:
    """(M,) distance (m) from world points (M, 3) to an object's surface (inf: not it)."""
    local = (points - record.pose.t) @ record.pose.R  # world -> object frame
    if record.type == "sphere":
        return np.abs(np.linalg.norm(local, axis=1) - record.size_m[0])
    if record.type in ("plane", "board"):
        half = 0.5 * np.asarray(record.size_m) + OBJECT_TOLERANCE_M
        inside = np.all(np.abs(local[:, :2]) <= half, axis=1)
        return np.where(inside, np.abs(local[:, 2]), np.inf)
    if record.type == "box":
        excess = np.abs(local) - 0.5 * np.asarray(record.size_m)
        outside = np.linalg.norm(np.maximum(excess, 0.0), axis=1)
        return np.abs(outside + np.minimum(excess.max(axis=1), 0.0))
    low, high = np.asarray(record.size_m[:3]), np.asarray(record.size_m[3:])
    margin = OBJECT_TOLERANCE_M
    inside = np.all((local >= low - margin) & (local <= high + margin), axis=1)
    # Overlapping boxes: the nearer box centre wins (by a hair, within the sentinel).
    nearness = np.linalg.norm(local - 0.5 * (low + high), axis=1) * 1e-6
    return np.where(inside, _MESH_BOX_DISTANCE_M + nearness, np.inf)


def object_ids(objects: tuple[ObjectRecord, ...], points_world: np.ndarray) -> np.ndarray:
    """(H, W) uint16 object id of each surface point (0: none) from (H, W, 3) world points."""
    shape = points_world.shape[:2]
    out = np.zeros(shape, dtype=np.uint16)
    hit = np.isfinite(points_world).all(axis=-1)
    if not objects or not hit.any():
        return out
    pts = points_world[hit]
    distances = np.stack([_surface_distance(o, pts) for o in objects])
    best = np.argmin(distances, axis=0)
    close = distances[best, np.arange(pts.shape[0])] <= OBJECT_TOLERANCE_M
    ids = np.array([o.id for o in objects], dtype=np.uint16)
    out[hit] = np.where(close, ids[best], 0)
    return out


def sample_arrays(
    capture: Any, spec: SampleSpec, layout: tuple[ArraySpec, ...]
) -> dict[str, np.ndarray]:
    """Every array of one sample (module docstring), cast to the layout's dtypes.

    Parameters
    ----------
    capture : the sample's :class:`virtus.capture.Capture` (with ground truth).
    spec : its specification (objects, cam2world).
    layout : the store's arrays (:func:`array_layout`).

    Returns
    -------
    dict name -> array of the layout's per-sample shape and dtype.
    """
    gt = capture.ground_truth
    frames = capture.frames
    sequence = capture.sequence
    valid = gt.mask
    masks = {
        "valid": valid,
        "hit": gt.mask_hit,
        "shadow": gt.mask_shadow,
        "outside": gt.mask_outside,
        "multibounce": gt.mask_multibounce,
        "saturated": (frames >= capture.full_scale).any(axis=0),
    }
    labels: dict[str, np.ndarray] = {
        "depth": gt.depth,
        "points": gt.points,
        "normals": gt.normals,
        "proj_uv": gt.proj_uv,
        "masks": np.stack([masks[name] for name in MASKS]),
    }
    specs = {array.name: array for array in layout}
    for name in DIRECTION_LABELS:
        labels[name] = np.full(specs[name].shape, specs[name].fill, dtype=specs[name].dtype)
    for direction in sequence.directions:
        values = _direction_labels(sequence, frames, gt.proj_uv, valid, direction)
        for name, value in values.items():
            labels[name][DIRECTIONS.index(direction)] = value
    points_world = gt.points
    if spec.cam2world != Pose.identity():
        points_world = spec.cam2world.apply(gt.points.reshape(-1, 3)).reshape(gt.points.shape)
    labels["object_id"] = object_ids(spec.objects, points_world)
    frames_out = np.zeros(specs["frames"].shape, dtype=specs["frames"].dtype)
    frames_out[: frames.shape[0]] = frames
    labels["frames"] = frames_out
    return {
        array.name: np.ascontiguousarray(labels[array.name], dtype=array.dtype) for array in layout
    }


def sample_checksum(arrays: dict[str, np.ndarray], layout: tuple[ArraySpec, ...]) -> str:
    """``"sha256:<hex>"`` of a sample's arrays: name, dtype, shape and C-order bytes of each,
    in layout order (what :func:`virtus.data.store.DatasetStore.verify` recomputes)."""
    digest = hashlib.sha256()
    for array in layout:
        value = np.ascontiguousarray(arrays[array.name])
        digest.update(f"{array.name}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return f"sha256:{digest.hexdigest()}"
