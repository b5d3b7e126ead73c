"""``DeviceDecode.to_host(only=...)``: some fields of the decode formed on the device and
copied alone, bit for bit those of the whole result (:mod:`virtus.render.jit.decode`).

As in ``test_decode.py``, on ``llvm_ad_rgb`` (the CPU twin of ``cuda_ad_rgb``), with its
sequences and synthetic frames; where ``cuda_ad_rgb`` works (a GPU machine), the bit-for-bit
comparison runs there too (the device's own kernels: contraction or fusion must not change a
bit).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tests.render.jit.test_decode import (
    HEIGHT,
    SEQUENCES,
    VARIANT,
    WHITE_BLACK,
    WIDTH,
    describe,
    direction,
    rng_for,
    synthesise,
)
from virtus.errors import InputError, VirtusError
from virtus.patterns import DecodeWarning, default_sequence
from virtus.render.backend import choose_variant
from virtus.render.jit.decode import (
    HOST_FIELDS,
    decode_on_device,
    frames_to_device,
    host_field_names,
)

ALL = tuple(HOST_FIELDS)


def assert_bitwise(fields: dict[str, np.ndarray], whole) -> None:
    """``fields`` are the same bits as ``whole``'s fields (NaN payloads included)."""
    for name, value in fields.items():
        expected = getattr(whole, name)
        assert value.dtype == np.float64 and value.shape == expected.shape, name
        assert value.flags.c_contiguous, name
        np.testing.assert_array_equal(value.view(np.uint64), expected.view(np.uint64), name)


def both(
    sequence, frames, *, precision="float64", neighbour_check=False, only=ALL, variant=VARIANT
):
    """(whole result, ``only`` fields) of one decode of ``frames``, each from a fresh
    (unevaluated) device decode."""
    device_frames = frames_to_device(frames, variant)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DecodeWarning)
        results = [
            decode_on_device(device_frames, sequence, HEIGHT, WIDTH, precision=precision)
            for _ in range(2)
        ]
        whole = results[0].to_host(sequence, neighbour_check=neighbour_check)
        fields = results[1].to_host(sequence, neighbour_check=neighbour_check, only=only)
    return whole, fields


@pytest.mark.parametrize("variant", [VARIANT, "cuda_ad_rgb"])
@pytest.mark.parametrize("name", list(SEQUENCES))
def test_fields_are_the_whole_results_bit_for_bit(name, variant) -> None:
    try:
        choose_variant(variant)
    except VirtusError:
        pytest.skip(f"{variant} does not work on this machine")
    sequence = SEQUENCES[name]()
    frames = synthesise(sequence, rng_for(f"only-{name}"))
    whole, fields = both(sequence, frames, variant=variant)
    assert list(fields) == list(ALL)
    assert np.isfinite(fields["proj_uv"]).any() and np.isnan(fields["proj_uv"]).any()
    assert_bitwise(fields, whole)
    # With the neighbour check (run on the host): the fields of the checked result.
    only = ("proj_uv", "phase_h")
    whole, fields = both(sequence, frames, neighbour_check=True, only=only, variant=variant)
    assert list(fields) == ["proj_uv", "phase_h"]
    assert_bitwise(fields, whole)


def test_float32_fields_and_an_absent_direction_are_the_whole_results() -> None:
    # Float32 maps are widened as the host widens them (proj_uv formed in float64 from
    # the float32 phase); an absent direction is NaN throughout.
    sequence = describe(direction("v", {"period": 18.0}, {"complement": True}))
    frames = synthesise(sequence, rng_for("only-float32"))
    for precision in ("float32", "float64"):
        whole, fields = both(sequence, frames, precision=precision)
        assert_bitwise(fields, whole)
        assert np.isnan(fields["proj_uv"][..., 1]).all() and np.isnan(fields["phase_h"]).all()
        assert np.isfinite(fields["modulation"]).all()


def test_proj_uv_is_interleaved_as_the_host_lays_it_out() -> None:
    sequence = default_sequence()
    frames = synthesise(sequence, rng_for("only-layout"))
    whole, fields = both(sequence, frames, only="proj_uv")
    assert list(fields) == ["proj_uv"] and fields["proj_uv"].shape == (HEIGHT, WIDTH, 2)
    assert_bitwise(fields, whole)
    whole, fields = both(sequence, frames, only=("background", "proj_uv"))
    assert list(fields) == ["background", "proj_uv"]
    assert_bitwise(fields, whole)


def test_fields_warn_as_the_whole_result_does() -> None:
    # As test_decode's: an edge-aligned code read as centre-aligned is flagged per pixel.
    def code(align: str):
        blocks = {"period": 18.0, "steps": 18}, {"complement": True, "align": align, "bits": 6}
        return describe(direction("v", *blocks) + direction("h", *blocks) + WHITE_BLACK)

    truth, wrong = code("edge"), code("centre")
    frames = synthesise(truth, rng_for("only-warn"))
    result = decode_on_device(frames_to_device(frames, VARIANT), wrong, HEIGHT, WIDTH)
    with pytest.warns(DecodeWarning, match="description"):
        result.to_host(wrong, only=("proj_uv",))
    sequence = default_sequence()  # frames of its own: no warning
    frames = synthesise(sequence, rng_for("only-quiet"))
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, HEIGHT, WIDTH)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DecodeWarning)
        result.to_host(sequence, only=("proj_uv",))


@pytest.mark.parametrize(
    "only", [(), ("proj_uv", "proj_uv"), ("mask",), ("proj_uv", "flagged"), "nonsense"]
)
def test_bad_fields_raise_input_error(only) -> None:
    with pytest.raises(InputError, match="only"):
        host_field_names(only)
    sequence = default_sequence()
    frames = synthesise(sequence, rng_for("only-bad"))
    result = decode_on_device(frames_to_device(frames, VARIANT), sequence, HEIGHT, WIDTH)
    with pytest.raises(InputError, match="only"):
        result.to_host(sequence, only=only)
