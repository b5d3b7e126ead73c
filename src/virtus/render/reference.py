"""Reference renderer: Mitsuba's own ``projector`` emitter, one render per frame.

An independent check of :func:`virtus.render.render` (and the baseline of the speed
benchmark): Mitsuba's ``perspective`` sensor and ``projector`` emitter with its ``direct``
integrator (one bounce) or its ``path`` tracer (``bounces`` > 1: interreflections, path depth
``bounces + 1``, no Russian roulette) render each frame separately. Mitsuba's frusta are
symmetric and ideal, so the rig must have centred principal points (``c = (size - 1) / 2``),
square pixels and no distortion; the scene must have no ambient light.

Frames: Mitsuba's camera/emitter local frame looks down +z with +x left and +y up, so an
OpenCV-frame pose maps to it through ``diag(-1, -1, 1)``; the projector texture's uv of
pixel ``j`` is ``(j + 0.5) / W``, which is the pixel-centre convention of
:mod:`virtus.geometry.optics`. Mitsuba's projector texture value is the irradiance on its image
plane
at z = 1 (uniform per pixel), the same model as :mod:`virtus.render.tracing`, so the two
renderers output radiance in the same units.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from virtus.checks import positive_int
from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.geometry.optics import Intrinsics
from virtus.geometry.transforms import Pose
from virtus.render.backend import mitsuba
from virtus.render.mitsuba_scene import scene_dict
from virtus.render.synthesis import LOOKUPS
from virtus.scene.model import Scene

#: Principal points and focal lengths must match Mitsuba's ideal frustum this closely (px).
_CENTRE_TOL_PX = 1e-9
#: OpenCV (x right, y down) -> Mitsuba local (x left, y up).
_FLIP = np.diag([-1.0, -1.0, 1.0, 1.0])


def _check_symmetric(name: str, intrinsics: Intrinsics) -> float:
    """Mitsuba's horizontal field of view (degrees) for an ideal, centred pinhole."""
    centre = ((intrinsics.width - 1) / 2, (intrinsics.height - 1) / 2)
    if intrinsics.has_distortion:
        raise InputError(
            f"{name}.dist", "no distortion (Mitsuba's pinhole is ideal)", intrinsics.dist
        )
    if max(abs(intrinsics.cx - centre[0]), abs(intrinsics.cy - centre[1])) > _CENTRE_TOL_PX:
        raise InputError(
            f"{name} principal point",
            f"the image centre {centre} (Mitsuba's frustum is symmetric)",
            (intrinsics.cx, intrinsics.cy),
        )
    if abs(intrinsics.fx - intrinsics.fy) > _CENTRE_TOL_PX:
        raise InputError(f"{name} focal lengths", "fx == fy", (intrinsics.fx, intrinsics.fy))
    return math.degrees(2.0 * math.atan(intrinsics.width / 2.0 / intrinsics.fx))


class ReferenceRenderer:
    """Mitsuba scene with a perspective camera and a projector emitter; renders one frame
    per call by swapping the projector texture.

    Parameters
    ----------
    rig : centred, undistorted, square-pixel camera and projector.
    scene : the scene (no ambient light).
    spp : samples per pixel (Mitsuba's ``stratified`` sampler; a perfect square).
    lookup : projector texture filter, ``"nearest"`` (DMD) or ``"bilinear"``.
    cam2world : camera pose in the scene's world frame (default identity).
    jitter : jitter the samples inside their strata (Mitsuba's default). ``False`` puts them
        at the strata centres, the positions :func:`virtus.render.render` uses, so the two
        renderers estimate each pixel from the same points.
    bsdf_samples : BSDF samples per pixel sample of Mitsuba's ``direct`` integrator. They
        cannot reach a point light and add nothing but time; Mitsuba's default is 1, 0 is the
        fastest correct setting (the one emitter sample is always used).
    variant : Mitsuba variant (default automatic).
    """

    def __init__(
        self,
        rig: Rig,
        scene: Scene,
        *,
        spp: int = 4,
        lookup: str = "nearest",
        cam2world: Pose | None = None,
        jitter: bool = True,
        bsdf_samples: int = 0,
        bounces: int = 1,
        variant: str | None = None,
    ) -> None:
        if lookup not in LOOKUPS:
            raise InputError("lookup", f"one of {LOOKUPS}", lookup)
        if scene.ambient != 0:
            raise InputError(
                "scene.ambient", "0 (Mitsuba's projector has no ambient term)", scene.ambient
            )
        camera_fov = _check_symmetric("camera", rig.camera.intrinsics)
        projector_fov = _check_symmetric("projector", rig.projector.intrinsics)
        self.spp = positive_int("spp", spp)
        cam2world = Pose.identity() if cam2world is None else cam2world
        proj2world = cam2world @ rig.proj2cam
        mi, dr, self.variant = mitsuba(variant)
        self._mi = mi
        projector = rig.projector.intrinsics
        camera = rig.camera.intrinsics
        description = scene_dict(mi, dr, scene)
        description["sensor"] = {
            "type": "perspective",
            "fov": camera_fov,
            "fov_axis": "x",
            "to_world": mi.ScalarTransform4f((cam2world.matrix @ _FLIP).tolist()),
            "film": {
                "type": "hdrfilm",
                "width": camera.width,
                "height": camera.height,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
            },
            "sampler": {"type": "stratified", "sample_count": self.spp, "jitter": jitter},
        }
        blank = mi.Bitmap(np.zeros((projector.height, projector.width, 1), dtype=np.float32))
        description["projector"] = {
            "type": "projector",
            "fov": projector_fov,
            "to_world": mi.ScalarTransform4f((proj2world.matrix @ _FLIP).tolist()),
            "irradiance": {
                "type": "bitmap",
                "bitmap": blank,
                "raw": True,
                "filter_type": lookup,
                "wrap_mode": "clamp",
            },
        }
        bounces = positive_int("bounces", bounces)
        if bounces == 1:
            description["integrator"] = {
                "type": "direct",
                "emitter_samples": 1,
                "bsdf_samples": int(bsdf_samples),
            }
        else:
            depth = bounces + 1
            description["integrator"] = {"type": "path", "max_depth": depth, "rr_depth": depth + 1}
        self._scene = mi.load_dict(description)
        self._params = mi.traverse(self._scene)
        self._key = next(k for k in self._params.keys() if k.endswith("irradiance.data"))
        self._shape = (projector.height, projector.width)

    def render_image(self, image: np.ndarray, seed: int = 0) -> np.ndarray:
        """Radiance (H, W) float32 of the scene lit by a projector ``image``
        ((H_p, W_p) float in [0, 1])."""
        image = np.asarray(image, dtype=np.float32)
        if image.shape != self._shape:
            raise InputError("image", f"a projector image of shape {self._shape}", image.shape)
        mi = self._mi
        self._params[self._key] = mi.TensorXf(image[..., None])
        self._params.update()
        result = mi.render(self._scene, spp=self.spp, seed=seed)
        return np.asarray(result, dtype=np.float32)[..., 0]

    def render_frames(
        self, sequence: Any, indices: list[int] | None = None, seed: int = 0
    ) -> np.ndarray:
        """Radiance (len(indices), H, W) float32 of the given frames of ``sequence``."""
        indices = list(range(len(sequence.frames))) if indices is None else list(indices)
        return np.stack(
            [self.render_image(sequence.image(i), seed=seed + k) for k, i in enumerate(indices)]
        )
