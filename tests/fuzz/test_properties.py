"""Property-based fuzzing (Hypothesis) of the structured inputs: sequence descriptions, rigs,
scenes, sensor and projector files and dataset configurations.

Each strategy builds documents of the reader's own shape -- the keys it knows, values drawn
from plausible ones *or* from anything JSON can hold (huge and non-finite numbers, wrong
types, nesting) -- written as the YAML or JSON file the user would give; the property is the
readers' contract: the file is read or refused with virtus's own error, never anything else
(``tests/fuzz/targets.py``).

Profiles: ``virtus-fuzz-ci`` (fixed seed: ``derandomize=True``, a small example budget, no
database) runs in CI; ``VIRTUS_FUZZ_LONG=1`` selects ``virtus-fuzz-long``
(``VIRTUS_FUZZ_EXAMPLES`` examples per property, default 20,000, no deadline, random).
"""

from __future__ import annotations

import itertools
import json
import os
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.fuzz.cases import TALLY
from tests.fuzz.mutate import _get, _paths, _replace
from tests.fuzz.targets import TARGETS, run_case

LONG = os.environ.get("VIRTUS_FUZZ_LONG", "") not in ("", "0")
_COMMON: dict[str, Any] = {
    "deadline": None,
    "database": None,
    "suppress_health_check": [HealthCheck.too_slow, HealthCheck.data_too_large],
}
settings.register_profile(
    "virtus-fuzz-ci",
    max_examples=int(os.environ.get("VIRTUS_FUZZ_CI_EXAMPLES", "100")),
    derandomize=True,
    **_COMMON,
)
settings.register_profile(
    "virtus-fuzz-long",
    max_examples=int(os.environ.get("VIRTUS_FUZZ_EXAMPLES", "20000")),
    **_COMMON,
)
#: The profile of these properties only (the global one is left alone).
PROFILE = settings.get_profile("virtus-fuzz-long" if LONG else "virtus-fuzz-ci")

# -- building blocks ------------------------------------------------------------------------

#: Numbers that break arithmetic: extremes, non-finite, just out of range.
nasty_numbers = st.one_of(
    st.sampled_from([0, -1, 1, 2, 0.5, -0.0, 2**31, 2**32, 2**63, 2**64, 10**30, 1e308, 5e-324]),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
)
scalars = st.one_of(nasty_numbers, st.booleans(), st.none(), st.text(max_size=12))
#: Anything JSON can hold, small.
anything = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


