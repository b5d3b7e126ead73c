"""Physically based capture renderer on Mitsuba 3 (the only package that imports Mitsuba).

One ray-tracing pass per pose, every frame of a pattern sequence synthesised from it, digitised
by the camera model of :mod:`virtus.sensor`, with :mod:`virtus.groundtruth` from the same pass:

* :mod:`~virtus.render.backend` -- Mitsuba variant choice (CUDA if it works, else LLVM).
* :mod:`~virtus.render.mitsuba_scene` -- virtus scene -> Mitsuba shapes and BSDFs.
* :mod:`~virtus.render.tracing` -- camera rays, hits, projector coordinates, shading.
* :mod:`~virtus.render.synthesis` -- all frames from the trace (sparse lookups, host).
* :mod:`~virtus.render.synthesis_jit` -- the same with Dr.Jit gathers on the device
  (used with CUDA variants).
* :mod:`~virtus.render.reference` -- Mitsuba's own projector emitter, one render per frame
  (validation and benchmarks).
"""

from virtus.render.backend import choose_variant
from virtus.render.pipeline import Rendering, render
from virtus.render.synthesis import synthesize
from virtus.render.tracing import Trace, trace

__all__ = [
    "Rendering",
    "Trace",
    "choose_variant",
    "render",
    "synthesize",
    "trace",
]
