"""Learning-based fringe analysis on virtus data (PyTorch optional: a clear message without it).

* :mod:`virtus.learn.triangulate` -- :class:`DepthLayer`, the exact differentiable phase ->
  depth layer built from a sample's stored calibration (:mod:`virtus.reconstruct` in torch).
* :mod:`virtus.learn.models` -- :class:`UNet` (FPP-ML-Bench's baseline; the phase head's trunk).
* :mod:`virtus.learn.dataset` -- :class:`LearnDataset`, a map-style dataset over a store.
* :mod:`virtus.learn.losses` -- hybrid L1 (alpha 0.7) and the phase loss.
* :mod:`virtus.learn.metrics` -- object/background MAE and RMSE (mm), phase RMSE (rad),
  fringe-order error rate, wrap-pixel error, the flat-plane test (numpy only).
* :mod:`virtus.learn.config` -- :class:`TrainConfig` (YAML).
* :mod:`virtus.learn.training` -- :func:`train` and :func:`evaluate`: run directories with
  checkpoints, resume after a kill, metrics JSON beside the checkpoint.
* :mod:`virtus.learn.captures` -- :func:`evaluate_captures`: a trained phase model on
  (real) captures against their own multi-step phase.

Units: metres and radians inside, millimetres in metric names that say ``_mm``. ``import
virtus.learn`` does not import torch; the names below load their module (and torch) on
first use (PEP 562).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "DepthLayer",
    "LearnDataset",
    "MetricSums",
    "TrainConfig",
    "UNet",
    "evaluate",
    "evaluate_captures",
    "load_train_config",
    "sample_errors",
    "train",
]

_WHERE = {
    "DepthLayer": "triangulate",
    "LearnDataset": "dataset",
    "MetricSums": "metrics",
    "TrainConfig": "config",
    "UNet": "models",
    "evaluate": "training",
    "evaluate_captures": "captures",
    "load_train_config": "config",
    "sample_errors": "metrics",
    "train": "training",
}


def __getattr__(name: str) -> Any:
    if name in _WHERE:
        return getattr(importlib.import_module(f"virtus.learn.{_WHERE[name]}"), name)
    raise AttributeError(f"module 'virtus.learn' has no attribute {name!r}")