@st.composite
def corrupted(draw: Any, valid: st.SearchStrategy, most: int = 2) -> Any:
    """A valid document with 0..``most`` corruptions at key paths Hypothesis picks: a value
    replaced by anything (a wrong type, an extreme number, nesting), a key dropped, an
    unknown key added. A third of the documents stay valid, so the readers' later checks
    (and their acceptance) are reached as well as their first ones."""
    doc = draw(valid)
    for _ in range(draw(st.integers(0, most))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        how = draw(st.sampled_from(["set", "set", "drop", "add"]))
        if how == "drop" and path:
            parent = _get(doc, path[:-1])
            if isinstance(parent, dict):
                parent = {k: v for k, v in parent.items() if k != path[-1]}
            else:
                parent = [v for i, v in enumerate(parent) if i != path[-1]]
            doc = _replace(doc, path[:-1], parent)
        elif how == "add" and isinstance(_get(doc, path), dict):
            key = draw(st.sampled_from(["unknown", "", "type", "kind", "Width"]))
            doc = _replace(doc, path, {**_get(doc, path), key: draw(anything)})
        else:
            doc = _replace(doc, path, draw(st.one_of(anything, nasty_numbers)))
    return doc


def floats(low: float, high: float) -> st.SearchStrategy:
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


def vector(length: int, low: float, high: float) -> st.SearchStrategy:
    return st.lists(floats(low, high), min_size=length, max_size=length)


@st.composite
def rotations(draw: Any) -> list[list[float]]:
    from virtus.geometry.transforms import Pose

    angles = draw(vector(3, -180, 180))
    return Pose.from_euler("xyz", angles, t=(0, 0, 0)).R.tolist()


# -- strategies per reader ------------------------------------------------------------------


@st.composite
def valid_sequences(draw: Any) -> dict[str, Any]:
    """Descriptions the reader should take: phase + Gray code, a code alone, heterodyne
    phase, OpenCV's preset, or the per-frame form of such a sequence."""
    from virtus.patterns.codings import gray_bits_needed

    width, height = draw(st.integers(8, 1024)), draw(st.integers(8, 1024))
    if draw(st.integers(0, 5)) == 0:
        doc: dict[str, Any] = {"width": width, "height": height, "preset": "opencv_graycode"}
        if draw(st.booleans()):
            doc["white_black"] = draw(st.sampled_from([True, False, ["black", "white"]]))
        return doc
    blocks: list[dict[str, Any]] = []
    for direction, span in (("v", width), ("h", height)):
        kind = draw(st.sampled_from(["phase+code", "code", "heterodyne", "none"]))
        if kind == "none" and blocks:
            continue
        steps = draw(st.integers(3, 12))
        profile = draw(st.sampled_from(["sinusoidal", "binary", "dithered"]))
        if kind == "heterodyne":
            base = draw(st.integers(8, 32))
            blocks.append({"kind": "phase", "direction": direction, "steps": steps,
                           "periods": [base, base * 8 / 7, base * 8 / 7 * 9 / 8]})  # fmt: skip
            continue
        code = draw(st.sampled_from(["gray", "binary"]))
        complement = draw(st.booleans())
        inverted = draw(st.booleans())
        order = draw(st.sampled_from(["msb_first", "lsb_first"]))
        if kind == "code":
            bits = max(1, (span - 1).bit_length()) + draw(st.integers(0, 1))
            blocks.append({"kind": code, "direction": direction, "bits": bits,
                           "bit_order": order, "inverted": inverted})  # fmt: skip
            continue
        period = draw(st.integers(4, 64))
        bits = gray_bits_needed(span, period, complement) + draw(st.integers(0, 1))
        blocks.append({"kind": "phase", "direction": direction, "period": period,
                       "steps": steps, "profile": profile,
                       "sign": draw(st.sampled_from([1, -1]))})  # fmt: skip
        blocks.append({"kind": code, "direction": direction, "period": period,
                       "bits": bits, "complement": complement, "inverted": inverted,
                       "bit_order": order})  # fmt: skip
    blocks += [{"kind": "white"}, {"kind": "black", "count": draw(st.integers(1, 3))}]
    doc = {"format": "virtus.pattern_sequence", "version": 2, "width": width,
           "height": height, "blocks": blocks}  # fmt: skip
    if draw(st.integers(0, 3)) == 0:  # the lossless per-frame form
        from virtus.errors import VirtusError
        from virtus.patterns import PatternSequence

        try:
            doc = PatternSequence.from_dict(doc).to_dict()
        except VirtusError:
            pass
    return doc


@st.composite
def valid_intrinsics(draw: Any) -> dict[str, Any]:
    width, height = draw(st.integers(8, 4096)), draw(st.integers(8, 4096))
    f = draw(floats(50, 8000))
    return {
        "width": width,
        "height": height,
        "K": [
            [f, 0.0, draw(floats(0, width))],
            [0.0, f * draw(floats(0.9, 1.1)), draw(floats(0, height))],
            [0.0, 0.0, 1.0],
        ],  # fmt: skip
        "dist": draw(st.sampled_from([0, 4, 5, 8]).flatmap(lambda n: vector(n, -0.3, 0.3))),
    }


valid_rigs = st.fixed_dictionaries(
    {
        "units": st.just("m"),
        "camera": valid_intrinsics(),
        "projector": valid_intrinsics(),
        "proj2cam": st.fixed_dictionaries({"R": rotations(), "t": vector(3, -1, 1)}),
    }
)

poses = st.one_of(
    st.fixed_dictionaries(
        {"euler_deg": vector(3, -90, 90), "t": vector(3, -0.5, 0.5)},
        optional={"seq": st.sampled_from(["xyz", "zyx"])},
    ),  # fmt: skip
    st.fixed_dictionaries({"R": rotations(), "t": vector(3, -0.5, 0.5)}),
)
materials = st.fixed_dictionaries(
    {},
    optional={
        "albedo": floats(0, 1) | st.sampled_from(["texture.png", "texture.npy"]),
        "roughness": floats(0, 1),
        "specular": floats(0, 1),
        "metal": st.booleans(),
    },
)
scene_objects = st.one_of(
    st.fixed_dictionaries({"type": st.just("sphere"), "radius_m": floats(0.001, 0.5),
                           "center_m": vector(3, -0.5, 2)}, optional={"material": materials}),
    st.fixed_dictionaries({"type": st.just("box"), "size_m": vector(3, 0.001, 0.5)},
                          optional={"pose": poses, "material": materials}),
    st.fixed_dictionaries({"type": st.just("plane"), "size_m": vector(2, 0.001, 2)},
                          optional={"pose": poses, "material": materials}),
    st.fixed_dictionaries(
        {"type": st.just("mesh"), "path": st.sampled_from(["part.stl", "part.obj"])},
        optional={"scale_to_m": floats(1e-4, 0.01), "pose": poses, "material": materials},
    ),
    st.fixed_dictionaries(
        {"type": st.just("textured_plane"), "size_m": vector(2, 0.01, 1),
         "texture": st.sampled_from(["texture.png", "texture.npy"])},
        optional={"pose": poses, "material": materials},
    ),
)  # fmt: skip
lights = st.one_of(
    st.fixed_dictionaries({"type": st.just("area"), "size_m": vector(2, 0.01, 1),
                           "radiance": floats(0.01, 10)}, optional={"pose": poses}),
    st.fixed_dictionaries({"type": st.just("environment"), "radiance": floats(0.01, 1)}),
)  # fmt: skip
valid_scenes = st.fixed_dictionaries(
    {"objects": st.lists(scene_objects, max_size=4)},
    optional={
        "background": st.fixed_dictionaries(
            {"type": st.just("plane"), "size_m": vector(2, 0.5, 3)}, optional={"pose": poses}
        ),
        "ambient": floats(0, 1),
        "lights": st.lists(lights, max_size=2),
    },
)


def _preset_like(presets: dict[str, Any]) -> st.SearchStrategy:
    """A preset's parameters (``to_dict`` without its name), some fields dropped."""

    def strip(model: Any) -> dict[str, Any]:
        data = dict(model.to_dict())
        data.pop("name", None)
        return data

    return st.sampled_from([strip(m) for m in presets.values()]).flatmap(
        lambda data: st.sets(st.sampled_from(sorted(data)), max_size=3).map(
            lambda drop: {k: v for k, v in data.items() if k not in drop}
        )
    )


def _sensor_presets() -> dict[str, Any]:
    from virtus.sensor.camera import SENSOR_PRESETS

    return SENSOR_PRESETS


def _projector_presets() -> dict[str, Any]:
    from virtus.sensor.projector import PROJECTOR_PRESETS

    return PROJECTOR_PRESETS


pair = st.tuples(floats(0.01, 0.1), floats(0.1, 0.3)).map(list)
valid_dataset_configs = st.fixed_dictionaries(
    {
        "mode": st.sampled_from(["training", "training", "scan", "ablation", "calibration"]),
        "seed": st.integers(0, 2**31),
        "num_samples": st.integers(1, 1000),
    },
    optional={
        "splits": st.just({"train": 0.8, "val": 0.1, "test": 0.1}),
        "rig": st.sampled_from([{"file": "rig.json"}, {"camera_scale": 0.5}, {}]),
        "render": st.fixed_dictionaries({"spp": st.integers(1, 16), "bounces": st.integers(0, 4)}),
        "sensor": st.lists(st.sampled_from(["ideal", "imx174", "webcam"]), min_size=1, max_size=3),
        "projector": st.lists(
            st.sampled_from(["ideal", "lightcrafter", "paper"]), min_size=1, max_size=2
        ),  # fmt: skip
        "fringes": st.fixed_dictionaries(
            {
                "codings": st.lists(
                    st.sampled_from(["gray", "heterodyne"]), min_size=1, max_size=2
                ),
                "steps": st.lists(st.integers(3, 16), min_size=1, max_size=2),
                "periods": st.lists(st.integers(8, 64), min_size=1, max_size=2),
            }
        ),  # fmt: skip
        "objects": st.fixed_dictionaries(
            {
                "sources": st.lists(
                    st.one_of(
                        st.fixed_dictionaries(
                            {
                                "type": st.just("sphere"),
                                "radius_m": pair,
                                "instances": st.integers(1, 64),
                            }
                        ),
                        st.fixed_dictionaries(
                            {
                                "type": st.just("box"),
                                "size_m": pair,
                                "instances": st.integers(1, 64),
                            }
                        ),
                        st.fixed_dictionaries(
                            {
                                "type": st.just("freeform"),
                                "size_m": pair,
                                "subdivisions": st.integers(1, 5),
                            }
                        ),
                    ),
                    min_size=1,
                    max_size=3,
                )
            },
            optional={
                "count": st.just([1, 3]),
                "distance_m": st.just([0.9, 1.1]),
                "field": floats(0.1, 1),
            },
        ),  # fmt: skip
        "ambient": st.just([0.0, 0.2]),
        "storage": st.fixed_dictionaries(
            {},
            optional={
                "shard_samples": st.integers(1, 64),
                "codec": st.sampled_from(["blosc-zstd", "blosc-lz4", "none"]),
                "level": st.integers(0, 9),
                "label_dtype": st.sampled_from(["float32", "float16"]),
            },
        ),  # fmt: skip
    },
)

sequences = corrupted(valid_sequences())
rigs = corrupted(valid_rigs)
scenes = corrupted(valid_scenes)
sensors = corrupted(st.deferred(lambda: _preset_like(_sensor_presets())))
projectors = corrupted(st.deferred(lambda: _preset_like(_projector_presets())))
dataset_configs = corrupted(valid_dataset_configs)

# -- the properties -------------------------------------------------------------------------

_counter = itertools.count()


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz-properties")


def _text(doc: Any, as_json: bool) -> bytes:
    if as_json:
        return json.dumps(doc, allow_nan=True).encode()
    return yaml.safe_dump(doc, allow_unicode=True).encode()


def _check(reader: str, doc: Any, as_json: bool, scratch: Path) -> None:
    """The reader's contract on ``doc`` written as a file (raises on a broken one)."""
    suffix = ".json" if as_json else ".yaml"
    TALLY["hypothesis"] += 1
    run_case(TARGETS[reader], _text(doc, as_json), "input" + suffix, scratch / f"p{next(_counter)}")


@settings(PROFILE)
@given(doc=sequences, as_json=st.booleans())
def test_sequence_descriptions(doc, as_json, scratch):
    _check("sequence", doc, as_json, scratch)


@settings(PROFILE)
@given(doc=rigs, as_json=st.booleans())
def test_rigs(doc, as_json, scratch):
    if not as_json:  # a rig YAML is OpenCV's FileStorage: the rig schema is JSON only
        doc = {"rig": doc}
    _check("calibration", doc, True, scratch)


@settings(PROFILE)
@given(doc=scenes)
def test_scenes(doc, scratch):
    _check("scene", doc, False, scratch)


@settings(PROFILE)
@given(doc=sensors, as_json=st.booleans())
def test_sensor_files(doc, as_json, scratch):
    _check("sensor", doc, as_json, scratch)


@settings(PROFILE)
@given(doc=projectors, as_json=st.booleans())
def test_projector_files(doc, as_json, scratch):
    _check("projector", doc, as_json, scratch)


@settings(PROFILE)
@given(doc=dataset_configs)
def test_dataset_configs(doc, scratch):
    _check("dataset_config", doc, False, scratch)
