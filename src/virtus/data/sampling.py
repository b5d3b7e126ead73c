"""Domain randomisation: what sample ``i`` of a dataset shows, from ``(seed, i, config)`` only.

:class:`Randomiser` turns a :class:`~virtus.data.config.DatasetConfig` into one
:class:`SampleSpec` per sample index: a :class:`~virtus.scanner.Scanner` (rig, sensor,
projector model, fringe sequence), a :class:`~virtus.scene.model.Scene` (objects, materials,
planes or a board, ambient light), ``cam2world``, the capture's noise seed, its split and
a table of its objects.

Determinism. Every random draw comes from a ``numpy`` generator seeded with
``SeedSequence([seed, stream, ...])``: the *group* stream (``[seed, 1, group]``) draws the
split, the scanner settings, the objects and their materials, the *instance* stream
(``[seed, 2, source, k]``) the shape of object instance ``k`` of a source, the *shuffle*
stream (``[seed, 4, source]``) which instances of a source go to which split, and the
*capture* stream (``[seed, 3, i]``) the sensor-noise seed. Nothing depends on the number of
samples, the worker that renders the sample or the order of rendering.

Groups. Samples that must share objects form a group: in ``scan`` mode the
``turntable.views`` consecutive views of one object (``group = i // views``), in
``ablation`` mode the ``materials x ambients`` cells of one object set
(``group = i // cells``); otherwise every sample is its own group.

Splits by object. Each object instance (``(source, k)``: a procedural shape with fixed
parameters, or one mesh file) belongs to one split: a source's instances are shuffled and
cut by the configured fractions (:func:`split_counts`). A group draws its split with the
same fractions, then draws its objects only from instances of that split, so no object of
the test split is ever seen in training. Calibration samples have no objects: they are
split by sample.

Frames: the world frame is the camera frame (``cam2world`` is the identity); poses are
``object2world`` (metres).
"""

from __future__ import annotations

import fcntl
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.data.config import DatasetConfig, ObjectSource
from virtus.errors import InputError
from virtus.geometry.transforms import Pose
from virtus.io.runs import atomic_write
from virtus.sensor.noise import MAX_SEED

__all__ = ["ObjectRecord", "Randomiser", "SampleSpec", "build_rig", "candidate_sequences"]

#: Stream numbers of the seed sequences (module docstring).
_GROUP, _INSTANCE, _CAPTURE, _SHUFFLE = 1, 2, 3, 4


def _rng(*key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([int(k) for k in key]))


def _split_of(u: float, splits: tuple[tuple[str, float], ...]) -> str:
    """The split whose cumulative fraction interval holds ``u`` in [0, 1)."""
    total = 0.0
    for name, fraction in splits:
        total += fraction
        if u < total:
            return name
    return next(name for name, fraction in reversed(splits) if fraction > 0)


def split_counts(n: int, splits: tuple[tuple[str, float], ...]) -> list[tuple[str, int]]:
    """How many of ``n`` instances go to each split: ``floor(fraction n)`` plus the
    remainder by largest fractional part, then at least one for every split with a positive
    fraction while another split has more than one (so 10 instances at 0.8/0.1/0.1 give
    8/1/1 and 3 give 1/1/1)."""
    exact = [fraction * n for _, fraction in splits]
    counts = [math.floor(x) for x in exact]
    by_remainder = sorted(range(len(splits)), key=lambda i: (counts[i] - exact[i], i))
    for i in by_remainder[: n - sum(counts)]:
        counts[i] += 1
    for i, (_, fraction) in enumerate(splits):
        if fraction > 0 and counts[i] == 0:
            donor = max(range(len(splits)), key=lambda j: (counts[j], -j))
            if counts[donor] > 1:
                counts[donor] -= 1
                counts[i] += 1
    return [(name, count) for (name, _), count in zip(splits, counts, strict=True)]


@dataclass(frozen=True)
class ObjectRecord:
    """One surface of a sample's scene, for the ``object_id`` label and the metadata.

    Attributes
    ----------
    id : 1-based label value in ``object_id`` (0 = no surface).
    key : the object's identity (``"sphere/3"``: instance 3 of source ``sphere``;
        ``"mesh/part.stl"``; ``"plane"``; ``"board"``); splits are by this key.
    type : ``sphere``, ``box``, ``mesh``, ``plane`` or ``board``.
    pose : object2world (for a sphere: identity rotation, t = centre), metres.
    size_m : sphere (radius,), box (x, y, z) edges, plane/board (width, height), mesh the
        local bounding box (xmin, ymin, zmin, xmax, ymax, zmax) after scaling, metres.
    material : the material's fields (albedo, roughness, specular, metal).
    """

    id: int
    key: str
    type: str
    pose: Pose
    size_m: tuple[float, ...]
    material: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "key": self.key,
            "type": self.type,
            "pose": self.pose.to_dict(),
            "size_m": list(self.size_m),
            "material": self.material,
        }


