"""The UNet (virtus.learn.models): FPP-ML-Bench's size at their width, any input size."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from virtus.learn.models import UNet, parameter_count  # noqa: E402


def test_their_width_has_their_31m_parameters() -> None:
    assert parameter_count(UNet()) == pytest.approx(31.0e6, rel=0.01)


@pytest.mark.parametrize(("height", "width"), [(48, 64), (45, 61), (7, 9)])
def test_any_input_size_comes_back_the_same_size(height: int, width: int) -> None:
    net = UNet(1, 2, base_channels=2, levels=3)
    assert net(torch.rand(2, 1, height, width)).shape == (2, 2, height, width)
