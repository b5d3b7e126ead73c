"""How a pose is rendered: :class:`RenderSettings`, one plain, frozen, validated value.

The settings of :func:`virtus.render.renderer.render` and
:func:`~virtus.render.renderer.render_device` that are not inputs of the pose (rig, scene,
sequence, camera pose, projector and sensor models, seed): supersamples, Mitsuba variant,
light transport and lenses. A :class:`virtus.scanner.Scanner` holds one in its ``render``
field and passes it to every render; the command line builds it once
(:func:`virtus.cli.options.build_scanner`).

This module imports neither Mitsuba nor Dr.Jit: a value, not a renderer. The tracer
(:func:`virtus.render.tracing.trace`) and :meth:`virtus.scanner.Scanner.check` check what
needs more than the value (spp a perfect square, the variant, the light-transport counts,
rays per pose for a camera).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from virtus.checks import positive_int
from virtus.errors import InputError
from virtus.geometry.optics import ThinLens

__all__ = ["MAX_RAYS", "MAX_SPP", "RenderSettings"]

#: Largest supersample count (a 32 x 32 grid): beyond it a pose needs > 10 GB of samples
#: at 960 x 960.
MAX_SPP = 1024
#: Largest number of camera rays per pose (pixels x spp): ~100 bytes each in the trace
#: (checked by :class:`virtus.scanner.Scanner`, which knows the camera).
MAX_RAYS = 1 << 27


@dataclass(frozen=True)
class RenderSettings:
    """The render settings of a pose: everything but its inputs (see the module docstring).

    ``RenderSettings()`` is the default render: 4 supersamples, automatic variant, direct
    light through pinholes.
    """

    #: Supersamples per camera pixel, a perfect square (a stratified grid centred on the
    #: pixel), 1 to :data:`MAX_SPP`.
    spp: int = 4
    #: Mitsuba variant (``cuda_ad_rgb`` or ``llvm_ad_rgb``); None = ``$VIRTUS_MITSUBA_VARIANT``
    #: or automatic (:func:`virtus.render.backend.choose_variant`).
    variant: str | None = None
    #: Path vertices per camera sample that see the projector (1 = direct light; more =
    #: interreflections, one tap per bounce), at most
    #: :data:`virtus.render.tracing.MAX_BOUNCES`.
    bounces: int = 1
    #: Thin lens of the projector (:class:`virtus.geometry.optics.ThinLens`: defocus), or
    #: None for a pinhole (in focus everywhere).
    projector_lens: ThinLens | None = None
    #: Thin lens of the camera (depth of field), or None for a pinhole.
    camera_lens: ThinLens | None = None
    #: Projector aperture samples per path vertex, only with a ``projector_lens``; None =
    #: the renderer's default (:data:`virtus.render.tracing.DEFAULT_APERTURE_SAMPLES` with a
    #: projector lens, 1 without).
    aperture_samples: int | None = None

    def __post_init__(self) -> None:
        spp = positive_int("spp", self.spp)
        if spp > MAX_SPP:
            raise InputError("spp", f"at most {MAX_SPP} supersamples per pixel", spp)
        object.__setattr__(self, "spp", spp)
        for name in ("projector_lens", "camera_lens"):
            lens = getattr(self, name)
            if lens is not None and not isinstance(lens, ThinLens):
                raise InputError(
                    name, "a virtus.geometry.optics.ThinLens or None", type(lens).__name__
                )

    def with_(self, **changes: Any) -> RenderSettings:
        """A copy with some fields replaced (checked again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (lenses as :meth:`ThinLens.to_dict`)."""
        return {
            "spp": self.spp,
            "variant": self.variant,
            "bounces": self.bounces,
            "projector_lens": None
            if self.projector_lens is None
            else self.projector_lens.to_dict(),
            "camera_lens": None if self.camera_lens is None else self.camera_lens.to_dict(),
            "aperture_samples": self.aperture_samples,
        }
