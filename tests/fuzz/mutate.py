"""Deterministic mutations of seed inputs: byte-level and structure-aware.

:func:`mutation` gives case ``index`` of a seed: the same ``(reader, seed name, index)``
always gives the same bytes (a :class:`random.Random` seeded by that string), so a failure
named in a test report is reproduced by ``python -m tests.fuzz.replay READER SEED INDEX``.

Byte-level mutations (every file): bit flips, interesting bytes and machine integers at
aligned offsets (headers: PNG, BMP, STL counts, zip, ``.npy``), truncation, deleted,
duplicated and swapped ranges, inserted tokens (huge numbers, NaN, brackets, YAML tags and
aliases, NUL, a BOM), numbers in the text replaced by extreme ones.

Structure-aware mutations (``.json``, ``.yaml``/``.yml`` files that parse): at a key or item
chosen among every node of the document, the value is replaced by a huge number, NaN,
infinity, a wrong type, an empty or very long string, deep nesting or a long list; or the
key is dropped, an unknown key is added, or the document is wrapped. The result is written
back in the file's format (JSON with ``NaN``/``Infinity`` tokens, YAML by PyYAML).

Folders (captures, text calibrations, stores): one file is chosen (manifests more often)
and mutated as above, or a file is removed, emptied or replaced by a folder.
"""

from __future__ import annotations

import json
import math
import random
import re
from collections.abc import Mapping
from typing import Any

import yaml

#: Machine integers that break size arithmetic, written over aligned header fields.
INTERESTING_INTS = (
    0, 1, -1, 2, 3, 7, 8, 16, 255, 256, 65535, 65536, 2**31 - 1, -(2**31), 2**31, 2**32 - 1,
    2**32, 2**63 - 1, -(2**63), 2**64 - 1,
)  # fmt: skip
#: Numbers written in place of a number of a text file.
INTERESTING_NUMBERS = (
    b"0", b"-0", b"-1", b"1", b"2", b"3", b"-2147483649", b"2147483648", b"4294967296",
    b"9223372036854775808", b"-9223372036854775809", b"18446744073709551616",
    b"99999999999999999999999999999999", b"1e308", b"1e309", b"-1e309", b"1e-320", b"0.5",
    b"nan", b"NaN", b".nan", b"inf", b"-inf", b".inf", b"Infinity", b"-Infinity", b"1_000",
    b"0x10", b"0o7", b"1e", b"--1", b"1.2.3", b"+", b"1" * 5000,
)  # fmt: skip
#: Tokens inserted into text.
TOKENS = (
    b"NaN", b"Infinity", b"1e999", b"-1", b"99999999999999999999", b"[", b"]", b"{", b"}",
    b",", b":", b": ", b"- ", b"\n", b"\t", b" ", b"#", b"'", b'"', b"\\", b"\\u0000",
    b"\x00", b"\xff", b"\xc3", b"\xef\xbb\xbf", b"&a ", b"*a", b"<<: *a",
    b"!!python/object:os.system",
    b"!!binary", b"!!float", b"!!set", b"? ", b"---\n", b"...\n", b"%YAML 1.1\n", b"%TAG ! !x\n",
    b"null", b"true", b"~", b"[" * 400, b"{" * 400, b"- " * 200, b"a: " * 200,
    b"<", b"</", b"&x;", b"<![CDATA[", b"]]>", b"@", b"@a@", b"</a>", b"def ", b"(", b")",
)  # fmt: skip
_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?)")
_WORD = re.compile(rb"[A-Za-z_][A-Za-z0-9_]*")
#: PyYAML's C loader and dumper when built with libyaml (the mutator's own parsing only).
_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
#: The deepest nesting a structured mutation writes (readers must refuse it, not recurse).
DEEP = 2000


def _deep_list(depth: int) -> Any:
    value: Any = 0
    for _ in range(depth):
        value = [value]
    return value


def _deep_dict(depth: int) -> Any:
    value: Any = 0
    for _ in range(depth):
        value = {"a": value}
    return value


_VALUES = (
    None, True, False, 0, -1, 1, 2**31, 2**64, 10**30, -(10**30), 10**400, 1.5, 1e308, -1e308,
    5e-324, math.nan, math.inf, -math.inf, "", "x", "nan", "1e999", "a" * 10000, [], {},
    [1, 2, 3], {"unknown": 1},
)  # fmt: skip


def interesting_values(rng: random.Random) -> Any:
    """A value that breaks a field: an extreme number, a wrong type, an empty container..."""
    return rng.choice(_VALUES)


def _paths(node: Any, limit: int = 100) -> list[tuple]:
    """Every key path of a parsed document (the root is ``()``), at most ``limit`` deep; a
    YAML alias makes a cycle of a document whose anchor holds it: walked once."""
    out: list[tuple] = []
    stack: list[tuple[Any, tuple, frozenset]] = [(node, (), frozenset())]
    while stack:
        value, prefix, seen = stack.pop()
        out.append(prefix)
        if len(prefix) >= limit or id(value) in seen:
            continue
        if isinstance(value, dict):
            children = list(value.items())
        elif isinstance(value, list):
            children = list(enumerate(value))
        else:
            continue
        inner = seen | {id(value)}
        stack += [(child, (*prefix, key), inner) for key, child in reversed(children)]
    return out


