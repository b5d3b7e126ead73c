"""Losses (virtus.learn.losses): FPP-ML-Bench's hybrid L1 on hand-made maps."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from virtus.learn.losses import hybrid_l1, masked_l1, phase_loss  # noqa: E402


def test_hybrid_l1_weights_objects_and_all_surfaces() -> None:
    target = torch.zeros(1, 2, 2)
    pred = torch.tensor([[[1.0, 2.0], [3.0, 4.0]]])
    objects = torch.tensor([[[True, False], [False, False]]])
    surface = torch.tensor([[[True, True], [True, False]]])
    loss = hybrid_l1(pred, target, objects, surface, alpha=0.7)
    assert float(loss) == pytest.approx(0.7 * 1.0 + 0.3 * 2.0)
    assert float(masked_l1(pred, target, torch.zeros_like(objects))) == 0.0  # empty mask


def test_phase_loss_is_continuous_across_the_wrap() -> None:
    wrapped = torch.tensor([[[np.pi - 0.01]]])
    across = torch.tensor([[[-np.pi + 0.01]]])
    sin_cos = torch.stack([torch.sin(across), torch.cos(across)], dim=1)
    loss = phase_loss(sin_cos, wrapped, torch.ones(1, 1, 1, dtype=torch.bool))
    assert float(loss) < 0.02  # 0.02 rad apart, not 2 pi - 0.02