@dataclass(frozen=True, eq=False)
class SampleSpec:
    """Everything that determines sample ``index`` (see the module docstring).

    Attributes
    ----------
    index, group : sample index and its group.
    split : the split name.
    capture_seed : seed of the capture's sensor-noise streams.
    scanner : the scanner (rig, sequence, projector, sensor, spp, bounces).
    scene : the scene (world frame = camera frame).
    cam2world : camera pose in the world frame (identity).
    objects : the scene's surfaces, in ``object_id`` order.
    info : JSON-ready extras: sensor and projector names, sequence choice, ambient, mode
        details (turntable view, ablation cell, board pose).
    """

    index: int
    group: int
    split: str
    capture_seed: int
    scanner: Any
    scene: Any
    cam2world: Pose
    objects: tuple[ObjectRecord, ...]
    info: dict[str, Any]


def build_rig(config: DatasetConfig) -> Any:
    """The dataset's rig: ``rig.file`` or the paper's, resampled by the scales."""
    from virtus.geometry.devices import Camera, Projector, Rig, default_rig

    rig = Rig.load_json(config.rig_file) if config.rig_file else default_rig()
    if config.camera_scale != 1.0 or config.projector_scale != 1.0:
        rig = Rig(
            Camera(rig.camera.intrinsics.scaled(config.camera_scale)),
            Projector(rig.projector.intrinsics.scaled(config.projector_scale)),
            rig.proj2cam,
        )
    return rig


def candidate_sequences(config: DatasetConfig, rig: Any) -> tuple[tuple[str, Any], ...]:
    """Every ``(name, PatternSequence)`` a sample may show (config ``fringes``).

    Raises
    ------
    InputError : a combination that cannot be decoded, or a sequence file for another
        projector size.
    """
    from virtus.patterns import (
        build_sequence,
        gray_bits_needed,
        heterodyne_sequence,
        load_sequence_file,
    )

    width, height = rig.projector.intrinsics.width, rig.projector.intrinsics.height
    fringes = config.fringes
    spans = {"v": width, "h": height}
    out = []
    for coding in fringes.codings:
        for steps in fringes.steps:
            for period in fringes.periods:
                name = f"{coding}/N{steps}/T{period:g}"
                try:
                    if coding == "gray":
                        bits = max(
                            gray_bits_needed(spans[d], period, True) for d in fringes.directions
                        )
                        sequence = build_sequence(
                            width, height, periods=period, steps=steps, gray_bits=bits,
                            directions=fringes.directions,
                        )  # fmt: skip
                    else:
                        span = max(spans[d] for d in fringes.directions)
                        m = max(math.ceil(span / period) + 1, 10)
                        periods = (period, period * m / (m - 1), period * m / (m - 8))
                        sequence = heterodyne_sequence(
                            width, height, periods=periods, steps=steps,
                            directions=fringes.directions,
                        )  # fmt: skip
                except InputError as error:
                    raise InputError(f"fringes ({name})", error.expected, error.got) from None
                out.append((name, sequence))
    for path in fringes.sequences:
        sequence, _ = load_sequence_file(path)
        if (sequence.width, sequence.height) != (width, height):
            raise InputError(
                f"fringes.sequences {path}",
                f"patterns for the rig's {width}x{height} px projector",
                f"{sequence.width}x{sequence.height} px",
            )
        out.append((Path(path).name, sequence))
    return tuple(out)


def _random_rotation(rng: np.random.Generator) -> Pose:
    """A uniformly distributed rotation (normalised Gaussian quaternion)."""
    quat = rng.normal(size=4)
    return Pose.from_quat(quat / np.linalg.norm(quat))


