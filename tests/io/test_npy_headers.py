""".npy/.npz headers parsed and bounded by virtus itself (virtus.io.npyfile): a hostile
header is one InputError line naming the file, found before anything large is allocated;
every array virtus writes still loads exactly as np.load loads it."""

from __future__ import annotations

import io
import re
import struct
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.io.npyfile import MAX_NPY_HEADER_BYTES, parse_header_dict
from virtus.io.safeio import load_npy, load_npz

#: Most bytes a refusal may allocate (Python objects and numpy buffers, as tracemalloc
#: sees them).
PEAK_BYTES = 1 << 20


def npy(header: str, data: bytes = b"", version: tuple[int, int] = (1, 0)) -> bytes:
    """An .npy file with ``header`` as its dict text, padded as numpy pads it."""
    text = header.encode("latin1")
    width = 2 if version == (1, 0) else 4
    text += b" " * (-(8 + width + len(text) + 1) % 64) + b"\n"
    size = struct.pack("<H" if width == 2 else "<I", len(text))
    return b"\x93NUMPY" + bytes(version) + size + text + data


def header(shape: str, descr: str = "'<f8'", fortran: str = "False") -> str:
    return f"{{'descr': {descr}, 'fortran_order': {fortran}, 'shape': {shape}, }}"


def refusal(path: Path, load=load_npy) -> tuple[str, int]:
    """The message of ``load(path)``'s InputError and the peak bytes traced while refusing
    (after one call that warms caches and imports)."""
    with pytest.raises(InputError):
        load(path, "gt")
    tracemalloc.start()
    try:
        with pytest.raises(InputError) as error:
            load(path, "gt")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(error.value)
    assert "\n" not in message and str(path) in message, message
    return message, peak


# -- the three the brief names: refused in one line, nothing large allocated -----------------------

HOSTILE = {
    # ~1 KB declaring 65536 x 65536 float64 (32 GiB)
    "declares-32-GiB": (
        npy(header("(65536, 65536)"), bytes(900)),
        r"expected 34,359,738,368 data bytes for shape \(65536, 65536\) float64, got '900 bytes "
        r"\(truncated\)'",
    ),
    # numpy's literal_eval gives 2**64, then an OverflowError on the shape
    "shape-2-to-the-64": (
        npy(header("(18446744073709551616,)"), bytes(8)),
        r"expected a valid \.npy header, got 'shape entry 18446744073709551616 at column \d+ "
        r"\(2\*\*63 or more\)'",
    ),
    "malformed-dict": (
        npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3, 4, }", bytes(96)),
        r"expected a valid \.npy header, got .*at column \d+",
    ),
}  # fmt: skip


@pytest.mark.parametrize(("content", "message"), HOSTILE.values(), ids=HOSTILE.keys())
def test_hostile_headers_are_one_line_without_allocating(tmp_path, content, message) -> None:
    path = tmp_path / "hostile.npy"
    path.write_bytes(content)
    assert len(content) <= 1100
    text, peak = refusal(path)
    assert text.startswith(f"gt {path}: ")
    assert peak < PEAK_BYTES, f"{peak:,} bytes allocated to refuse it"
    assert re.search(message, text), text


# -- every other malformed header: InputError, never numpy's or Python's own exceptions ------------

