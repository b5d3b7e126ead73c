"""What a store's files must be to be trusted: checks of its description, its shard records
and its samples (used by :class:`virtus.data.store.DatasetStore` on every read).

* ``dataset.json`` (:func:`check_description`): well-formed, and not edited since it was
  written -- its ``identity_digest`` is the digest of its ``identity``, and its ``config``
  (less ``num_samples``) is the configuration in that identity.
* A shard record (:func:`record_problem`): this dataset's (its ``dataset`` digest is the
  description's, so a record copied from another store, or a description edited to pass
  for another configuration, is caught), the shard its file name says, samples inside
  that shard, each with a checksum, split and frame count.
* The Zarr arrays (:func:`check_arrays`): the per-sample shapes and dtypes of the layout.
* A sample (:class:`DamagedSample`): its arrays read back and match its recorded checksum;
  a decompression error or a truncated shard file is a damaged sample too, never a
  traceback.

:class:`VerifyReport` is what :meth:`virtus.data.store.DatasetStore.verify` found.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from virtus.data.labels import ArraySpec
from virtus.errors import InputError, RunConflict
from virtus.io.runs import config_digest, first_difference

__all__ = [
    "DamagedSample",
    "VerifyReport",
    "check_arrays",
    "check_description",
    "describe",
    "record_problem",
    "short_digest",
]


class DamagedSample(InputError):
    """A recorded sample whose data cannot be read (a damaged shard file: the decompressor
    fails, the file is truncated) or does not match the checksum its record holds.

    Attributes
    ----------
    store : the store folder.
    index : the sample index.
    problem : what is wrong (``"checksum mismatch (depth)"``, ``"depth unreadable (...)"``).
    """

    def __init__(self, store: str | Path, index: int, problem: str) -> None:
        super().__init__(f"{store}: sample {index}", "data matching its checksum", problem)
        self.store, self.index, self.problem = Path(store), index, problem
        self.args = (
            f"{store}: sample {index} is damaged: {problem} (virtus dataset verify {store} "
            "lists every damaged sample)",
        )


@dataclass
class VerifyReport:
    """What :meth:`DatasetStore.verify` found.

    Attributes
    ----------
    checked : samples read back and checksummed.
    bad : ``(index, problem)`` of samples whose data does not match their checksum or
        cannot be read.
    missing : sample indices in ``[0, num_samples)`` without a record.
    stray : leftover temporary files (from a killed writer; harmless, removed by the
        next ``generate``).
    """

    checked: int = 0
    bad: list[tuple[int, str]] = field(default_factory=list)
    missing: list[int] = field(default_factory=list)
    stray: list[str] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """No bad sample and none missing."""
        return not self.bad and not self.missing

    def to_dict(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "checked": self.checked,
            "bad": [list(b) for b in self.bad],
            "missing": self.missing,
            "stray": self.stray,
        }


def describe(error: BaseException, limit: int = 160) -> str:
    """``"Type: message"`` of an exception on one line, at most ``limit`` characters."""
    text = " ".join(f"{type(error).__name__}: {error}".split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def short_digest(digest: Any) -> str:
    """``"sha256:0123456789ab..."``: enough of a digest to tell two apart."""
    return f"{digest[:19]}..." if isinstance(digest, str) and len(digest) > 22 else repr(digest)


def check_description(file: Path, data: dict[str, Any], storages: tuple[str, ...]) -> None:
    """Refuse a ``dataset.json`` (``data``, read from ``file``) that is malformed or was
    edited since it was written (module docstring).

    Raises
    ------
    InputError : a key missing or of the wrong type (named).
    RunConflict : the description disagrees with itself (the first difference named).
    """

    def need(key: str, kind: type, expected: str) -> Any:
        value = data.get(key)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise InputError(f"{file} {key}", expected, value)
        return value

    storage = need("storage", str, f"one of {', '.join(storages)}")
    if storage not in storages:
        raise InputError(f"{file} storage", f"one of {', '.join(storages)}", storage)
    config = need("config", dict, "the store's configuration (a mapping)")
    identity = need("identity", dict, "the store's identity (a mapping)")
    digest = need("identity_digest", str, "the digest of the identity")
    layout = need("layout", list, "the array layout (a list)")
    num = need("num_samples", int, "a sample count")
    shard_samples = (config.get("storage") or {}).get("shard_samples")
    if (
        num < 0
        or isinstance(shard_samples, bool)
        or not isinstance(shard_samples, int)
        or shard_samples < 1
    ):
        raise InputError(
            f"{file} num_samples and config.storage.shard_samples",
            "counts (>= 0, >= 1)",
            [num, shard_samples],
        )
    try:
        specs = [ArraySpec.from_dict(a) for a in layout]
        for spec in specs:
            np.dtype(spec.dtype)
            if not isinstance(spec.name, str):
                raise ValueError(f"name {spec.name!r}")
            if not all(isinstance(n, int) and n > 0 for n in spec.shape):
                raise ValueError(f"shape {list(spec.shape)}")
    except (KeyError, TypeError, ValueError, AttributeError) as error:
        raise InputError(
            f"{file} layout", "array specs (name, shape, dtype, unit, fill)", describe(error)
        ) from None
    if "frames" not in {spec.name for spec in specs}:
        raise InputError(f"{file} layout", "a frames array", [spec.name for spec in specs])
    edited = "; the file was edited: restore it, or generate into a new store"
    if config_digest(identity) != digest:
        raise RunConflict(
            f"{file}: identity_digest {short_digest(digest)} is not the digest of its "
            f"identity ({short_digest(config_digest(identity))}){edited}"
        )
    where = first_difference(
        {k: v for k, v in config.items() if k != "num_samples"}, identity.get("config")
    )
    if where is not None:
        place = where.split(": ", 1)[0]
        raise RunConflict(f"{file}: config.{place} differs from identity.config.{place}{edited}")


def check_arrays(store: Path, layout: tuple[ArraySpec, ...], arrays: dict[str, Any]) -> None:
    """Refuse Zarr arrays (name -> ``zarr.Array``) whose per-sample shape or dtype is not
    the layout's, naming the array's ``zarr.json``."""
    for spec in layout:
        array = arrays[spec.name]
        shape = getattr(array, "shape", None)  # None: a group where the array should be
        if shape is None or tuple(shape[1:]) != spec.shape or np.dtype(array.dtype) != spec.dtype:
            raise InputError(
                f"{store / spec.name / 'zarr.json'}",
                f"per-sample shape {list(spec.shape)} and dtype {spec.dtype} (the layout "
                "of its dataset.json)",
                "a group" if shape is None else f"shape {list(shape[1:])}, dtype {array.dtype}",
            )


def record_problem(
    file: Path, record: dict[str, Any], *, shard_format: str, digest: str, shard_samples: int
) -> str | None:
    """Why a manifest file (``record``, read from ``file``) is not a record of a shard of the
    dataset ``digest`` (module docstring); None when it is one."""
    if record.get("format") != shard_format:
        return f"format {record.get('format')!r}, expected {shard_format}"
    if record.get("dataset") != digest:
        return (
            f"it records dataset {short_digest(record.get('dataset'))}, this store's "
            f"dataset.json says {short_digest(digest)} (a record copied from another store, "
            "or an edited dataset.json)"
        )
    shard = record.get("shard")
    named = re.fullmatch(r"shard_(\d+)", file.stem)
    if (
        isinstance(shard, bool)
        or not isinstance(shard, int)
        or named is None
        or int(named.group(1)) != shard
    ):
        return f"it records shard {shard!r}, not the shard its name says"
    samples = record.get("samples")
    if not isinstance(samples, list) or not samples:
        return "no samples listed"
    start, stop = shard * shard_samples, (shard + 1) * shard_samples
    seen: set[int] = set()
    for meta in samples:
        index = meta.get("index") if isinstance(meta, dict) else None
        if (
            isinstance(index, bool)
            or not isinstance(index, int)
            or not start <= index < stop
            or index in seen
        ):
            return f"sample index {index!r} repeated or outside the shard ({start}..{stop - 1})"
        if not isinstance(meta.get("checksum"), str) or not isinstance(meta.get("split"), str):
            return f"sample {index} without a checksum or split"
        if isinstance(meta.get("n_frames"), bool) or not isinstance(meta.get("n_frames"), int):
            return f"sample {index} without n_frames"
        seen.add(index)
    return None
