"""The training configuration of :mod:`virtus.learn`: one validated, frozen description.

YAML schema (every key optional; the defaults are FPP-ML-Bench's UNet setting where it has
one: RMSprop lr 1e-4, weight decay 1e-5, ReduceLROnPlateau factor 0.1 patience 10, hybrid L1
with alpha 0.7; arXiv 2601.08900)::

    model: unet              # unet: fringe -> depth | phase: fringe -> wrapped phase (sin,
                             # cos) -> the calibration layer -> depth
    input_frame: auto        # 'auto' (first phase step of `direction`) or a frame index
    direction: v             # fringes the phase labels and depth come from: v (vertical,
                             # u_p) or h (horizontal, v_p: for a baseline along the
                             # camera's rows' normal, e.g. a projector above the camera)
    base_channels: 64        # UNet width (64: ~31 M parameters, theirs); 8 for tests
    levels: 4                # down-samplings (input padded to a multiple of 2**levels)
    seed: 0
    epochs: 100
    max_steps: null          # stop after this many optimiser steps (null: epochs decide)
    batch_size: 2
    lr: 1.0e-4
    weight_decay: 1.0e-5
    plateau_patience: 10     # ReduceLROnPlateau on the validation loss, factor 0.1
    alpha: 0.7               # hybrid L1: alpha * object L1 + (1 - alpha) * all-surface L1
    depth_offset_m: 1.8      # unet target: (depth - offset) / range (one global scale:
    depth_range_m: 0.5       # metric depth comes back without the ground truth's maximum)
    depth_weight: 1.0        # phase model: weight of the depth L1 (m -> loss units / range)
    checkpoint_every: 100    # optimiser steps between checkpoints (and one per epoch end)
    amp: true                # bfloat16 autocast on CUDA (ignored on CPU)
    workers: 0               # DataLoader worker processes

Units: metres, radians. Every number is bounded; unknown keys are refused by name.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from virtus.errors import InputError
from virtus.io.safeio import check_keys, read_yaml

__all__ = ["MODELS", "TrainConfig", "load_train_config"]

#: The models :func:`virtus.learn.training.train` builds.
MODELS = ("unet", "phase")


def _int(name: str, value: Any, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise InputError(name, f"an integer in {low}..{high}", value)
    return int(value)


def _float(name: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not low <= value <= high:
        raise InputError(name, f"a number in [{low:g}, {high:g}]", value)
    return float(value)


@dataclass(frozen=True)
class TrainConfig:
    """A training run's settings (module docstring for meaning, units and defaults)."""

    model: str = "unet"
    input_frame: int | str = "auto"
    direction: str = "v"
    base_channels: int = 64
    levels: int = 4
    seed: int = 0
    epochs: int = 100
    max_steps: int | None = None
    batch_size: int = 2
    lr: float = 1e-4
    weight_decay: float = 1e-5
    plateau_patience: int = 10
    alpha: float = 0.7
    depth_offset_m: float = 1.8
    depth_range_m: float = 0.5
    depth_weight: float = 1.0
    checkpoint_every: int = 100
    amp: bool = True
    workers: int = 0

    @classmethod
    def from_dict(cls, data: Any) -> TrainConfig:
        """Validate a mapping; :class:`InputError` names the first bad key."""
        if not isinstance(data, dict):
            raise InputError("config", "a mapping", type(data).__name__)
        check_keys(data, tuple(cls.__dataclass_fields__), "learn config")
        d = {**asdict(cls()), **data}
        if d["model"] not in MODELS:
            raise InputError("model", f"one of {', '.join(MODELS)}", d["model"])
        if d["direction"] not in ("v", "h"):
            raise InputError("direction", "v or h", d["direction"])
        frame = d["input_frame"]
        if frame != "auto":
            frame = _int("input_frame", frame, 0, 4095)
        amp = d["amp"]
        if not isinstance(amp, bool):
            raise InputError("amp", "true or false", amp)
        max_steps = d["max_steps"]
        return cls(
            model=d["model"],
            input_frame=frame,
            direction=d["direction"],
            base_channels=_int("base_channels", d["base_channels"], 1, 256),
            levels=_int("levels", d["levels"], 1, 7),
            seed=_int("seed", d["seed"], 0, 2**63 - 1),
            epochs=_int("epochs", d["epochs"], 1, 100_000),
            max_steps=None if max_steps is None else _int("max_steps", max_steps, 1, 10**9),
            batch_size=_int("batch_size", d["batch_size"], 1, 1024),
            lr=_float("lr", d["lr"], 1e-9, 1.0),
            weight_decay=_float("weight_decay", d["weight_decay"], 0.0, 1.0),
            plateau_patience=_int("plateau_patience", d["plateau_patience"], 0, 10_000),
            alpha=_float("alpha", d["alpha"], 0.0, 1.0),
            depth_offset_m=_float("depth_offset_m", d["depth_offset_m"], 0.0, 100.0),
            depth_range_m=_float("depth_range_m", d["depth_range_m"], 1e-3, 100.0),
            depth_weight=_float("depth_weight", d["depth_weight"], 0.0, 1e6),
            checkpoint_every=_int("checkpoint_every", d["checkpoint_every"], 1, 10**9),
            amp=amp,
            workers=_int("workers", d["workers"], 0, 64),
        )

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def load_train_config(path: str | Path) -> TrainConfig:
    """Read and validate a training configuration YAML (module docstring)."""
    return TrainConfig.from_dict(read_yaml(path, "learn config", expect=dict) or {})
