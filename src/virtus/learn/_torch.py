"""PyTorch, imported only when a learning feature is used.

``import virtus`` and ``import virtus.learn`` never import torch; the modules of this package
that define networks or tensor operations call :func:`require_torch` (or import ``torch``
from here) and a missing torch becomes one :class:`~virtus.errors.MissingDependency` line
saying how to install it.
"""

from __future__ import annotations

from typing import Any

from virtus.errors import MissingDependency

__all__ = ["require_torch"]

_TORCH_MISSING = (
    "virtus.learn needs PyTorch: pip install 'virtus-fpp[learn]' (or a torch build for your "
    "CUDA from pytorch.org)"
)


def require_torch() -> Any:
    """The ``torch`` module, or :class:`MissingDependency` with the install command."""
    try:
        import torch
    except ImportError:
        raise MissingDependency(_TORCH_MISSING) from None
    return torch
