"""Physically based capture renderer on Mitsuba 3 (the only package that imports Mitsuba).

One ray-tracing pass per pose, every frame of a pattern sequence synthesised from it, digitised
by the camera model of :mod:`virtus.sensor.camera`, with :mod:`virtus.capture.groundtruth` from the
same pass:

* :mod:`~virtus.render.settings` -- :class:`RenderSettings`, how a pose is rendered (spp,
  variant, bounces, lenses, aperture samples): one plain value that :func:`render`,
  :func:`render_device` and :class:`virtus.scanner.Scanner` take (no Mitsuba in it).
* :mod:`~virtus.render.renderer` -- :func:`render`: one pose, every frame and its ground
  truth, from a rig, a scene, a sequence, the projector and sensor models and the settings.
* :mod:`~virtus.render.backend` -- Mitsuba variant choice (CUDA if it works, else LLVM).
* :mod:`~virtus.render.mitsuba_scene` -- virtus scene -> Mitsuba shapes and BSDFs.
* :mod:`~virtus.render.tracing` -- camera rays, hits, projector coordinates, shading.
* :mod:`~virtus.render.synthesis` -- all frames from the trace (sparse lookups, host).
* :mod:`~virtus.render.jit.tracing` -- device-resident passes: taps and frames kept where they
  were traced (:func:`trace_device`, :class:`~virtus.render.jit.tracing.DeviceFrames`: one
  transfer to the host, or DLPack to PyTorch); :func:`render_device` is the whole pose.
* :mod:`~virtus.render.jit.synthesis` -- every frame of a pose synthesised and digitised in
  one device kernel (the GPU path; its CPU twin runs on ``llvm_ad_rgb``).
* :mod:`~virtus.render.jit.noise` -- the sensor's counter-based noise streams on the device.
* :mod:`~virtus.render.jit.decode` -- fringe decoding on the device.
* :mod:`~virtus.render.reference` -- Mitsuba's own projector emitter, one render per frame
  (validation and benchmarks).
"""

from virtus.render.backend import choose_variant
from virtus.render.jit.tracing import DeviceFrames, DeviceTrace, trace_device
from virtus.render.renderer import DeviceRendering, Rendering, render, render_device
from virtus.render.settings import RenderSettings
from virtus.render.synthesis import synthesize
from virtus.render.tracing import Trace, trace

__all__ = [
    "DeviceFrames",
    "DeviceRendering",
    "DeviceTrace",
    "RenderSettings",
    "Rendering",
    "Trace",
    "choose_variant",
    "render",
    "render_device",
    "synthesize",
    "trace",
    "trace_device",
]