MALFORMED = {
    "shape-2-to-the-63": npy(header("(9223372036854775808,)")),
    "shape-9000-digits": npy(header("(" + "9" * 9000 + ",)")),
    "negative": npy(header("(-3,)"), bytes(24)),
    "a-number-not-a-tuple": npy(header("(3)"), bytes(24)),
    "a-list": npy(header("[3]"), bytes(24)),
    "nested": npy(header("((3,),)"), bytes(24)),
    "deep-parens": npy(header("(" * 2000 + ")" * 2000)),
    "float-entry": npy(header("(3.0,)"), bytes(24)),
    "leading-zero": npy(header("(03,)"), bytes(24)),
    "65-dims": npy(header("(" + "1, " * 65 + ")"), bytes(8)),
    "call": npy(header("(3,)", descr="__import__('os').getcwd()")),
    "unterminated-string": npy("{'descr': '<f8, 'fortran_order': False, 'shape': (3,), }"),
    "escape": npy(header("(3,)", descr="'<f\\x38'"), bytes(24)),
    "structured": npy(header("(3,)", descr="[('a', '<f8')]"), bytes(24)),
    "structured-string": npy(header("(3,)", descr="'f8,i4'"), bytes(36)),
    "sub-array": npy(header("(3,)", descr="'(2,)<f8'"), bytes(48)),
    "object": npy(header("(3,)", descr="'|O'"), bytes(24)),
    "void": npy(header("(3,)", descr="'|V8'"), bytes(24)),
    "unknown-dtype": npy(header("(3,)", descr="'<x8'"), bytes(24)),
    "huge-itemsize": npy(header("(3,)", descr="'<U9999999999'")),
    "long-descr": npy(header("(3,)", descr="'" + "<f8" * 40 + "'")),
    "fortran-not-bool": npy(header("(3,)", fortran="1"), bytes(24)),
    "duplicate-key": npy("{'descr': '<f8', 'descr': '<f8', 'fortran_order': False, "
                         "'shape': (3,), }", bytes(24)),
    "unknown-key": npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3,), 'x': 1}"),
    "missing-key": npy("{'descr': '<f8', 'shape': (3,), }", bytes(24)),
    "not-a-dict": npy("('<f8', False, (3,))", bytes(24)),
    "trailing-junk": npy(header("(3,)") + " 1", bytes(24)),
    "empty-header": npy(""),
    "version-9": npy(header("(3,)"), bytes(24), version=(9, 0)),
    "header-length-2-GiB": b"\x93NUMPY\x02\x00" + struct.pack("<I", 2**31) + b"{}",
    "header-over-bound": npy(header("(3,)") + " " * MAX_NPY_HEADER_BYTES, bytes(24),
                             version=(2, 0)),
    "utf8-in-v3": npy(header("(3,)"), bytes(24), version=(3, 0)).replace(b"'<f8'", b"'\xff\xfe'"),
    "magic-only": b"\x93NUMPY",
    "half-magic": b"\x93NUM",
    "empty-file": b"",
}  # fmt: skip


@pytest.mark.parametrize("content", MALFORMED.values(), ids=MALFORMED.keys())
def test_malformed_headers_are_one_input_error_line(tmp_path, content) -> None:
    path = tmp_path / "bad.npy"
    path.write_bytes(content)
    _, peak = refusal(path)
    assert peak < PEAK_BYTES


def test_mutated_headers_only_ever_raise_input_error(tmp_path) -> None:
    # Every single-byte change of a real header (and of its length field) either loads an
    # array of the right size or is one InputError; nothing else escapes.
    buffer = io.BytesIO()
    np.save(buffer, np.arange(12.0).reshape(3, 4))
    good = buffer.getvalue()
    rng = np.random.default_rng(0)
    path = tmp_path / "m.npy"
    values = [0, 9, 10, 32, 39, 40, 41, 44, 45, 48, 57, 58, 102, 123, 125, 255]
    for position in range(6, 128):
        for value in rng.choice(values, 3, replace=False):
            data = bytearray(good)
            data[position] = value
            path.write_bytes(bytes(data))
            try:
                array = load_npy(path, "gt")
            except InputError as error:
                assert "\n" not in str(error)
            else:
                assert array.nbytes == len(good) - 128


def test_the_parser_reads_exactly_what_np_save_writes() -> None:
    assert parse_header_dict("{'descr': '<f8', 'fortran_order': True, 'shape': (), }", "h") == {
        "descr": "<f8", "fortran_order": True, "shape": (),
    }  # fmt: skip
    assert parse_header_dict('{"shape": (5,), "fortran_order": False, "descr": "|b1"}', "h")[
        "shape"
    ] == (5,)


# -- valid arrays: identical to np.load ------------------------------------------------------------


def _arrays() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(1)
    base = rng.uniform(0, 200, (5, 7))
    arrays: dict[str, np.ndarray] = {}
    for dtype in ("float32", "float64", "uint8", "uint16", "bool", "int32", "int64", ">f8"):
        array = (base > 100) if dtype == "bool" else base.astype(dtype)
        arrays[dtype] = array
        arrays[f"{dtype}-fortran"] = np.asfortranarray(array)
        arrays[f"{dtype}-3d-fortran"] = np.asfortranarray(np.stack([array, array, array], -1))
    arrays["0-d"] = np.array(3.25)
    arrays["0-d-uint16"] = np.array(7, np.uint16)
    arrays["empty"] = np.zeros((0, 5), np.float32)
    arrays["empty-fortran"] = np.asfortranarray(np.zeros((4, 0, 2), np.uint16))
    arrays["empty-1d"] = np.zeros(0, bool)
    arrays["str"] = np.array(["episode-3", "x"])
    arrays["complex"] = base.astype(np.complex128)
    arrays["large"] = rng.uniform(size=(300, 400))
    return arrays


