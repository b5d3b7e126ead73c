"""Training losses: FPP-ML-Bench's hybrid L1 and the phase head's loss.

Masks are bool tensors of the target's shape; a mask with no pixel contributes 0 (never a
division by zero).
"""

from __future__ import annotations

from typing import Any

from virtus.learn._torch import require_torch

__all__ = ["hybrid_l1", "masked_l1", "phase_loss"]

torch = require_torch()


def masked_l1(pred: Any, target: Any, mask: Any) -> Any:
    """Mean ``|pred - target|`` over ``mask`` (0 for an empty mask)."""
    weight = mask.to(pred.dtype)
    return ((pred - target).abs() * weight).sum() / weight.sum().clamp(min=1.0)


def hybrid_l1(pred: Any, target: Any, objects: Any, surface: Any, alpha: float = 0.7) -> Any:
    """FPP-ML-Bench's hybrid L1: ``alpha * L1(objects) + (1 - alpha) * L1(all)``.

    Theirs takes ``depth > 0`` as the object and the whole image as "all" (background depth
    0); virtus stores the background plane's true depth, so "all" is every pixel with a
    surface and the object mask is the objects' pixels (planes and boards excluded).
    """
    return alpha * masked_l1(pred, target, objects) + (1 - alpha) * masked_l1(pred, target, surface)


def phase_loss(sin_cos: Any, wrapped: Any, valid: Any) -> Any:
    """L1 between predicted ``(sin, cos)`` ``(B, 2, H, W)`` and those of the true wrapped
    phase ``(B, H, W)`` over ``valid``: smooth across the +-pi wrap, unlike a loss on the
    angle itself."""
    target = torch.stack([torch.sin(wrapped), torch.cos(wrapped)], dim=1)
    return masked_l1(sin_cos, target, valid[:, None].expand_as(sin_cos))
