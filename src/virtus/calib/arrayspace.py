"""numpy arrays or torch tensors (CPU or CUDA) for the batched window work of observation.

The local homographies (:mod:`virtus.calib.windowfit`) and the circle centroids
(:func:`virtus.calib.detect.refine_centres`) gather every board point's window of pixels
into one padded batch and reduce it with elementwise arithmetic and small batched linear
algebra. The same code runs on either library through an :class:`ArraySpace`: the module
itself (:attr:`ArraySpace.xp`) for what both spell alike, methods for the few operations
whose spelling or semantics differ. Work that is elementwise over every padded pixel
costs a CPU core tens of milliseconds a pose and a GPU a few hundred kernel launches;
torch on the CPU runs the device's code, and the tests hold it to numpy's to rounding.
"""

from __future__ import annotations

import contextlib
from typing import Any

import numpy as np

__all__ = ["NUMPY", "ArraySpace", "space_of", "start_linear_algebra", "torch_space"]


class ArraySpace:
    """numpy's operations whose torch spelling differs (:func:`torch_space` gives torch's);
    everything else (arithmetic, indexing, ``sum``/``any``/``all`` with ``axis``,
    ``stack``, ``where``, ``sqrt``, ``einsum``, ``broadcast_to``, ``concatenate``,
    ``linalg.eigh/solve/cond``) is called on :attr:`xp`, the module itself, where both
    libraries spell it alike. Arrays are float64 unless said otherwise."""

    def __init__(self, xp: Any, device: Any = None) -> None:
        self.xp = xp
        self.device = device

    def asarray(self, host: np.ndarray) -> Any:
        """A host array in this space (float64 stays float64)."""
        return host

    def to_host(self, array: Any) -> np.ndarray:
        return np.asarray(array)

    def full(self, shape: tuple[int, ...], value: float) -> Any:
        """A float64 array of ``shape`` filled with ``value``."""
        return np.full(shape, value)

    def eye(self, n: int) -> Any:
        return np.eye(n)

    def float64(self, array: Any) -> Any:
        return array.astype(np.float64)

    def copy(self, array: Any) -> Any:
        return array.copy()

    def equal(self, a: Any, b: Any) -> bool:
        return bool(np.array_equal(a, b))

    def row_max(self, values: Any) -> Any:
        """(n,) maxima of the rows of (n, P)."""
        return values.max(axis=1)

    def row_medians(self, values: Any) -> Any:
        """(n, 1) medians of the non-NaN entries of each row of (n, P) with at least one
        (the mean of the two middle ones for an even count, as ``np.nanmedian``)."""
        return np.nanmedian(values, axis=1, keepdims=True)

    def quiet(self) -> Any:
        """A context in which division by zero and NaN comparisons are silent."""
        return np.errstate(all="ignore")

    @property
    def singular_error(self) -> type[Exception]:
        return np.linalg.LinAlgError


class _TorchSpace(ArraySpace):
    """:class:`ArraySpace` of torch tensors on ``device``."""

    def asarray(self, host: np.ndarray) -> Any:
        return self.xp.as_tensor(host, device=self.device)

    def to_host(self, array: Any) -> np.ndarray:
        return array.cpu().numpy()

    def full(self, shape: tuple[int, ...], value: float) -> Any:
        return self.xp.full(shape, value, dtype=self.xp.float64, device=self.device)

    def eye(self, n: int) -> Any:
        return self.xp.eye(n, dtype=self.xp.float64, device=self.device)

    def float64(self, array: Any) -> Any:
        return array.to(self.xp.float64)

    def copy(self, array: Any) -> Any:
        return array.clone()

    def equal(self, a: Any, b: Any) -> bool:
        return bool(self.xp.equal(a, b))

    def row_max(self, values: Any) -> Any:
        return values.amax(dim=1)

    def row_medians(self, values: Any) -> Any:
        # nanquantile's linear interpolation at 0.5 is np.nanmedian's mean of the middle
        # two; torch.nanmedian would take the lower one.
        return self.xp.nanquantile(values, 0.5, dim=1, keepdim=True)

    def quiet(self) -> Any:
        return contextlib.nullcontext()

    @property
    def singular_error(self) -> type[Exception]:
        return self.xp.linalg.LinAlgError


#: The numpy space (the default: no torch needed).
NUMPY = ArraySpace(np)


def torch_space(device: str) -> ArraySpace:
    """The space of torch tensors on ``device`` (``"cpu"``, ``"cuda"``, ...); torch must
    be importable (the caller checks)."""
    import torch

    return _TorchSpace(torch, torch.device(device))


def start_linear_algebra(device: str) -> None:
    """Load torch's linear algebra on ``device`` from this thread, before threads use it.

    torch loads a CUDA device's solver libraries on their first use, and that lazy start
    is not thread-safe: observer threads that begin with ``torch.linalg`` calls at once
    fail with "lazy wrapper should be called at most once" (pytorch/pytorch#90613, seen
    here on an H100 with torch 2.11). One call of each kind used here, in the thread
    that starts the observers, starts them once."""
    import torch

    a = torch.eye(3, dtype=torch.float64, device=torch.device(device))
    torch.linalg.solve(a, a)
    torch.linalg.eigh(a)
    torch.linalg.cond(a)


def space_of(device: str | None) -> ArraySpace:
    """:data:`NUMPY` for ``device`` None, else :func:`torch_space` of it."""
    return NUMPY if device is None else torch_space(device)