ARRAYS = _arrays()


def _same(got: np.ndarray, want: np.ndarray) -> None:
    assert got.dtype == want.dtype and got.shape == want.shape
    assert got.flags.c_contiguous == want.flags.c_contiguous
    assert got.flags.f_contiguous == want.flags.f_contiguous
    assert got.flags.writeable
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("name", ARRAYS)
def test_valid_arrays_load_as_np_load_loads_them(tmp_path, name) -> None:
    path = tmp_path / "a.npy"
    np.save(path, ARRAYS[name])
    _same(load_npy(path, "gt"), np.load(path))


@pytest.mark.parametrize("version", [(1, 0), (2, 0), (3, 0)])
def test_every_format_version_loads(tmp_path, version) -> None:
    path = tmp_path / "v.npy"
    with open(path, "wb") as stream:
        np.lib.format.write_array(stream, ARRAYS["float64-fortran"], version=version)
    _same(load_npy(path, "gt"), np.load(path))


# -- .npz ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("save", [np.savez, np.savez_compressed])
def test_npz_archives_load_as_np_load_loads_them(tmp_path, save) -> None:
    path = tmp_path / "a.npz"
    save(path, **ARRAYS)
    arrays = load_npz(path, "pose file")
    with np.load(path) as reference:
        assert sorted(arrays) == sorted(reference.files)
        for key in reference.files:
            _same(arrays[key], reference[key])


def _declare(path: Path, member: int, size: int) -> None:
    """Make the central directory declare ``size`` uncompressed bytes for one member."""
    data = bytearray(path.read_bytes())
    at = -1
    for _ in range(member + 1):
        at = data.index(b"PK\x01\x02", at + 1)
    data[at + 24 : at + 28] = struct.pack("<I", size)
    path.write_bytes(bytes(data))


def test_a_zip_bomb_is_refused_before_decompressing(tmp_path) -> None:
    bomb = tmp_path / "bomb.npz"
    np.savez_compressed(bomb, a=np.zeros((1000, 1000), np.uint8))
    _declare(bomb, 0, 0xFFFFFFF0)  # 4 GiB from a few kB: more than DEFLATE can produce
    text, peak = refusal(bomb, load_npz)
    assert "not a readable gt" in text and "zip bomb" in text and peak < PEAK_BYTES
    # honest, but over the caller's bound: refused on the declared size alone
    big = tmp_path / "big.npz"
    np.savez_compressed(big, a=np.zeros((1000, 1000), np.uint8))
    with pytest.raises(InputError, match=r"at most 65,536 uncompressed bytes"):
        load_npz(big, "pose file", max_bytes=1 << 16)


def test_npz_members_are_checked_like_npy_files(tmp_path) -> None:
    lying = tmp_path / "lying.npz"
    with zipfile.ZipFile(lying, "w") as archive:
        archive.writestr("ok.npy", npy(header("(3,)"), bytes(24)))
        archive.writestr("big.npy", npy(header("(65536, 65536)"), bytes(900)))
    text, peak = refusal(lying, load_npz)
    assert "member big.npy: expected 34,359,738,368 data bytes" in text and peak < PEAK_BYTES
    for name, content in {
        "overflow.npy": npy(header("(18446744073709551616,)")),
        "notes.txt": b"hello",
        "pickle.npy": npy(header("(3,)", descr="'|O'"), bytes(24)),
    }.items():
        path = tmp_path / f"{name}.npz"
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr(name, content)
        text, _ = refusal(path, load_npz)
        assert name in text and "not a readable gt" in text
    corrupt = tmp_path / "crc.npz"
    np.savez(corrupt, a=np.arange(100.0))
    data = bytearray(corrupt.read_bytes())
    data[data.index(b"\x00\x00\xf0\x3f") + 3] ^= 0xFF  # the bytes of 1.0: data, not header
    corrupt.write_bytes(bytes(data))
    text, _ = refusal(corrupt, load_npz)
    assert "CRC" in text
