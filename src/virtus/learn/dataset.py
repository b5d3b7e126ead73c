"""A map-style training dataset over a virtus store, for the models of :mod:`virtus.learn`.

Built on :class:`virtus.data.FringeDataset` (every read checked against the sample's
checksum). Item ``i`` is a dict of tensors (``H x W`` camera pixels, ``[row, col]``)::

    image    (1, H, W) float32  the input frame / the sensor's full scale (2**bit_depth - 1)
    depth    (H, W)    float32  metres (camera z); 0 where ``surface`` is False
    surface  (H, W)    bool     a surface is seen (finite depth)
    object   (H, W)     bool     the surface is an object, not a background plane or board
    wrapped  (H, W)    float32  exact wrapped phase of the ``direction`` fringes, rad; 0 where
                                ``valid`` is False               (phase model only)
    order    (H, W)    int64    its fringe order; -1 where invalid (phase model only)
    valid    (H, W)    bool     phase labels valid (lit, decodable)   (phase model only)
    index    int                the sample index in the store

:meth:`LearnDataset.layer` gives the sample's :class:`~virtus.learn.triangulate.DepthLayer`
and fringe period (px), built from the calibration stored with the sample.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from virtus.data import FringeDataset, input_frame_index
from virtus.errors import InputError
from virtus.learn._torch import require_torch

__all__ = ["LearnDataset", "needed_arrays"]

#: Arrays each model reads from a store.
_NEEDS = {
    "unet": ("frames", "depth", "object_id"),
    "phase": ("frames", "depth", "object_id", "wrapped", "order"),
}
#: Object types that are background, not objects (the "object" metrics leave them out).
BACKGROUND_TYPES = ("plane", "board")


def needed_arrays(model: str) -> tuple[str, ...]:
    """Store arrays the model ``model`` trains or is evaluated on."""
    return _NEEDS[model]


class LearnDataset:
    """Items for training ``model`` from a store's ``split`` (module docstring); the phase
    labels, the input frame ``"auto"`` and the depth layer are those of the ``direction``
    fringes (``"v"``: vertical, ``u_p``; ``"h"``: horizontal, ``v_p``).

    Raises
    ------
    InputError : the store lacks an array the model needs (named), the split is unknown,
        or a sample's sequence lacks the input frame (checked for every sample up front).
    """

    def __init__(
        self,
        store: str | Path,
        split: str | None,
        model: str,
        frame: int | str = "auto",
        direction: str = "v",
    ) -> None:
        require_torch()
        probe = FringeDataset(store, split, tensors=False)
        missing = [name for name in _NEEDS[model] if name not in probe.arrays]
        if missing:
            raise InputError(
                "store", f"a store with the labels the {model} model needs", f"no {missing}"
            )
        self.base = FringeDataset(store, split, _NEEDS[model], tensors=False)
        self.model, self.direction = model, direction
        what = "vertical" if direction == "v" else "horizontal"
        if model == "phase":  # its labels are those of the direction's fringes
            for i in range(len(self)):
                frames = self.base.meta(i)["sequence"]["frames"]
                if not any(
                    f.get("kind") == "phase" and f.get("direction") == direction for f in frames
                ):
                    raise InputError(
                        "store", f"the {what}-fringe phase labels the phase model needs",
                        f"sample {self.base.indices[i]} without {what} fringes",
                    )  # fmt: skip
        self.frames = [
            input_frame_index(self.base.meta(i), frame, direction) for i in range(len(self))
        ]
        self._layers: dict[str, tuple[Any, float]] = {}

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_layers"] = {}  # rebuilt where needed; workers only read samples
        return state

    def __len__(self) -> int:
        return len(self.base)

    def meta(self, item: int) -> dict[str, Any]:
        return self.base.meta(item)

    def __getitem__(self, item: int) -> dict[str, Any]:
        torch = require_torch()
        data = self.base[item]
        meta = self.base.meta(item)
        full = float(2 ** int(meta.get("bit_depth", 8)) - 1)
        image = data["frames"][self.frames[item]].astype(np.float32) / full
        depth = data["depth"].astype(np.float32)
        surface = np.isfinite(depth)
        background = [o["id"] for o in meta["objects"] if o["type"] in BACKGROUND_TYPES]
        object_id = data["object_id"]
        out = {
            "image": torch.from_numpy(image[None]),
            "depth": torch.from_numpy(np.where(surface, depth, 0.0).astype(np.float32)),
            "surface": torch.from_numpy(surface),
            "object": torch.from_numpy((object_id > 0) & ~np.isin(object_id, background)),
            "index": int(data["index"]),
        }
        if self.model == "phase":
            axis = 0 if self.direction == "v" else 1  # the labels' direction axis (v, h)
            wrapped = data["wrapped"][axis].astype(np.float32)
            order = data["order"][axis].astype(np.int64)
            valid = np.isfinite(wrapped) & (order >= 0) & surface
            out["wrapped"] = torch.from_numpy(np.where(valid, wrapped, 0.0).astype(np.float32))
            out["order"] = torch.from_numpy(np.where(valid, order, -1))
            out["valid"] = torch.from_numpy(valid)
        return out

    def decoded_phase(self, item: int) -> np.ndarray:
        """``(H, W)`` float64 absolute phase of the ``direction`` fringes (rad) decoded from the
        sample's own frames (phase steps with its code frames or second frequency, as its
        sequence has them: :meth:`virtus.patterns.PatternSequence.decode`); NaN where the
        decode is invalid. Unwrapping a single-shot prediction to the branch nearest it is
        what a complementary Gray-code decode of the prediction gives."""
        import warnings

        from virtus.patterns import PatternSequence

        meta = self.base.meta(item)
        sequence = PatternSequence.from_dict(meta["sequence"])
        frames = self.base[item]["frames"][: int(meta["n_frames"])]
        full_scale = float(2 ** int(meta.get("bit_depth", 8)) - 1)
        with warnings.catch_warnings():  # a poor decode shows as order errors instead
            warnings.simplefilter("ignore")
            decoded = sequence.decode(frames, full_scale=full_scale)
        if self.direction == "h":
            return np.where(decoded.mask_h, decoded.phase_h, np.nan)
        return np.where(decoded.mask_v, decoded.phase_v, np.nan)

    def layer(self, item: int) -> tuple[Any, float]:
        """The sample's depth layer and finest period of ``direction`` (projector px), cached."""
        from virtus.learn.triangulate import DepthLayer

        meta = self.base.meta(item)
        key = json.dumps([meta["rig"], meta["sequence"]], sort_keys=True)
        if key not in self._layers:  # samples of one rig and sequence share one layer
            self._layers[key] = DepthLayer.from_record(meta, self.direction)
        return self._layers[key]