def _get(node: Any, path: tuple) -> Any:
    for key in path:
        node = node[key]
    return node


def _retype(value: Any, rng: random.Random) -> Any:
    """The value in a wrong type (a number as text, a list as a mapping, ...)."""
    if isinstance(value, bool):
        return rng.choice([int(value), str(value).lower(), "yes", None])
    if isinstance(value, int | float):
        return rng.choice(
            [str(value), [value], {"value": value}, bool(value), -value, value * 10**12]
        )
    if isinstance(value, str):
        return rng.choice(
            [[value], {value: value}, len(value), value.upper(), value + "\x00", value * 1000]
        )
    if isinstance(value, list):
        return rng.choice([dict(enumerate(value)), value[:1], value * 3, value[::-1], [value]])
    if isinstance(value, dict):
        return rng.choice([list(value.values()), list(value), [value], {}])
    return rng.choice([0, "null", []])


def mutate_structure(doc: Any, rng: random.Random) -> tuple[Any, str]:
    """One structural change of a parsed JSON/YAML document; ``(new doc, description)``."""
    paths = _paths(doc)
    path = rng.choice(paths)
    where = "$" + "".join(f"[{key!r}]" for key in path)
    op = rng.randrange(12)
    if op in (0, 1, 2, 3):
        new = interesting_values(rng)
        what = f"set {where} = {_short(new)}"
    elif op == 4:
        new = _retype(_get(doc, path), rng)
        what = f"retype {where} -> {_short(new)}"
    elif op == 5:
        new = rng.choice([_deep_list(DEEP), _deep_dict(DEEP), _deep_list(60), _deep_dict(60)])
        what = f"set {where} = deep nesting"
    elif op == 6:
        new = rng.choice([[0] * 3000, [_get(doc, path)] * 300, ["x"] * 3000])
        what = f"set {where} = long list"
    elif op == 7 and path:  # drop the key or item
        parent = _get(doc, path[:-1])
        if isinstance(parent, dict):
            parent = dict(parent)
            del parent[path[-1]]
        else:
            parent = [v for i, v in enumerate(parent) if i != path[-1]]
        return _replace(doc, path[:-1], parent), f"drop {where}"
    elif op == 8:  # an unknown or odd key beside
        node = _get(doc, path)
        if isinstance(node, dict):
            key = rng.choice(["unknown", "", "0", "__class__", "a" * 300, "NaN", "format"])
            new = dict(node, **{key: interesting_values(rng)})
            what = f"add key {key[:20]!r} to {where}"
        else:
            new = {"wrapped": node}
            what = f"wrap {where} in a mapping"
    elif op == 9:  # a number nudged off by a tiny or huge factor
        node = _get(doc, path)
        if isinstance(node, int | float) and not isinstance(node, bool):
            new = rng.choice([node + 1, node - 1, -node, node * 1e300, node / 1e300, node + 0.5])
            what = f"nudge {where} -> {_short(new)}"
        else:
            new = _retype(node, rng)
            what = f"retype {where} -> {_short(new)}"
    elif op == 10:  # duplicate an item of a list
        node = _get(doc, path)
        new = (
            (node + node[:1] * rng.choice([1, 10, 1000]))
            if isinstance(node, list) and node
            else None
        )
        what = f"repeat the first item of {where}" if new is not None else f"set {where} = null"
    else:
        new = rng.choice([[], {}, None, "", [_get(doc, path)]])
        what = f"set {where} = {_short(new)}"
    return _replace(doc, path, new), what


def _replace(doc: Any, path: tuple, value: Any) -> Any:
    if not path:
        return value
    parent = _get(doc, path[:-1])
    if isinstance(parent, dict):
        parent = dict(parent)
    else:
        parent = list(parent)
    parent[path[-1]] = value
    return _replace(doc, path[:-1], parent)


