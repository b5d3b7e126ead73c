"""The networks: a UNet (Ronneberger et al. 2015; FPP-ML-Bench's baseline) with a depth or a
phase output.

* ``UNet(out_channels=1)`` -- the depth baseline: one fringe image ``(B, 1, H, W)`` in
  ``[0, 1]`` -> normalised depth ``(B, 1, H, W)`` (:mod:`virtus.learn.config`'s
  ``depth_offset_m`` / ``depth_range_m``).
* ``UNet(out_channels=2)`` -- the phase head's trunk: the same image -> ``(sin, cos)`` of the
  wrapped phase of the vertical fringes; ``atan2`` gives the phase in ``[-pi, pi)``, the
  fringe order unwraps it, and :class:`virtus.learn.triangulate.DepthLayer` turns it into
  depth with the sample's own calibration (nothing of the rig is learnt).

Blocks: two 3x3 convolutions, each with instance normalisation and ReLU; max-pool down,
transposed convolution up, skip connections by concatenation. ``base_channels = 64`` and
four levels give 31.0 M parameters, the size FPP-ML-Bench reports for its UNet. Inputs of
any size are padded (reflect) to a multiple of ``2**levels`` and the output cropped back.
"""

from __future__ import annotations

from typing import Any

from virtus.learn._torch import require_torch

__all__ = ["UNet", "parameter_count"]

torch = require_torch()
nn = torch.nn
F = torch.nn.functional


def _block(cin: int, cout: int) -> Any:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, padding=1, bias=False),
        nn.InstanceNorm2d(cout, affine=True),
        nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False),
        nn.InstanceNorm2d(cout, affine=True),
        nn.ReLU(inplace=True),
    )


class UNet(nn.Module):
    """A UNet (module docstring).

    Parameters
    ----------
    in_channels, out_channels : image channels in and out.
    base_channels : channels of the first level (doubling per level).
    levels : down-samplings.
    """

    def __init__(
        self, in_channels: int = 1, out_channels: int = 1, base_channels: int = 64, levels: int = 4
    ) -> None:
        super().__init__()
        self.levels = levels
        widths = [base_channels * 2**i for i in range(levels + 1)]
        self.down = nn.ModuleList([_block(in_channels, widths[0])])
        self.down.extend(_block(widths[i], widths[i + 1]) for i in range(levels))
        self.up = nn.ModuleList(
            nn.ConvTranspose2d(widths[i + 1], widths[i], 2, stride=2)
            for i in reversed(range(levels))
        )
        self.merge = nn.ModuleList(
            _block(2 * widths[i], widths[i]) for i in reversed(range(levels))
        )
        self.head = nn.Conv2d(widths[0], out_channels, 1)

    def forward(self, x: Any) -> Any:
        """``(B, in_channels, H, W)`` -> ``(B, out_channels, H, W)``."""
        height, width = x.shape[-2:]
        step = 2**self.levels
        pad_h, pad_w = (-height) % step, (-width) % step
        if pad_h or pad_w:
            mode = "reflect" if pad_h < height and pad_w < width else "replicate"
            x = F.pad(x, (0, pad_w, 0, pad_h), mode=mode)
        skips = []
        for i, block in enumerate(self.down):
            x = block(x if i == 0 else F.max_pool2d(x, 2))
            skips.append(x)
        x = skips.pop()
        for up, merge in zip(self.up, self.merge, strict=True):
            x = merge(torch.cat([skips.pop(), up(x)], dim=1))
        return self.head(x)[..., :height, :width]


def parameter_count(model: Any) -> int:
    """Trainable parameters of ``model``."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
