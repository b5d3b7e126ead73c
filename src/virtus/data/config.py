"""The dataset configuration: one validated, frozen description of what to generate.

A configuration is read from YAML (:func:`load_config`) or a mapping
(:meth:`DatasetConfig.from_dict`); unknown keys anywhere are refused with the key named
(:func:`virtus.io.safeio.check_keys`), every number and size is bounded, and every file it
names (rig, sensor, projector, sequence files, mesh folders) is checked before any work
starts. :meth:`DatasetConfig.to_dict` gives the canonical form (absolute paths, defaults
filled in) that a store records in ``dataset.json`` and that ``from_dict`` reads back.

Schema (YAML; every key optional except ``mode``; ranges are ``[low, high]`` or one
number; lists of choices are drawn uniformly per sample)::

    format: virtus.dataset_config/1
    mode: training                 # scan | training | calibration | ablation
    seed: 0                        # >= 0; sample i depends only on (seed, i, config)
    num_samples: 100               # 1..MAX_SAMPLES (--num overrides)
    splits: {train: 0.8, val: 0.1, test: 0.1}   # by object (see virtus.data.sampling)
    rig:
      file: null                   # rig JSON (relative to this file); default the paper's rig
      camera_scale: 1.0            # resample the camera (Intrinsics.scaled), e.g. 0.25
      projector_scale: 1.0
    render: {spp: 1, bounces: 1}
    sensor: [ideal]                # presets (ideal, paper, imx174, webcam) or files
    projector: [ideal]             # presets (ideal, paper, lightcrafter) or files
    fringes:
      codings: [gray]              # gray (+ complementary frame) | heterodyne (3 periods);
                                   # [] with sequences: only the sequence files
      steps: [18]                  # phase steps N >= 3 (choices)
      periods: [18]                # finest period, projector px (choices)
      directions: [v, h]
      sequences: []                # sequence description files (virtus patterns), added
                                   # to the choices
    objects:
      count: [1, 1]                # objects per sample (training, ablation); training may
                                   # use 0 (planes only: a flat-plane test set)
      distance_m: [0.9, 1.1]       # object centres: camera-frame depth range
      field: 0.5                   # centres fall in this central share of the image
      sources:                     # what objects are made of (at least one)
        - {type: sphere, radius_m: [0.03, 0.08], instances: 16, weight: 1}
        - {type: box, size_m: [0.03, 0.12], instances: 16, weight: 1}
        - {type: freeform, size_m: [0.06, 0.12], instances: 8, subdivisions: 4, weight: 1}
        - {type: mesh_folder, path: meshes/, size_m: [0.05, 0.15], weight: 1}
    materials: {albedo: [0.3, 1.0], roughness: [0.3, 1.0], specular: [0.0, 0.5],
                metal_probability: 0.0}
    ambient: [0.0, 0.2]            # relative to the projector's white (virtus.scene.model)
    planes: {count: [1, 1], distance_m: [1.2, 1.4], tilt_deg: 20, size_m: 2.0}
    turntable: {views: 12, tilt_deg: 15}                      # scan mode
    board: {spec: "4x7"}                                      # calibration mode
    ablation: {materials: [matte, glossy, metal, reflective], ambients: [dark, ambient]}
    storage: {shard_samples: 8, codec: blosc-zstd, level: 1, label_dtype: float32,
              compress_on: cpu}              # cpu | gpu | auto (gpu: zstd, shuffle-zstd only)

Units: metres, degrees where a key says ``_deg``, projector px for periods.

``storage.compress_on`` says who compresses, not what is stored: ``cpu`` (numcodecs),
``gpu`` (nvCOMP, ``pip install virtus-fpp[gpu]``; only for the codecs ``zstd`` and
``shuffle-zstd``, refused without nvCOMP or a CUDA device) or ``auto`` (the GPU where that
works, else the CPU, and the run says so). The default is ``cpu``: on one H200 host with 8
workers the GPU's zstd was the slower. The arrays are the same either way, so it is not part
of a store's identity: a store may be resumed with another one
(:mod:`virtus.data.chunkcodecs`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from virtus.errors import InputError
from virtus.io.safeio import check_keys, is_file, read_yaml

__all__ = [
    "CODECS",
    "CONFIG_FORMAT",
    "MAX_IMAGE_PIXELS",
    "MAX_SAMPLES",
    "MAX_WORKERS",
    "MODES",
    "DatasetConfig",
    "load_config",
]

#: Format tag of a configuration (optional in files, written by ``to_dict``).
CONFIG_FORMAT = "virtus.dataset_config/1"
#: Generation modes.
MODES = ("scan", "training", "calibration", "ablation")
#: Most samples in one dataset (a sample of the paper's 52 frames at 960 x 960 is ~48 MB
#: raw: a million samples is already tens of TB).
MAX_SAMPLES = 1_000_000
#: Most parallel workers (local processes or Ray tasks in flight).
MAX_WORKERS = 256
#: Largest camera image (pixels): 4096 x 4096.
MAX_IMAGE_PIXELS = 4096 * 4096
#: Most choices in one list (sensors, steps, periods, ...), objects per sample and
#: instances per source.
MAX_CHOICES = 64
MAX_OBJECTS = 16
MAX_INSTANCES = 100_000
#: Most samples per shard, and most raw bytes a shard of frames may hold (a worker keeps
#: one shard in memory).
MAX_SHARD_SAMPLES = 1024
MAX_SHARD_BYTES = 4 << 30
#: Mesh files read from a mesh folder, at most this many.
MAX_MESH_FILES = 10_000
#: Storage codecs: Blosc (byte shuffle) with zstd (the default) or lz4 for every array,
#: ``blosc-auto`` (frames with blosc-zstd, labels with blosc-lz4: less compression work,
#: more bytes; see :func:`virtus.data.chunkcodecs.zarr_compressor`), plain zstd, byte shuffle
#: then zstd (``shuffle-zstd``: as small as blosc-zstd, and written by the GPU too), none.
CODECS = ("blosc-zstd", "blosc-auto", "blosc-lz4", "zstd", "shuffle-zstd", "none")
#: Object source types.
SOURCE_TYPES = ("sphere", "box", "freeform", "mesh_folder")
#: Fringe codings built from ``fringes`` (see :mod:`virtus.patterns`).
CODINGS = ("gray", "heterodyne")

_TOP_KEYS = (
    "format", "mode", "seed", "num_samples", "splits", "rig", "render", "sensor", "projector",
    "fringes", "objects", "materials", "ambient", "planes", "turntable", "board", "ablation",
    "storage",
)  # fmt: skip


# -- small parsers ----------------------------------------------------------------------------


def _number(name: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(name, f"a number in [{low:g}, {high:g}]", value)
    number = float(value)
    if not (math.isfinite(number) and low <= number <= high):
        raise InputError(name, f"a number in [{low:g}, {high:g}]", value)
    return number


def _integer(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(name, f"an integer in {low}..{high}", value)
    return int(value)


def _range(name: str, value: Any, low: float, high: float) -> tuple[float, float]:
    """``[a, b]`` (or one number ``a`` = ``[a, a]``) with ``low <= a <= b <= high``."""
    pair = (
        [value, value] if isinstance(value, int | float) and not isinstance(value, bool) else value
    )
    if not isinstance(pair, list | tuple) or len(pair) != 2:
        raise InputError(name, f"[low, high] within [{low:g}, {high:g}] or one number", value)
    a, b = (_number(name, v, low, high) for v in pair)
    if a > b:
        raise InputError(name, "[low, high] with low <= high", value)
    return (a, b)


def _int_range(name: str, value: Any, low: int, high: int) -> tuple[int, int]:
    pair = [value, value] if isinstance(value, int) and not isinstance(value, bool) else value
    if not isinstance(pair, list | tuple) or len(pair) != 2:
        raise InputError(name, f"[low, high] integers within {low}..{high}", value)
    a, b = (_integer(name, v, low, high) for v in pair)
    if a > b:
        raise InputError(name, "[low, high] with low <= high", value)
    return (a, b)


def _choices(name: str, value: Any, item: Any) -> tuple:
    """A non-empty list of at most :data:`MAX_CHOICES` items (one item alone is accepted)."""
    items = value if isinstance(value, list | tuple) else [value]
    if not items or len(items) > MAX_CHOICES:
        raise InputError(name, f"a list of 1..{MAX_CHOICES} choices", value)
    out = tuple(item(f"{name}[{i}]", v) for i, v in enumerate(items))
    if len(set(out)) != len(out):
        raise InputError(name, "distinct choices", value)
    return out


def _object_count(mode: str, value: Any, planes: Any) -> tuple[int, int]:
    """``objects.count``: 0 objects is a training sample of background planes only (a
    flat-plane test set); other modes place at least one object, and a sample is never empty."""
    low = 0 if mode == "training" else 1
    count = _int_range("objects.count", value, low, MAX_OBJECTS)
    no_planes = planes is not None and _int_range("planes.count", planes, 0, MAX_OBJECTS)[0] == 0
    if count[0] == 0 and no_planes:
        raise InputError("objects.count", "at least 1 where planes.count may be 0", list(count))
    return count


def _section(data: Mapping[str, Any], key: str, allowed: tuple[str, ...]) -> Mapping[str, Any]:
    value = data.get(key) or {}
    return check_keys(value, allowed, key)


def _path(name: str, value: Any, base: Path | None, *, folder: bool = False) -> Path:
    if not isinstance(value, str | Path) or not str(value):
        raise InputError(name, "a path", value)
    path = Path(value).expanduser()
    if not path.is_absolute() and base is not None:
        path = base / path
    try:
        path = path.resolve()
    except (OSError, ValueError, RuntimeError):  # a NUL byte, a symlink loop: no such file
        raise InputError(name, f"an existing {'folder' if folder else 'file'}", value) from None
    if not is_file(path, folder=folder):
        raise InputError(name, f"an existing {'folder' if folder else 'file'}", str(path))
    return path


def _spec(name: str, value: Any, presets: Mapping[str, Any], base: Path | None) -> str:
    """A preset name, or a file path made absolute (checked to exist)."""
    if isinstance(value, str) and value in presets:
        return value
    if not isinstance(value, str):
        raise InputError(name, f"a preset ({', '.join(presets)}) or a file", value)
    return str(_path(name, value, base))


# -- sections ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class ObjectSource:
    """One kind of object the randomiser draws from.

    Attributes
    ----------
    type : ``sphere``, ``box``, ``freeform`` (:func:`virtus.scene.procedural.freeform_object` with a
        per-instance shape seed) or ``mesh_folder`` (every .stl/.obj/.ply file of ``path``).
    size_m : range of the object's size, metres: the radius of a sphere, the edge lengths of
        a box, the largest bounding-box extent of a free-form or mesh object.
    instances : distinct objects of a procedural source (each with fixed, seeded shape
        parameters); a mesh folder has one instance per file.
    weight : relative probability of drawing from this source.
    subdivisions : icosphere subdivisions of free-form objects (4: 5,120 faces).
    path : the mesh folder (``mesh_folder``); files: its mesh files, sorted.
    scale_to_m : metres per mesh-file unit before resizing to ``size_m`` (only the aspect
        ratio matters: meshes are scaled to ``size_m``).
    """

    type: str
    size_m: tuple[float, float]
    instances: int
    weight: float = 1.0
    subdivisions: int = 4
    path: Path | None = None
    files: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        size_key = "radius_m" if self.type == "sphere" else "size_m"
        out: dict[str, Any] = {"type": self.type, size_key: list(self.size_m)}
        if self.type == "mesh_folder":
            out["path"] = str(self.path)
        else:
            out["instances"] = self.instances
        if self.type == "freeform":
            out["subdivisions"] = self.subdivisions
        out["weight"] = self.weight
        return out


def _source(name: str, data: Any, base: Path | None) -> ObjectSource:
    from virtus.scene.model import MESH_SUFFIXES

    if not isinstance(data, Mapping) or data.get("type") not in SOURCE_TYPES:
        got = data.get("type") if isinstance(data, Mapping) else data
        raise InputError(f"{name}.type", f"one of {', '.join(SOURCE_TYPES)}", got)
    kind = data["type"]
    allowed = {
        "sphere": ("type", "radius_m", "instances", "weight"),
        "box": ("type", "size_m", "instances", "weight"),
        "freeform": ("type", "size_m", "instances", "subdivisions", "weight"),
        "mesh_folder": ("type", "path", "size_m", "weight"),
    }[kind]
    check_keys(data, allowed, name)
    size_key = "radius_m" if kind == "sphere" else "size_m"
    default = {"sphere": [0.03, 0.08], "box": [0.03, 0.12]}.get(kind, [0.06, 0.12])
    size = _range(f"{name}.{size_key}", data.get(size_key, default), 1e-3, 2.0)
    weight = _number(f"{name}.weight", data.get("weight", 1.0), 0.0, 1e6)
    if kind == "mesh_folder":
        folder = _path(f"{name}.path", data.get("path"), base, folder=True)
        files = sorted(
            p.name for p in folder.iterdir() if p.is_file() and p.suffix.lower() in MESH_SUFFIXES
        )
        if not files:
            raise InputError(
                f"{name}.path", f"a folder holding mesh files ({', '.join(MESH_SUFFIXES)})",
                f"no mesh file in {folder}",
            )  # fmt: skip
        if len(files) > MAX_MESH_FILES:
            raise InputError(f"{name}.path", f"at most {MAX_MESH_FILES} mesh files", len(files))
        return ObjectSource(kind, size, len(files), weight, path=folder, files=tuple(files))
    instances = _integer(f"{name}.instances", data.get("instances", 16), 1, MAX_INSTANCES)
    subdivisions = _integer(f"{name}.subdivisions", data.get("subdivisions", 4), 1, 7)
    return ObjectSource(kind, size, instances, weight, subdivisions)


@dataclass(frozen=True)
class Fringes:
    """The fringe sequences a sample may show: every combination of ``codings`` x
    ``steps`` x ``periods`` (built for the rig's projector) plus the ``sequences`` files.

    Attributes
    ----------
    codings : ``gray`` (one period + the Gray code that numbers its orders + the
        complementary frame) or ``heterodyne`` (three periods ``P, P m/(m-1), P m/(m-8)``
        with ``m = ceil(L / P) + 1`` for the longer projector axis ``L``, so the widest beat
        covers it).
    steps : phase steps per period (>= 3).
    periods : finest fringe period, projector px (>= 2).
    directions : ``v`` (vertical fringes, along u_p), ``h``, or both.
    sequences : sequence description files (absolute paths).
    """

    codings: tuple[str, ...] = ("gray",)
    steps: tuple[int, ...] = (18,)
    periods: tuple[float, ...] = (18.0,)
    directions: tuple[str, ...] = ("v", "h")
    sequences: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "codings": list(self.codings),
            "steps": list(self.steps),
            "periods": list(self.periods),
            "directions": list(self.directions),
            "sequences": list(self.sequences),
        }


def _fringes(data: Mapping[str, Any], base: Path | None) -> Fringes:
    allowed = ("codings", "steps", "periods", "directions", "sequences")
    section = _section(data, "fringes", allowed)

    def coding(name: str, value: Any) -> str:
        if value not in CODINGS:
            raise InputError(name, f"one of {', '.join(CODINGS)}", value)
        return str(value)

    def direction(name: str, value: Any) -> str:
        if value not in ("v", "h"):
            raise InputError(name, "v or h", value)
        return str(value)

    files = section.get("sequences") or []
    if not isinstance(files, list) or len(files) > MAX_CHOICES:
        raise InputError("fringes.sequences", f"a list of at most {MAX_CHOICES} files", files)
    return Fringes(
        codings=()  # only the sequence files
        if files and section.get("codings") == []
        else _choices("fringes.codings", section.get("codings", ["gray"]), coding),
        steps=_choices(
            "fringes.steps", section.get("steps", [18]), lambda n, v: _integer(n, v, 3, 256)
        ),
        periods=_choices(
            "fringes.periods", section.get("periods", [18]), lambda n, v: _number(n, v, 2, 1e5)
        ),
        directions=_choices("fringes.directions", section.get("directions", ["v", "h"]), direction),
        sequences=tuple(
            str(_path(f"fringes.sequences[{i}]", p, base)) for i, p in enumerate(files)
        ),
    )


# -- the configuration ------------------------------------------------------------------------


@dataclass(frozen=True)
class DatasetConfig:
    """A dataset's configuration (module docstring for the YAML schema).

    Attributes
    ----------
    mode : ``scan`` (one object per sample turning on a turntable, ``turntable.views``
        consecutive samples per object), ``training`` (objects and planes at random poses),
        ``calibration`` (a circle board at random poses inside both fields) or ``ablation``
        (the objects of a group under every material x ambient cell of ``ablation``).
    seed : dataset seed, >= 0.
    num_samples : samples to generate.
    splits : ``(name, fraction)`` pairs, fractions summing to 1.
    rig_file, camera_scale, projector_scale : the rig (None: the paper's) and resampling.
    spp, bounces : render settings (:class:`virtus.scanner.Scanner`).
    sensors, projectors : choices of sensor / projector model (preset names or files).
    fringes : the fringe sequence choices (:class:`Fringes`).
    object_count : objects per sample ``(min, max)``.
    object_distance_m : range of object-centre depths, metres (camera frame).
    object_field : central share of the image that object centres fall in, (0, 1].
    sources : :class:`ObjectSource` choices.
    albedo, roughness, specular : material ranges; metal_probability in [0, 1].
    ambient : ambient level range (relative radiance).
    plane_count, plane_distance_m, plane_tilt_deg, plane_size_m : background planes.
    turntable_views, turntable_tilt_deg : scan mode.
    board : calibration mode board spec (``virtus.calib.board.board_from_spec``).
    ablation_materials, ablation_ambients : ablation cells (names of
        :mod:`virtus.scene.presets`' tables).
    shard_samples : samples per shard (the write unit; each worker owns whole shards).
    codec, level : compression (:data:`CODECS`) and its level.
    label_dtype : ``float32`` or ``float64`` for real-valued labels.
    compress_on : who compresses: ``auto``, ``cpu`` or ``gpu`` (module docstring; not part
        of :meth:`identity`).
    """

    mode: str
    seed: int = 0
    num_samples: int = 100
    splits: tuple[tuple[str, float], ...] = (("train", 0.8), ("val", 0.1), ("test", 0.1))
    rig_file: str | None = None
    camera_scale: float = 1.0
    projector_scale: float = 1.0
    spp: int = 1
    bounces: int = 1
    sensors: tuple[str, ...] = ("ideal",)
    projectors: tuple[str, ...] = ("ideal",)
    fringes: Fringes = field(default_factory=Fringes)
    object_count: tuple[int, int] = (1, 1)
    object_distance_m: tuple[float, float] = (0.9, 1.1)
    object_field: float = 0.5
    sources: tuple[ObjectSource, ...] = ()
    albedo: tuple[float, float] = (0.3, 1.0)
    roughness: tuple[float, float] = (0.3, 1.0)
    specular: tuple[float, float] = (0.0, 0.5)
    metal_probability: float = 0.0
    ambient: tuple[float, float] = (0.0, 0.2)
    plane_count: tuple[int, int] = (1, 1)
    plane_distance_m: tuple[float, float] = (1.2, 1.4)
    plane_tilt_deg: float = 20.0
    plane_size_m: float = 2.0
    turntable_views: int = 12
    turntable_tilt_deg: float = 15.0
    board: str = "4x7"
    ablation_materials: tuple[str, ...] = ("matte", "glossy", "metal", "reflective")
    ablation_ambients: tuple[str, ...] = ("dark", "ambient")
    shard_samples: int = 8
    codec: str = "blosc-zstd"
    level: int = 1
    label_dtype: str = "float32"
    compress_on: str = "cpu"

    # -- reading ------------------------------------------------------------------------

    @classmethod
    def from_dict(cls, data: Any, base_dir: str | Path | None = None) -> DatasetConfig:
        """Validate a configuration mapping; relative paths resolve against ``base_dir``.

        Raises
        ------
        InputError
            An unknown key (named, with a guess), a value out of its bounds, a missing
            file, an empty mesh folder, or a combination that cannot be generated.
        """
        from virtus.scene.presets import AMBIENTS, MATERIALS
        from virtus.sensor.camera import SENSOR_PRESETS
        from virtus.sensor.projector import PROJECTOR_PRESETS

        base = None if base_dir is None else Path(base_dir)
        data = check_keys(data, _TOP_KEYS, "dataset config")
        if data.get("format", CONFIG_FORMAT) != CONFIG_FORMAT:
            raise InputError("format", CONFIG_FORMAT, data.get("format"))
        if data.get("mode") not in MODES:
            raise InputError("mode", f"one of {', '.join(MODES)}", data.get("mode"))
        mode = data["mode"]

        splits_data = data.get("splits", {"train": 0.8, "val": 0.1, "test": 0.1})
        if not isinstance(splits_data, Mapping) or not 1 <= len(splits_data) <= 8:
            raise InputError("splits", "a mapping of 1..8 split names to fractions", splits_data)
        splits = tuple(
            (str(k), _number(f"splits.{k}", v, 0.0, 1.0)) for k, v in splits_data.items()
        )
        if abs(sum(f for _, f in splits) - 1.0) > 1e-9:
            raise InputError("splits", "fractions summing to 1", dict(splits))

        rig = _section(data, "rig", ("file", "camera_scale", "projector_scale"))
        render = _section(data, "render", ("spp", "bounces"))
        objects = _section(data, "objects", ("count", "distance_m", "field", "sources"))
        materials = _section(
            data, "materials", ("albedo", "roughness", "specular", "metal_probability")
        )
        planes = _section(data, "planes", ("count", "distance_m", "tilt_deg", "size_m"))
        turntable = _section(data, "turntable", ("views", "tilt_deg"))
        board = _section(data, "board", ("spec",))
        ablation = _section(data, "ablation", ("materials", "ambients"))
        storage = _section(
            data, "storage", ("shard_samples", "codec", "level", "label_dtype", "compress_on")
        )

        def member(table: Mapping[str, Any], what: str):  # noqa: ANN202
            def check(name: str, value: Any) -> str:
                if not isinstance(value, str) or value not in table:  # (a list: unhashable)
                    raise InputError(name, f"one of {', '.join(table)} ({what})", value)
                return str(value)

            return check

        sources_data = objects.get("sources")
        if sources_data is None:
            sources_data = [{"type": "sphere"}] if mode != "calibration" else []
        if not isinstance(sources_data, list) or len(sources_data) > MAX_CHOICES:
            raise InputError("objects.sources", f"a list of at most {MAX_CHOICES}", sources_data)
        sources = tuple(
            _source(f"objects.sources[{i}]", s, base) for i, s in enumerate(sources_data)
        )
        if mode != "calibration" and not sources:
            raise InputError("objects.sources", "at least one object source", "none")
        if sources and not sum(s.weight for s in sources) > 0:
            raise InputError("objects.sources", "a positive total weight", 0)

        codec = storage.get("codec", "blosc-zstd")
        if codec not in CODECS:
            raise InputError("storage.codec", f"one of {', '.join(CODECS)}", codec)
        compress_on = _compress_on(storage.get("compress_on", "cpu"), codec)
        label_dtype = storage.get("label_dtype", "float32")
        if label_dtype not in ("float32", "float64"):
            raise InputError("storage.label_dtype", "float32 or float64", label_dtype)
        board_spec = board.get("spec", "4x7")
        if not isinstance(board_spec, str):
            raise InputError("board.spec", "a board spec such as '4x7'", board_spec)
        config = cls(
            mode=mode,
            seed=_integer("seed", data.get("seed", 0), 0, (1 << 63) - 1),
            num_samples=_integer("num_samples", data.get("num_samples", 100), 1, MAX_SAMPLES),
            splits=splits,
            rig_file=None if rig.get("file") is None else str(_path("rig.file", rig["file"], base)),
            camera_scale=_number("rig.camera_scale", rig.get("camera_scale", 1.0), 1e-3, 8.0),
            projector_scale=_number(
                "rig.projector_scale", rig.get("projector_scale", 1.0), 1e-3, 8.0
            ),
            spp=_integer("render.spp", render.get("spp", 1), 1, 64),
            bounces=_integer("render.bounces", render.get("bounces", 1), 1, 8),
            sensors=_choices(
                "sensor",
                data.get("sensor", ["ideal"]),
                lambda n, v: _spec(n, v, SENSOR_PRESETS, base),
            ),  # fmt: skip
            projectors=_choices(
                "projector",
                data.get("projector", ["ideal"]),
                lambda n, v: _spec(n, v, PROJECTOR_PRESETS, base),
            ),  # fmt: skip
            fringes=_fringes(data, base),
            object_count=_object_count(mode, objects.get("count", [1, 1]), planes.get("count")),
            object_distance_m=_range(
                "objects.distance_m", objects.get("distance_m", [0.9, 1.1]), 0.05, 100.0
            ),
            object_field=_number("objects.field", objects.get("field", 0.5), 1e-3, 1.0),
            sources=sources,
            albedo=_range("materials.albedo", materials.get("albedo", [0.3, 1.0]), 0.0, 1.0),
            roughness=_range(
                "materials.roughness", materials.get("roughness", [0.3, 1.0]), 0.0, 1.0
            ),
            specular=_range("materials.specular", materials.get("specular", [0.0, 0.5]), 0.0, 1.0),
            metal_probability=_number(
                "materials.metal_probability", materials.get("metal_probability", 0.0), 0.0, 1.0
            ),
            ambient=_range("ambient", data.get("ambient", [0.0, 0.2]), 0.0, 1000.0),
            plane_count=_int_range("planes.count", planes.get("count", [1, 1]), 0, MAX_OBJECTS),
            plane_distance_m=_range(
                "planes.distance_m", planes.get("distance_m", [1.2, 1.4]), 0.05, 100.0
            ),
            plane_tilt_deg=_number("planes.tilt_deg", planes.get("tilt_deg", 20.0), 0.0, 80.0),
            plane_size_m=_number("planes.size_m", planes.get("size_m", 2.0), 0.01, 100.0),
            turntable_views=_integer("turntable.views", turntable.get("views", 12), 1, 360),
            turntable_tilt_deg=_number(
                "turntable.tilt_deg", turntable.get("tilt_deg", 15.0), 0.0, 90.0
            ),
            board=board_spec,
            ablation_materials=_choices(
                "ablation.materials",
                ablation.get("materials", list(MATERIALS)),
                member(MATERIALS, "virtus.scene.presets.MATERIALS"),
            ),
            ablation_ambients=_choices(
                "ablation.ambients",
                ablation.get("ambients", list(AMBIENTS)),
                member(AMBIENTS, "virtus.scene.presets.AMBIENTS"),
            ),
            shard_samples=_integer(
                "storage.shard_samples", storage.get("shard_samples", 8), 1, MAX_SHARD_SAMPLES
            ),
            codec=codec,
            level=_integer("storage.level", storage.get("level", 1), 0, 9),
            label_dtype=label_dtype,
            compress_on=compress_on,
        )
        return config

    def with_num_samples(self, num: int | None) -> DatasetConfig:
        """A copy with ``num_samples`` replaced (``--num``), bounded by :data:`MAX_SAMPLES`."""
        from dataclasses import replace

        if num is None:
            return self
        return replace(self, num_samples=_integer("num", num, 1, MAX_SAMPLES))

    # -- writing ------------------------------------------------------------------------

    def to_dict(self) -> dict[str, Any]:
        """The canonical, JSON-ready configuration (absolute paths, every default filled
        in); ``from_dict(to_dict())`` gives the same configuration."""
        return {
            "format": CONFIG_FORMAT,
            "mode": self.mode,
            "seed": self.seed,
            "num_samples": self.num_samples,
            "splits": dict(self.splits),
            "rig": {
                "file": self.rig_file,
                "camera_scale": self.camera_scale,
                "projector_scale": self.projector_scale,
            },
            "render": {"spp": self.spp, "bounces": self.bounces},
            "sensor": list(self.sensors),
            "projector": list(self.projectors),
            "fringes": self.fringes.to_dict(),
            "objects": {
                "count": list(self.object_count),
                "distance_m": list(self.object_distance_m),
                "field": self.object_field,
                "sources": [s.to_dict() for s in self.sources],
            },
            "materials": {
                "albedo": list(self.albedo),
                "roughness": list(self.roughness),
                "specular": list(self.specular),
                "metal_probability": self.metal_probability,
            },
            "ambient": list(self.ambient),
            "planes": {
                "count": list(self.plane_count),
                "distance_m": list(self.plane_distance_m),
                "tilt_deg": self.plane_tilt_deg,
                "size_m": self.plane_size_m,
            },
            "turntable": {"views": self.turntable_views, "tilt_deg": self.turntable_tilt_deg},
            "board": {"spec": self.board},
            "ablation": {
                "materials": list(self.ablation_materials),
                "ambients": list(self.ablation_ambients),
            },
            "storage": {
                "shard_samples": self.shard_samples,
                "codec": self.codec,
                "level": self.level,
                "label_dtype": self.label_dtype,
                "compress_on": self.compress_on,
            },
        }

    def stored_dict(self) -> dict[str, Any]:
        """:meth:`to_dict` without ``storage.compress_on``: the configuration a store records
        in ``dataset.json`` (who compressed is recorded in its ``encoding``)."""
        out = self.to_dict()
        del out["storage"]["compress_on"]
        return out

    def identity(self) -> dict[str, Any]:
        """What decides every sample's content: the configuration without ``num_samples``
        (a store may be extended with more samples of the same configuration) and without
        ``storage.compress_on`` (who compresses changes no array)."""
        out = self.stored_dict()
        del out["num_samples"]
        return out


def _compress_on(value: Any, codec: str) -> str:
    """``storage.compress_on``: one of :data:`~virtus.data.chunkcodecs.COMPRESS_ON`; ``gpu``
    only with a codec the GPU writes (whether nvCOMP and a device are here is checked when
    a run starts: :func:`~virtus.data.chunkcodecs.plan_compression`)."""
    from virtus.data.chunkcodecs import COMPRESS_ON, GPU_CODECS

    if not isinstance(value, str) or value not in COMPRESS_ON:
        raise InputError("storage.compress_on", f"one of {', '.join(COMPRESS_ON)}", value)
    if value == "gpu" and codec not in GPU_CODECS:
        raise InputError(
            "storage.compress_on gpu", f"storage.codec {' or '.join(GPU_CODECS)}", codec
        )
    return value


def load_config(path: str | Path) -> DatasetConfig:
    """Read and validate a dataset configuration YAML file (through
    :func:`virtus.io.safeio.read_yaml`: size, UTF-8, aliases, depth, duplicate keys)."""
    path = Path(path)
    data = read_yaml(path, "dataset config", expect=dict)
    return DatasetConfig.from_dict(data, base_dir=path.resolve().parent)