def _short(value: Any, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _dump(doc: Any, suffix: str) -> bytes:
    if suffix == ".json":
        return json.dumps(doc, allow_nan=True).encode()
    return yaml.dump(doc, Dumper=_DUMPER, sort_keys=False, allow_unicode=True).encode()


def _parse(data: bytes, suffix: str) -> Any:
    if suffix == ".json":
        return json.loads(data)
    if suffix in (".yaml", ".yml") and not data.startswith(b"%YAML:"):  # not OpenCV's dialect
        return yaml.load(data, Loader=_LOADER)  # noqa: S506 (a safe loader)
    raise ValueError("not structured")


def mutate_bytes(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One byte-level change; ``(new bytes, description)``."""
    size = len(data)
    op = rng.randrange(12)
    if size == 0:
        token = rng.choice(TOKENS)
        return token, f"empty -> {token[:20]!r}"
    at = rng.randrange(size)
    if op == 0:
        bit = 1 << rng.randrange(8)
        return data[:at] + bytes([data[at] ^ bit]) + data[at + 1 :], f"flip bit {bit} of byte {at}"
    if op == 1:
        value = rng.choice([0, 0xFF, 0x7F, 0x80, 0x01, 0x20, 0x0A, 0x30, 0x39])
        return data[:at] + bytes([value]) + data[at + 1 :], f"byte {at} = {value:#x}"
    if op == 2:
        width = rng.choice([2, 4, 8])
        at -= at % width
        value = rng.choice(INTERESTING_INTS)
        order = rng.choice(["little", "big"])
        word = (value % (1 << (8 * width))).to_bytes(width, order)
        return data[:at] + word + data[at + width :], f"{width}-byte {order} {value} at {at}"
    if op == 3:
        return data[:at], f"truncate at {at} of {size}"
    if op == 4:
        stop = min(size, at + rng.choice([1, 2, 4, 16, 64, size]))
        return data[:at] + data[stop:], f"delete [{at}, {stop})"
    if op == 5:
        stop = min(size, at + rng.choice([1, 4, 16, 64, 256]))
        times = rng.choice([1, 2, 16, 256])
        return data[:stop] + data[at:stop] * times + data[stop:], f"repeat [{at}, {stop}) x{times}"
    if op == 6:
        token = rng.choice(TOKENS)
        return data[:at] + token + data[at:], f"insert {token[:20]!r} at {at}"
    if op in (7, 8):
        numbers = list(_NUMBER.finditer(data))
        if numbers:
            match = rng.choice(numbers)
            new = rng.choice(INTERESTING_NUMBERS)
            return (
                data[: match.start()] + new + data[match.end() :],
                f"number {match.group()[:20]!r} at {match.start()} -> {new[:20]!r}",
            )
    if op == 9:
        words = list(_WORD.finditer(data))
        if len(words) > 1:
            a, b = rng.sample(words, 2)
            return (
                data[: a.start()] + b.group() + data[a.end() :],
                f"word {a.group()[:20]!r} at {a.start()} -> {b.group()[:20]!r}",
            )
    if op == 10:
        count = rng.choice([1, 4, 32])
        noise = bytes(rng.randrange(256) for _ in range(count))
        return data[:at] + noise + data[at:], f"insert {count} random bytes at {at}"
    other = rng.randrange(size)
    a, b = sorted((at, other))
    length = min(rng.choice([1, 4, 16]), b - a)
    if length <= 0:
        return data[:at] + data[at + 1 :], f"delete byte {at}"
    chunk_a, chunk_b = data[a : a + length], data[b : b + length]
    swapped = data[:a] + chunk_b + data[a + length : b] + chunk_a + data[b + len(chunk_b) :]
    return swapped, f"swap {length} bytes at {a} and {b}"


def mutate_file(data: bytes, suffix: str, rng: random.Random) -> tuple[bytes, str]:
    """One to three changes of a file's bytes (structure-aware where it parses)."""
    changes = []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        if suffix in (".json", ".yaml", ".yml") and rng.random() < 0.6:
            try:
                doc = _parse(data, suffix)
            except Exception:  # noqa: BLE001 (a mutated document no longer parses: bytes then)
                doc = None
            if isinstance(doc, dict | list):
                new, what = mutate_structure(doc, rng)
                try:
                    data = _dump(new, suffix)
                    changes.append(what)
                    continue
                except (RecursionError, ValueError, yaml.YAMLError):
                    pass
        data, what = mutate_bytes(data, rng)
        changes.append(what)
    return data, "; ".join(changes)


def _weight(name: str) -> float:
    """How often a folder's file is chosen: manifests and metadata first."""
    if name.endswith(("capture.json", "dataset.json")):
        return 6.0
    if name.endswith("zarr.json") or name.startswith("manifest/"):
        return 3.0
    if name.endswith((".json", ".txt", ".yaml")):
        return 3.0
    return 1.0


def mutate_folder(files: Mapping[str, bytes], rng: random.Random) -> tuple[dict[str, Any], str]:
    """One change of a folder's files; ``(new files, description)`` (``None`` for a
    folder in place of a file)."""
    names = sorted(files)
    out: dict[str, Any] = dict(files)
    name = rng.choices(names, weights=[_weight(n) for n in names])[0]
    op = rng.randrange(20)
    if op == 0:
        del out[name]
        return out, f"remove {name}"
    if op == 1:
        out[name] = b""
        return out, f"empty {name}"
    if op == 2:
        out[name] = None
        return out, f"a folder in place of {name}"
    if op == 3:
        other = rng.choice(names)
        out[name] = files[other]
        return out, f"{name} replaced by {other}"
    suffix = "." + name.rsplit(".", 1)[-1] if "." in name.rsplit("/", 1)[-1] else ""
    out[name], what = mutate_file(files[name], suffix, rng)
    return out, f"{name}: {what}"


def mutation(reader: str, seed_name: str, seed: Any, index: int, suffix: str) -> tuple[Any, str]:
    """Case ``index`` of a seed (bytes or a folder's files); ``(input, description)``."""
    rng = random.Random(f"{reader}:{seed_name}:{index}")
    if isinstance(seed, bytes):
        return mutate_file(seed, suffix, rng)
    return mutate_folder(seed, rng)