class Randomiser:
    """Sample specifications of one dataset configuration.

    Parameters
    ----------
    config : the configuration.
    assets_dir : folder for generated mesh files (free-form objects), shared by workers:
        each file is written atomically, with the same bytes by whoever writes it.

    Raises
    ------
    InputError : the configuration cannot be generated (a sequence that cannot be decoded,
        a split without object instances, a sensor file that does not parse, ...).
    """

    def __init__(self, config: DatasetConfig, assets_dir: str | Path) -> None:
        from virtus.sensor.camera import load_sensor
        from virtus.sensor.projector import load_projector

        self.config = config
        self.assets_dir = Path(assets_dir)
        self.rig = build_rig(config)
        cam = self.rig.camera.intrinsics
        from virtus.data.config import MAX_IMAGE_PIXELS

        if cam.width * cam.height > MAX_IMAGE_PIXELS:
            raise InputError(
                "rig", f"a camera of at most {MAX_IMAGE_PIXELS} pixels", f"{cam.width}x{cam.height}"
            )
        self.sequences = candidate_sequences(config, self.rig)
        self.sensors = tuple(load_sensor(s) for s in config.sensors)
        self.projectors = tuple(load_projector(p) for p in config.projectors)
        self.instances = self._instances()
        if config.mode == "calibration":
            from virtus.calib.board import board_from_spec

            self.board = board_from_spec(config.board)
        else:
            needed = [name for name, fraction in config.splits if fraction > 0]
            empty = [name for name in needed if not self.instances.get(name)]
            if empty:
                raise InputError(
                    "objects.sources",
                    "object instances in every split with a positive fraction (raise "
                    "'instances' or add mesh files)",
                    f"none in {empty}",
                )

    # -- tables ---------------------------------------------------------------------------

    @property
    def max_frames(self) -> int:
        """Most frames of any candidate sequence (the store's frame axis)."""
        return max(len(seq) for _, seq in self.sequences)

    @property
    def bit_depth(self) -> int:
        """Largest sensor bit depth (8 -> uint8 frames, else uint16)."""
        return max(s.bit_depth for s in self.sensors)

    def _instances(self) -> dict[str, list[tuple[int, int]]]:
        """Split name -> ``(source index, instance k)`` of every object instance.

        Each source's instances are shuffled (stream ``[seed, 4, source]``) and cut into
        splits by :func:`split_counts`, so every split with a positive fraction gets
        instances whenever a source has enough."""
        table: dict[str, list[tuple[int, int]]] = {name: [] for name, _ in self.config.splits}
        for s, source in enumerate(self.config.sources):
            order = _rng(self.config.seed, _SHUFFLE, s).permutation(source.instances)
            first = 0
            for name, count in split_counts(source.instances, self.config.splits):
                table[name] += [(s, int(k)) for k in sorted(order[first : first + count])]
                first += count
        return table

    def group_of(self, index: int) -> int:
        """The group of sample ``index`` (module docstring)."""
        if self.config.mode == "scan":
            return index // self.config.turntable_views
        if self.config.mode == "ablation":
            return index // self._cells
        return index

    @property
    def _cells(self) -> int:
        return len(self.config.ablation_materials) * len(self.config.ablation_ambients)

    # -- one sample ----------------------------------------------------------------------

    def sample(self, index: int) -> SampleSpec:
        """The specification of sample ``index`` (0 <= index < MAX_SAMPLES)."""
        from virtus.render.settings import RenderSettings
        from virtus.scanner import Scanner

        config = self.config
        group = self.group_of(index)
        rng = _rng(config.seed, _GROUP, group)
        split = _split_of(float(rng.random()), config.splits)
        seq_index = int(rng.integers(len(self.sequences)))
        sensor_index = int(rng.integers(len(self.sensors)))
        projector_index = int(rng.integers(len(self.projectors)))
        ambient = float(rng.uniform(*config.ambient))
        seq_name, sequence = self.sequences[seq_index]
        scanner = Scanner(
            rig=self.rig,
            sequence=sequence,
            projector=self.projectors[projector_index],
            sensor=self.sensors[sensor_index],
            render=RenderSettings(spp=config.spp, bounces=config.bounces),
        )
        info: dict[str, Any] = {
            "mode": config.mode,
            "sequence": seq_name,
            "sensor": config.sensors[sensor_index],
            "projector": config.projectors[projector_index],
        }
        if config.mode == "calibration":
            objects, extra = self._board(rng)
        else:
            objects = self._objects(rng, split)
            extra = self._arrange(index, rng, objects)
            objects = extra.pop("objects")
            if "ambient" in extra:
                ambient = extra.pop("ambient")
        info.update(extra)
        info["ambient"] = ambient
        capture_seed = (
            int(
                np.random.SeedSequence([config.seed, _CAPTURE, index]).generate_state(1, np.uint64)[
                    0
                ]
            )
            & MAX_SEED
        )
        return SampleSpec(
            index=index,
            group=group,
            split=split,
            capture_seed=capture_seed,
            scanner=scanner,
            scene=self._scene(objects, ambient),
            cam2world=Pose.identity(),
            objects=tuple(o for o, _ in objects),
            info=info,
        )

    # -- objects --------------------------------------------------------------------------

    def _material(self, rng: np.random.Generator) -> dict[str, Any]:
        config = self.config
        metal = bool(rng.random() < config.metal_probability)
        return {
            "albedo": float(rng.uniform(*config.albedo)),
            "roughness": float(rng.uniform(*config.roughness)),
            "specular": float(rng.uniform(*config.specular)),
            "metal": metal,
        }

    def _objects(self, rng: np.random.Generator, split: str) -> list[dict[str, Any]]:
        """Draw the group's object instances (from ``split`` only) and their materials."""
        config = self.config
        pool = self.instances[split]
        weights = np.array([config.sources[s].weight for s, _ in pool], dtype=np.float64)
        weights /= weights.sum()
        count = int(rng.integers(config.object_count[0], config.object_count[1] + 1))
        chosen = rng.choice(len(pool), size=count, p=weights)
        return [
            {"source": pool[c][0], "instance": pool[c][1], "material": self._material(rng)}
            for c in chosen
        ]

    def _centre(self, rng: np.random.Generator) -> np.ndarray:
        """(3,) a centre on a camera ray through the central ``field`` share of the image,
        at a depth in ``objects.distance_m`` (camera frame, metres)."""
        cam = self.rig.camera.intrinsics
        half = 0.5 * self.config.object_field
        frac = rng.uniform(0.5 - half, 0.5 + half, size=2)
        pixel = np.array([[frac[0] * cam.width - 0.5, frac[1] * cam.height - 0.5]])
        ray = cam.unproject(pixel)[0]
        depth = rng.uniform(*self.config.object_distance_m)
        return ray * depth / ray[2]

    def _arrange(
        self, index: int, rng: np.random.Generator, drawn: list[dict[str, Any]]
    ) -> dict[str, Any]:
        """Place the objects (and planes) for the mode; returns extras with ``objects``:
        a list of ``(ObjectRecord, scene object)``."""
        config = self.config
        extra: dict[str, Any] = {}
        placed = []
        if config.mode == "scan":
            from virtus.geometry.trajectories import turntable_poses

            view = index % config.turntable_views
            tilt = Pose.from_euler(
                "x", rng.uniform(-config.turntable_tilt_deg, config.turntable_tilt_deg), True
            )
            start = Pose((tilt @ _random_rotation(rng)).R, self._centre(rng))
            pose = turntable_poses(config.turntable_views, start)[view]
            placed.append(self._make(len(placed) + 1, drawn[0], pose, rng))
            extra["view"] = view
        else:
            poses = [Pose(_random_rotation(rng).R, self._centre(rng)) for _ in drawn]
            for item, pose in zip(drawn, poses, strict=True):
                placed.append(self._make(len(placed) + 1, item, pose, rng))
        if config.mode == "ablation":
            from virtus.scene.presets import AMBIENTS, MATERIALS

            cell = index % self._cells
            material_name = config.ablation_materials[cell // len(config.ablation_ambients)]
            ambient_name = config.ablation_ambients[cell % len(config.ablation_ambients)]
            material = {"albedo": 0.8, "roughness": 0.95, "specular": 0.15, "metal": False}
            material.update(MATERIALS[material_name])
            placed = [self._with_material(record, obj, material) for record, obj in placed]
            extra.update(cell=cell, material=material_name, ambient_name=ambient_name)
            extra["ambient"] = float(AMBIENTS[ambient_name])
        placed += self._planes(rng, len(placed))
        extra["objects"] = placed
        return extra

    def _with_material(self, record: ObjectRecord, obj: Any, material: dict[str, Any]) -> tuple:
        from virtus.scene.model import Material

        new = obj.model_copy(update={"material": Material(**material)})
        return ObjectRecord(
            record.id, record.key, record.type, record.pose, record.size_m, material
        ), new

    def _make(
        self, object_id: int, item: dict[str, Any], pose: Pose, rng: np.random.Generator
    ) -> tuple[ObjectRecord, Any]:
        """The scene object of an instance placed at ``pose`` (object2world)."""
        from virtus.scene.model import BoxObject, Material, MeshObject, SphereObject

        source: ObjectSource = self.config.sources[item["source"]]
        k = item["instance"]
        shape = _rng(self.config.seed, _INSTANCE, item["source"], k)
        material = item["material"]
        mat = Material(**material)
        if source.type == "sphere":
            radius = float(shape.uniform(*source.size_m))
            key = f"sphere{item['source']}/{k}"
            record = ObjectRecord(
                object_id, key, "sphere", Pose(np.eye(3), pose.t), (radius,), material
            )
            return record, SphereObject(radius_m=radius, center_m=pose.t, material=mat)
        if source.type == "box":
            size = tuple(float(x) for x in shape.uniform(*source.size_m, size=3))
            key = f"box{item['source']}/{k}"
            record = ObjectRecord(object_id, key, "box", pose, size, material)
            return record, BoxObject(size_m=size, pose=pose, material=mat)
        size = float(shape.uniform(*source.size_m))
        if source.type == "freeform":
            shape_seed = int(shape.integers(0, 2**31))
            path = self._freeform_file(shape_seed, source.subdivisions)
            key = f"freeform{item['source']}/{k}"
        else:
            path = source.path / source.files[k]  # type: ignore[operator]
            key = f"mesh{item['source']}/{source.files[k]}"
        low, high = _mesh_bounds(str(path))
        scale = size / float(np.max(high - low))
        centre = 0.5 * (low + high) * scale
        # object2world of the mesh file's frame: the bounding-box centre goes to pose.t.
        file2world = Pose(pose.R, pose.t - pose.R @ centre)
        bounds = (*(low * scale - centre), *(high * scale - centre))
        record = ObjectRecord(
            object_id, key, "mesh", pose, tuple(float(b) for b in bounds), material
        )
        return record, MeshObject(path=path, scale_to_m=scale, pose=file2world, material=mat)

    def _freeform_file(self, shape_seed: int, subdivisions: int) -> Path:
        """The free-form object of ``shape_seed`` as a binary STL in the assets folder
        (written atomically once; every writer writes the same bytes)."""
        from virtus.scene.procedural import freeform_object

        path = self.assets_dir / f"freeform_{shape_seed}_s{subdivisions}.stl"
        if path.is_file():
            return path
        # Workers that draw the same shape at once used to collide in a shared staging
        # folder; atomic_write now stages each call apart, so that is safe without a lock.
        # The lock stays so that the mesh is generated once, not once per worker that
        # draws it (free-form meshes cost CPU time): one writer at a time per assets
        # folder; the others wait, then find the file written.
        self.assets_dir.mkdir(parents=True, exist_ok=True)
        with open(self.assets_dir / ".freeform.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            if not path.is_file():
                mesh = freeform_object(0.1, subdivisions, shape_seed)
                atomic_write(path, lambda tmp: mesh.export(tmp, file_type="stl"))
        return path

    def _planes(self, rng: np.random.Generator, first: int) -> list[tuple[ObjectRecord, Any]]:
        from virtus.scene.model import Material, PlaneObject

        config = self.config
        count = int(rng.integers(config.plane_count[0], config.plane_count[1] + 1))
        out = []
        for p in range(count):
            angles = rng.uniform(-config.plane_tilt_deg, config.plane_tilt_deg, size=2)
            depth = float(rng.uniform(*config.plane_distance_m))
            pose = Pose.from_euler("xyz", (*angles, 0.0), degrees=True, t=(0.0, 0.0, depth))
            material = self._material(rng)
            size = (config.plane_size_m, config.plane_size_m)
            record = ObjectRecord(first + p + 1, "plane", "plane", pose, size, material)
            out.append((record, PlaneObject(size_m=size, pose=pose, material=Material(**material))))
        return out

    def _board(self, rng: np.random.Generator) -> tuple[list[tuple[ObjectRecord, Any]], dict]:
        """A circle board at a random pose inside both fields (calibration mode)."""
        from virtus.calib.poses import random_poses
        from virtus.calib.scene import board_scene, board_texture

        pose = random_poses(self.rig, self.board, 1, rng)[0]
        # The calibration job's texture (kept per board there), so boards look alike.
        plane = board_scene(self.board, pose, board_texture(self.board)).objects[0]
        record = ObjectRecord(1, "board", "board", pose.board2cam, self.board.plane_size_m, {})
        return [(record, plane)], {
            "board": self.board.to_dict(),
            "board2cam": pose.board2cam.to_dict(),
        }

    def _scene(self, objects: list[tuple[ObjectRecord, Any]], ambient: float) -> Any:
        from virtus.scene.model import Scene

        return Scene(objects=tuple(obj for _, obj in objects), ambient=ambient)


@functools.lru_cache(maxsize=256)
def _mesh_bounds(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(3,), (3,) bounding box of a mesh file, file units (read once per process)."""
    from virtus.scene.model import MeshObject

    vertices = MeshObject(path=path).load()[0]
    return vertices.min(axis=0), vertices.max(axis=0)
