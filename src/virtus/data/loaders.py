"""Reading a dataset: :class:`FringeDataset`, a PyTorch map-style dataset over a store.

Each item is a dict of tensors named as the store's arrays (:mod:`virtus.data.labels`):
metric units are kept (depth and points in metres, phases in radians, projector
coordinates in projector px, frames in digital numbers), dtypes as stored (no
normalisation: a network's input scaling is the user's choice, and depth stays metric).
The item also holds ``index`` (the sample index) and ``n_frames`` (frames of its own
sequence; the rest of the frame axis is zero padding). Everything else about the sample
-- its rig, ``cam2world``, sequence, sensor, objects -- is in :meth:`FringeDataset.meta`,
with :meth:`FringeDataset.rig` and :meth:`FringeDataset.sequence` as objects.

Every item is checked against its sample's recorded checksum as it is read: a damaged
sample (a shard file that no longer decompresses, or data that changed) raises
:class:`~virtus.data.store.DamagedSample`, one line naming the store and the sample.

PyTorch is optional: ``FringeDataset(..., tensors=False)`` returns numpy arrays and never
imports it; with ``tensors=True`` (the default) a missing torch raises a
:class:`~virtus.errors.VirtusError` that says how to install it. The dataset is
picklable and opens the store lazily in each ``DataLoader`` worker.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from virtus.data.store import DatasetStore
from virtus.errors import InputError, MissingDependency

__all__ = ["FringeDataset", "require_torch"]

_TORCH_MISSING = (
    "FringeDataset returns torch tensors and needs PyTorch: pip install 'virtus-fpp[data]' "
    "(or torch), or pass tensors=False for numpy arrays"
)


def require_torch() -> Any:
    """The ``torch`` module, or :class:`MissingDependency` with the install command."""
    try:
        import torch
    except ImportError:
        raise MissingDependency(_TORCH_MISSING) from None
    return torch


class FringeDataset:
    """A map-style dataset over the complete samples of a store (module docstring).

    Parameters
    ----------
    path : the store folder.
    split : only samples of this split (``"train"``, ``"val"``, ``"test"``, ... as the
        configuration names them); None: all.
    arrays : names of the arrays to load (default: all).
    tensors : return ``torch.Tensor`` (True) or ``numpy.ndarray`` (False).

    Items are ordered by sample index. ``len(dataset)`` counts complete samples only (the
    manifest's), so a store still being generated can be read safely.
    """

    def __init__(
        self,
        path: str | Path,
        split: str | None = None,
        arrays: list[str] | tuple[str, ...] | None = None,
        *,
        tensors: bool = True,
    ) -> None:
        if tensors:
            require_torch()
        self.path = Path(path)
        self.tensors = tensors
        store = DatasetStore.open(self.path)
        known = [a.name for a in store.layout]
        if arrays is not None:
            unknown = [name for name in arrays if name not in known]
            if unknown or not arrays:
                raise InputError("arrays", f"names among {known}", unknown or list(arrays))
        self.arrays = tuple(known if arrays is None else arrays)
        samples = store.samples()
        splits = sorted({m["split"] for m in samples.values()})
        configured = list(store.description["config"]["splits"])
        if split is not None and split not in configured:
            raise InputError("split", f"one of {configured}", split)
        self.indices = [i for i, m in samples.items() if split is None or m["split"] == split]
        self._meta = {i: samples[i] for i in self.indices}
        self.splits = splits
        self._store: DatasetStore | None = store

    def __len__(self) -> int:
        return len(self.indices)

    def _position(self, item: int) -> int:
        if isinstance(item, bool) or not isinstance(item, int | np.integer):
            raise InputError("item", "an integer position", item)
        if not -len(self) <= item < len(self):
            raise IndexError(f"item {item} out of range for {len(self)} samples")
        return self.indices[int(item)]

    def __getitem__(self, item: int) -> dict[str, Any]:
        """The arrays of the ``item``-th sample (tensors or numpy arrays), plus ``index`` and
        ``n_frames``.

        Raises
        ------
        DamagedSample : the sample's data cannot be read or does not match its checksum
            (:meth:`~virtus.data.store.DatasetStore.read_sample`: every read is checked).
        """
        index = self._position(item)
        if self._store is None:  # unpickled in a DataLoader worker
            self._store = DatasetStore.open(self.path)
        data: dict[str, Any] = self._store.read_sample(
            index, self.arrays, checksum=self._meta[index]["checksum"]
        )
        if self.tensors:
            torch = require_torch()
            data = {name: torch.from_numpy(value) for name, value in data.items()}
        data["index"] = index
        data["n_frames"] = int(self._meta[index]["n_frames"])
        return data

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_store"] = None
        return state

    def meta(self, item: int) -> dict[str, Any]:
        """The ``item``-th sample's record: split, seed, checksum, rig (rig JSON schema),
        cam2world, sequence, sensor, projector, scanner, render settings, objects."""
        return self._meta[self._position(item)]

    def rig(self, item: int) -> Any:
        """The ``item``-th sample's :class:`virtus.geometry.devices.Rig` (triangulate with it)."""
        from virtus.geometry.devices import Rig

        return Rig.from_dict(self.meta(item)["rig"])

    def sequence(self, item: int) -> Any:
        """The ``item``-th sample's :class:`virtus.patterns.PatternSequence`."""
        from virtus.patterns import PatternSequence

        return PatternSequence.from_dict(self.meta(item)["sequence"])
