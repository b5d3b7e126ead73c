"""Mitsuba variant selection: the one place that imports Mitsuba and Dr.Jit.

``cuda_ad_rgb`` is used when a CUDA GPU works, ``llvm_ad_rgb`` (multi-threaded CPU)
otherwise. Override with the ``variant`` argument of the render functions or the environment
variable ``VIRTUS_MITSUBA_VARIANT``. CPU variants need a libLLVM >= 16 shared library.
"""

from __future__ import annotations

import functools
import os
from types import ModuleType

from virtus.errors import InputError, VirtusError

#: Environment variable that overrides the automatic variant choice.
VARIANT_ENV = "VIRTUS_MITSUBA_VARIANT"
#: Variants the renderer supports (JIT-compiled, RGB): GPU first, then CPU.
SUPPORTED_VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb")


@functools.cache
def _works(variant: str) -> bool:
    """True when ``variant`` can be selected and runs a kernel on this machine."""
    import drjit as dr
    import mitsuba as mi

    if variant not in mi.variants():
        return False
    try:
        mi.set_variant(variant)
        value = mi.Float([1.0, 2.0]) * 2.0
        dr.eval(value)
        return bool(dr.all(value == mi.Float([2.0, 4.0])))
    except Exception:  # a missing driver or LLVM shows up as various errors
        return False


def choose_variant(variant: str | None = None) -> str:
    """The Mitsuba variant to use: ``variant``, else ``$VIRTUS_MITSUBA_VARIANT``, else the
    first working one of ``cuda_ad_rgb``, ``llvm_ad_rgb``."""
    requested = variant or os.environ.get(VARIANT_ENV) or None
    if requested is not None:
        if requested not in SUPPORTED_VARIANTS:
            source = "variant" if variant else VARIANT_ENV
            raise InputError(source, f"one of {', '.join(SUPPORTED_VARIANTS)}", requested)
        if not _works(requested):
            raise VirtusError(f"Mitsuba variant {requested!r} does not work on this machine")
        return requested
    for candidate in SUPPORTED_VARIANTS:
        if _works(candidate):
            return candidate
    raise VirtusError(
        "no Mitsuba variant works here: llvm_ad_rgb needs a libLLVM >= 16 shared library "
        "(Debian: apt-get install libllvm19, or set DRJIT_LIBLLVM_PATH)"
    )


def on_gpu(variant: str | None = None) -> bool:
    """Whether :func:`choose_variant` of ``variant`` runs on a GPU (a CUDA variant): there
    frames, decodes and labels are best kept on the device."""
    return choose_variant(variant).startswith("cuda")


def mitsuba(variant: str | None = None) -> tuple[ModuleType, ModuleType, str]:
    """Select the variant and return ``(mitsuba, drjit, variant_name)``."""
    import drjit as dr
    import mitsuba as mi

    name = choose_variant(variant)
    if mi.variant() != name:
        mi.set_variant(name)
    return mi, dr, name


def variant_of(array: object) -> str:
    """The supported variant whose backend holds a Dr.Jit array (CUDA or LLVM)."""
    import drjit as dr

    return "cuda_ad_rgb" if dr.backend_v(array) == dr.JitBackend.CUDA else "llvm_ad_rgb"
