"""The guarded reading layer: every malformed input is one InputError line naming the file."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

from virtus.errors import InputError
from virtus.io import safeio


def one_line(error: pytest.ExceptionInfo) -> str:
    """The message of a raised InputError, checked to be a single line."""
    message = str(error.value)
    assert "\n" not in message
    return message


# -- files and text ----------------------------------------------------------------------------


def test_missing_file_and_folder_name_what_and_path(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"^rig: expected an existing JSON file, got .*nope") as e:
        safeio.read_json(tmp_path / "nope.json", "rig")
    one_line(e)
    with pytest.raises(InputError, match=r"^scene: expected an existing YAML file, .*\(a folder\)"):
        safeio.read_yaml(tmp_path, "scene")


def test_size_is_bounded_before_reading(tmp_path: Path) -> None:
    path = tmp_path / "big.json"
    path.write_text("[" + "0, " * 100 + "0]")
    with pytest.raises(InputError, match=r"big\.json: expected a JSON file of at most 64 bytes"):
        safeio.read_json(path, "rig", max_bytes=64)


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b'{"width": 960}\x00\x00', r"expected UTF-8 text, got 'a binary file \(NUL byte at 14\)'"),
        (b'{"name": "caf\xe9"}', r"expected UTF-8 text, got 'not UTF-8 text \(byte 0xe9 at 13\)'"),
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", r"binary file"),
    ],
    ids=["nul", "latin-1", "png"],
)
def test_binary_and_non_utf8_text_is_refused(tmp_path: Path, content: bytes, problem: str) -> None:
    path = tmp_path / "rig.json"
    path.write_bytes(content)
    with pytest.raises(InputError, match=rf"^rig .*rig\.json: .*{problem}") as e:
        safeio.read_json(path, "rig")
    one_line(e)


def test_utf8_with_byte_order_mark_is_read(tmp_path: Path) -> None:
    path = tmp_path / "a.json"
    path.write_bytes('\ufeff{"name": "café"}'.encode())
    assert safeio.read_json(path, "rig", expect=dict) == {"name": "café"}


# -- JSON ----------------------------------------------------------------------------------------


def test_deep_json_is_refused_before_parsing_not_recursion_error() -> None:
    deep = "[" * 100_000 + "]" * 100_000
    with pytest.raises(InputError, match=r"^doc: expected JSON nested at most 64 deep, got"):
        safeio.parse_json(deep, "doc")
    # brackets inside strings do not count; the bound itself is accepted
    inside = '{"a": "[[[[[[[[[[{{{{{"}'
    assert safeio.parse_json(inside, "doc", max_depth=1) == {"a": "[[[[[[[[[[{{{{{"}
    ok = "[" * safeio.MAX_DEPTH + "]" * safeio.MAX_DEPTH
    assert safeio.parse_json(ok, "doc") is not None
    # a depth bound above the interpreter's recursion limit still ends as InputError
    with pytest.raises(InputError, match="too deep to parse"):
        safeio.parse_json(deep, "doc", max_depth=10**6)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ('{"fx": 1,\n "fy": }', r"expected valid JSON, got 'Expecting value at line 2, column 8'"),
        ("", r"Expecting value at line 1, column 1"),
        ('{"fx": NaN}', r"expected finite numbers \(JSON has no NaN or Infinity\), got 'NaN'"),
        ('{"fx": -Infinity}', r"got '-Infinity'"),
        ('{"fx": 1e999}', r"expected numbers within float64 range, got '1e999'"),
        ('{"fx": 1' + "0" * 400 + "}", r"expected numbers within float64 range, got '1000"),
        ('{"fx": 1, "fx": 2}', r"expected each key once per object, got \"key 'fx' twice\""),
        ('{"n": ' + "9" * 5000 + "}", r"expected valid JSON, got 'Exceeds the limit"),
    ],
    ids=["syntax", "empty", "nan", "infinity", "overflow", "int-overflow", "duplicate", "huge-int"],
)
def test_bad_json_gives_one_line(text: str, problem: str) -> None:
    with pytest.raises(InputError, match=rf"^rig .*a\.json: .*{problem}") as e:
        safeio.parse_json(text, "rig /tmp/a.json")
    one_line(e)


def test_nan_can_be_allowed_for_reports() -> None:
    value = safeio.parse_json('{"radius_std": NaN}', "report", allow_nan=True)
    assert np.isnan(value["radius_std"])


@pytest.mark.parametrize(
    ("text", "got"),
    [("[1, 2]", "a JSON array"), ('"rig"', "a JSON string"), ("3.5", "a JSON number"),
     ("null", "JSON null"), ("true", "JSON true/false")],
)  # fmt: skip
def test_json_of_the_wrong_kind_is_refused(text: str, got: str) -> None:
    with pytest.raises(InputError, match=rf"^rig: expected a JSON object, got '{got}'"):
        safeio.parse_json(text, "rig", expect=dict)
    with pytest.raises(InputError, match=r"expected a JSON array, got 'a JSON object'"):
        safeio.parse_json("{}", "list", expect=list)


# -- YAML ----------------------------------------------------------------------------------------


def alias_bomb(levels: int = 9, width: int = 9) -> str:
    """A "billion laughs" document: ``width ** levels`` leaves once aliases are expanded."""
    lines = ["a0: &a0 [" + ", ".join(["lol"] * width) + "]"]
    for level in range(1, levels):
        lines.append(f"a{level}: &a{level} [" + ", ".join([f"*a{level - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


def test_alias_bomb_fails_fast_with_a_clear_message() -> None:
    # 9 ** 9 = 387 million nodes once expanded: refused while composing, before any
    # expansion (milliseconds; expanding it would take minutes and gigabytes).
    with pytest.raises(InputError, match=r"^bomb: expected at most 2,000,000 YAML nodes") as e:
        safeio.parse_yaml(alias_bomb(), "bomb")
    assert "alias bomb" in one_line(e)
    # a small document with a few aliases is fine
    assert safeio.parse_yaml(alias_bomb(2, 3), "small")["a1"] == [["lol"] * 3] * 3


def test_too_many_aliases_are_refused() -> None:
    text = "a: &a 1\nb: [" + ", ".join(["*a"] * (safeio.MAX_YAML_ALIASES + 1)) + "]\n"
    with pytest.raises(InputError, match=r"expected at most 1,000 YAML aliases"):
        safeio.parse_yaml(text, "doc")


def test_recursive_anchor_and_deep_yaml_are_refused() -> None:
    with pytest.raises(InputError, match=r"expected no recursive YAML anchors, got 'alias \*a"):
        safeio.parse_yaml("a: &a [1, *a]\n", "doc")
    with pytest.raises(InputError, match=r"expected YAML nested at most 64 deep"):
        safeio.parse_yaml("[" * 100_000, "doc")
    with pytest.raises(InputError, match=r"expected YAML nested at most 3 deep"):
        safeio.parse_yaml("a: {b: {c: {d: 1}}}", "doc", max_depth=3)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("objects:\n  - radius_m: [0.1\n", r"expected valid YAML, got .* line \d+, column \d+"),
        ("a: 1\nb: 2\na: 3\n", r"expected each key once per mapping, got .*'a' twice at line 3"),
        ("radius_m: .nan\n", r"expected finite numbers, got '\.nan at line 1'"),
        ("radius_m: -.inf\n", r"got '-\.inf at line 1'"),
        ("radius_m: 1.0e+400\n", r"got '1\.0e\+400 at line 1'"),
        ("seed: 1" + "0" * 400 + "\n", r"expected numbers within float64 range, got '1000"),
        ("a: !!python/object/apply:os.system [ls]\n", r"expected valid YAML, got .*constructor"),
        ("a: *missing\n", r"expected valid YAML, got .*undefined alias"),
        ("n: " + "9" * 5000 + "\n", r"expected valid YAML values, got 'Exceeds the limit"),
    ],
    ids=["syntax", "duplicate", "nan", "inf", "overflow", "int-overflow", "python-tag", "undefined",
         "huge-int"],
)  # fmt: skip
def test_bad_yaml_gives_one_line(text: str, problem: str) -> None:
    with pytest.raises(InputError, match=rf"^scene s\.yaml: .*{problem}") as e:
        safeio.parse_yaml(text, "scene s.yaml")
    one_line(e)


def test_yaml_merge_keys_and_kinds() -> None:
    data = safeio.parse_yaml("base: &b {x: 1, y: 2}\nd:\n  <<: *b\n  x: 3\n", "doc", expect=dict)
    assert data["d"] == {"x": 3, "y": 2}
    with pytest.raises(InputError, match=r"^doc: expected a YAML mapping, got 'a YAML sequence'"):
        safeio.parse_yaml("- 1\n- 2\n", "doc", expect=dict)
    with pytest.raises(InputError, match=r"got 'an empty YAML document'"):
        safeio.parse_yaml("# nothing\n", "doc", expect=dict)
    with pytest.raises(InputError, match=r"got 'a YAML scalar'"):
        safeio.parse_yaml("just text", "doc", expect=dict)


def test_read_yaml_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "scene.yaml"
    path.write_text(alias_bomb())
    with pytest.raises(InputError, match=r"^scene .*scene\.yaml: expected at most"):
        safeio.read_yaml(path, "scene")


# -- .npy ----------------------------------------------------------------------------------------


def test_npy_round_trip_and_checks(tmp_path: Path) -> None:
    array = np.arange(12.0).reshape(3, 4)
    np.save(tmp_path / "a.npy", array)
    np.testing.assert_array_equal(safeio.load_npy(tmp_path / "a.npy", "gt"), array)
    np.save(tmp_path / "f.npy", np.asfortranarray(array))
    np.testing.assert_array_equal(safeio.load_npy(tmp_path / "f.npy", "gt", shape=(3, 4)), array)
    loaded = safeio.load_npy(tmp_path / "a.npy", "gt", dtype=(np.float32, np.float64))
    assert loaded.dtype == np.float64
    with pytest.raises(InputError, match=r"^gt .*a\.npy: expected an array of dtype uint16, got"):
        safeio.load_npy(tmp_path / "a.npy", "gt", dtype=np.uint16)
    with pytest.raises(
        InputError, match=r"expected an array of shape \(N, 3\), got 'shape \(3, 4\)'"
    ):
        safeio.load_npy(tmp_path / "a.npy", "gt", shape=(None, 3))


def test_pickled_arrays_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "obj.npy"
    np.save(path, np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    with pytest.raises(InputError, match=r"pickled arrays are refused") as e:
        safeio.load_npy(path, "gt")
    assert "obj.npy" in one_line(e)
    (tmp_path / "raw.npy").write_bytes(pickle.dumps(np.zeros(3)))
    with pytest.raises(InputError, match=r"got 'pickled data \(pickles are refused\)'"):
        safeio.load_npy(tmp_path / "raw.npy", "gt")


@pytest.mark.parametrize(
    ("cut", "problem"),
    [
        (slice(0, -8), r"expected 96 data bytes for shape \(3, 4\) float64, got '88 bytes \(trunc"),
        (slice(0, 30), r"expected a readable \.npy file"),
        (slice(10, None), r"expected a \.npy file, got 'no \.npy header \(bad magic\)'"),
    ],
    ids=["truncated-data", "truncated-header", "no-magic"],
)  # fmt: skip
def test_truncated_and_corrupt_npy_are_refused(tmp_path: Path, cut: slice, problem: str) -> None:
    np.save(tmp_path / "a.npy", np.arange(12.0).reshape(3, 4))
    path = tmp_path / "bad.npy"
    path.write_bytes((tmp_path / "a.npy").read_bytes()[cut])
    with pytest.raises(InputError, match=rf"^gt .*bad\.npy: {problem}") as e:
        safeio.load_npy(path, "gt")
    one_line(e)


def test_npy_with_extra_bytes_or_a_lying_header_is_refused(tmp_path: Path) -> None:
    np.save(tmp_path / "a.npy", np.zeros(4, np.uint8))
    raw = (tmp_path / "a.npy").read_bytes()
    (tmp_path / "extra.npy").write_bytes(raw + b"\x00")
    with pytest.raises(InputError, match=r"got '5 bytes \(extra data\)'"):
        safeio.load_npy(tmp_path / "extra.npy", "gt")
    # a header announcing 10^12 elements over 4 bytes of data: refused, nothing allocated
    big = np.lib.format.header_data_from_array_1_0(np.zeros(4, np.uint8))
    big["shape"] = (10**6, 10**6)
    with open(tmp_path / "lying.npy", "wb") as stream:
        np.lib.format.write_array_header_1_0(stream, big)
        stream.write(b"\x00" * 4)
    with pytest.raises(InputError, match=r"expected 1,000,000,000,000 data bytes .*truncated"):
        safeio.load_npy(tmp_path / "lying.npy", "gt")


# -- keys ----------------------------------------------------------------------------------------


def test_unknown_keys_are_refused_with_a_suggestion() -> None:
    allowed = ("width", "height", "K", "dist")
    with pytest.raises(InputError) as e:
        safeio.check_keys({"width": 1, "distortion": [0.1]}, allowed, "camera")
    assert one_line(e) == (
        "camera: expected only the keys width, height, K, dist, "
        "got \"unknown key 'distortion' (did you mean 'dist'?)\""
    )
    with pytest.raises(InputError, match=r"unknown keys 'k' \(did you mean 'K'\?\), 'zoom'"):
        safeio.check_keys({"k": 1, "zoom": 2}, allowed, "camera")
    with pytest.raises(InputError, match=r"did you mean 'height'"):
        safeio.check_keys({"hieght": 1}, allowed, "camera")
    with pytest.raises(InputError, match=r"^camera: expected an object with the keys .*'list'"):
        safeio.check_keys([1, 2], allowed, "camera")
    assert safeio.check_keys({"K": 1}, allowed, "camera") == {"K": 1}
    assert safeio.closest_key("focal", allowed) is None


def test_npz_files_are_read_without_pickles_and_refused_in_one_line(tmp_path):
    from virtus.errors import VirtusError
    from virtus.io.safeio import load_npz

    good = tmp_path / "good.npz"
    np.savez(good, a=np.arange(3), b=np.eye(2))
    arrays = load_npz(good, "pose file")
    assert sorted(arrays) == ["a", "b"]
    np.testing.assert_array_equal(arrays["b"], np.eye(2))
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, a=np.array([{"x": 1}], dtype=object))
    garbage = tmp_path / "garbage.npz"
    garbage.write_bytes(b"not an archive")
    zip_header = tmp_path / "zip_header.npz"
    zip_header.write_bytes(b"PK\x03\x04 then nothing of a zip archive")
    for path in (pickled, garbage, zip_header, tmp_path / "missing.npz"):
        with pytest.raises(VirtusError, match=r"not a readable pose file"):
            load_npz(path, "pose file")


# -- size bounds, at the byte ------------------------------------------------------------------


def test_npy_one_byte_over_the_bound_is_refused(tmp_path: Path) -> None:
    # The bound is in bytes: a file of exactly max_bytes is read, one byte more is refused
    # (before reading), as is an array whose data alone exceeds it.
    path = tmp_path / "a.npy"
    np.save(path, np.arange(1000, dtype=np.uint8))
    size = path.stat().st_size
    assert size > 1000
    assert safeio.load_npy(path, "gt", max_bytes=size).size == 1000
    with pytest.raises(InputError, match=rf"at most {size - 1:,} bytes, got '{size:,} bytes'"):
        safeio.load_npy(path, "gt", max_bytes=size - 1)
    # The header's own check: data bytes against the bound, whatever the file check did.
    from virtus.io.npyfile import read_npy_header

    with open(path, "rb") as stream:
        assert read_npy_header(stream, "gt", size=size, max_bytes=1000).nbytes == 1000
    with open(path, "rb") as stream, pytest.raises(InputError, match="at most 999 bytes"):
        read_npy_header(stream, "gt", size=size, max_bytes=999)


def test_npz_one_byte_over_the_uncompressed_bound_is_refused(tmp_path: Path) -> None:
    # 100 kB of zeros deflate to a few hundred bytes: the file is far below the bound, its
    # declared uncompressed size is what counts.
    path = tmp_path / "z.npz"
    np.savez_compressed(path, zeros=np.zeros(100_000, np.uint8))
    import zipfile

    with zipfile.ZipFile(path) as archive:
        declared = sum(info.file_size for info in archive.infolist())
    assert path.stat().st_size < 2000 < declared
    assert safeio.load_npz(path, "pose file", max_bytes=declared)["zeros"].size == 100_000
    with pytest.raises(InputError, match="uncompressed bytes"):
        safeio.load_npz(path, "pose file", max_bytes=declared - 1)


def test_default_array_bound_holds_a_capture_and_no_more_than_a_few_gigabytes() -> None:
    import inspect

    # 52 frames of 4096 x 4096 uint16 (1.7 GB) must fit; a bound 1024 times too large would
    # let a lying file allocate terabytes.
    assert 52 * 4096 * 4096 * 2 <= safeio.MAX_ARRAY_BYTES <= 4 * 2**30
    for function in (safeio.load_npy, safeio.load_npz):
        default = inspect.signature(function).parameters["max_bytes"].default
        assert default == safeio.MAX_ARRAY_BYTES, function.__name__


def test_a_texture_just_over_its_bound_is_refused(tmp_path: Path, monkeypatch) -> None:
    # The texture bound is read when a texture is loaded: patched small, a .npy texture one
    # byte over it is refused, one at it is read.
    from virtus.scene import model

    path = tmp_path / "t.npy"
    np.save(path, np.full((8, 8), 0.5))
    size = path.stat().st_size
    monkeypatch.setattr(model, "MAX_TEXTURE_BYTES", size)
    assert model.load_texture(path).shape == (8, 8)
    monkeypatch.setattr(model, "MAX_TEXTURE_BYTES", size - 1)
    with pytest.raises(InputError, match="at most"):
        model.load_texture(path)
