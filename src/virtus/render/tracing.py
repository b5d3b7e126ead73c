"""One ray-tracing pass per pose: camera rays -> light paths -> projector coordinates and weights.

For every camera pixel this records *taps*: per camera supersample, path vertex and projector
aperture sample, the projector coordinates ``(u_p, v_p)`` that light the vertex and the
radiance that a full-on (white) projector sends back to the camera along that path. Light
transport is linear in the pattern, so every frame of a sequence is synthesised from this one
pass (:mod:`virtus.render.synthesis`): ``L_f(p) = sum_t weight[p, t] pattern_f(u_p or v_p
[p, t]) + ambient[p]``.

Model
-----
* Camera rays come from ``rig.camera.intrinsics.unproject`` (any principal point, lens
  distortion) at ``spp = s * s`` stratified positions per pixel: an s x s grid at offsets
  ``(i + 0.5) / s - 0.5`` px, whose centroid is the pixel centre (2 x 2: +-0.25 px).
* Camera depth of field (``camera_lens``, a :class:`~virtus.geometry.optics.ThinLens`): the pinhole
  ray of a supersample meets the focus plane z = d_f (camera frame) at F; the ray starts
  instead at a point a of the aperture disk (diameter A, in the plane z = 0) and goes
  toward F. The pixel's spp aperture points are stratified (one per equal-area annulus, at
  golden-angle steps from a random angle per pixel) and paired with the sub-pixel positions
  through a random shift per pixel, so the two are uncorrelated. Radiometry: the mean over
  the aperture (no cos^4 vignetting). A point at depth d is spread over a disk of diameter
  ``A fx |d - d_f| / (d d_f)`` px: :meth:`ThinLens.blur_diameter_px` with ``fx`` read as
  the image distance in pixels (``focal_length_m`` None, or ``focal_px = fx (d_f - f) /
  d_f``).
* Surface points go to the projector frame through ``rig.cam2proj`` and to projector pixels
  through ``rig.projector.intrinsics.project`` (its principal point and distortion).
* The projector is a point source at its optical centre whose irradiance on its virtual
  image plane z = 1 is uniform over the projector pixels (so each pixel emits the same
  power; this is also Mitsuba's ``projector`` emitter): radiant intensity
  ``I = pi / cos^3(theta_p)`` for a white pixel, theta_p the angle to the projector axis.
  Lens distortion's change of pixel solid angle is neglected.
* Radiance toward the camera from a surface point X: ``L = f(wi, wo) cos(theta_o) I / d^2``
  with the hit's Mitsuba BSDF ``f`` (``bsdf.eval`` includes the cosine), ``d`` the distance
  to the projector centre, zero where a shadow ray to the projector is blocked or the point
  falls outside the projector image. A Lambertian surface of albedo rho facing the projector
  at 1 m on its axis therefore has ``L = rho``.
* Projector defocus (``projector_lens``): ``aperture_samples`` points a of the projector's
  aperture disk (stratified as the camera's, a new random angle per vertex) each carry
  ``1 / aperture_samples`` of the power. Through a, the projector pixel that lights X is the
  pinhole projection of the point where the line a -> X crosses the projector focus plane
  z = d_f; the shadow ray and the BSDF direction go from X to a; ``I / d^2`` stays that of
  the centre (the aperture is small against the distance). A point at projector depth z sees
  a disk of projector pixels of diameter ``A fx |z - d_f| / (z d_f)``.
* Interreflections (``bounces`` > 1): from each camera hit the path continues by sampling
  the BSDF (``bsdf.sample``; the throughput is its weight f cos / pdf), up to ``bounces``
  vertices, with next-event estimation toward the projector at every vertex (vertex 0 = the
  camera's surface point gives the direct light, vertex k the light that bounced k times).
  No Russian roulette: a fixed, small number of vertices. Random numbers are counter-based
  (TEA hashes of the global camera-sample index and a stream number, see ``_STREAM_*``),
  so a trace does not depend on how the rays are split into chunks.
* Taps: each camera supersample has ``T = bounces * aperture_samples`` taps, so a pixel has
  ``S = spp * T`` (column ``s * T + k * aperture_samples + j`` for supersample s, vertex k,
  aperture sample j). Camera aperture samples do not add taps: they move the supersamples.
  With ``bounces=1`` and no lenses the pass is the single-bounce pinhole one, bit for bit.
* Ambient light: ``L_amb = scene.ambient * rho_d`` with ``rho_d`` Mitsuba's diffuse
  reflectance of the camera hit (no occlusion), plus the scene's ``lights`` (area lights and
  an environment, see :class:`virtus.scene.model.Scene`): next-event estimation toward them at every
  path vertex with the same paths (visibility included), and the emitters the camera rays
  see directly. It is pattern-independent and goes into ``Trace.ambient``.
* Ground truth uses one extra pinhole ray through each pixel centre (lenses do not move
  it); ``mask_multibounce`` marks pixels whose white-projector radiance from vertices >= 1
  exceeds that of vertex 0.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.capture.groundtruth import GroundTruth
from virtus.checks import positive_int
from virtus.errors import InputError
from virtus.geometry.devices import Rig
from virtus.geometry.optics import Intrinsics, ThinLens
from virtus.geometry.transforms import Pose
from virtus.render.backend import mitsuba, variant_of
from virtus.render.mitsuba_scene import check_in_front, load_scene
from virtus.render.rays import camera_rays, sample_offsets
from virtus.scene.model import Scene

#: Rays traced per Mitsuba call: bounds memory (~100 B per ray inside Dr.Jit).
_RAYS_PER_CHUNK = 1 << 23
#: Most path vertices per camera sample (``bounces``): each adds a tap per sample; light
#: that bounced more than 7 times is negligible on diffuse scenes of albedo < 0.9.
MAX_BOUNCES = 8
#: Most projector aperture samples per path vertex: each adds a tap per sample.
MAX_APERTURE_SAMPLES = 1024
#: Projector aperture samples per vertex when a projector lens is given and the count is not.
DEFAULT_APERTURE_SAMPLES = 16
#: Golden angle (radians): successive aperture points turn by it (a Vogel spiral).
_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))
#: TEA rounds per random number: 8 decorrelates consecutive indices (Zafar et al. 2010).
_TEA_ROUNDS = 8
#: Random streams (second TEA key; the first is the global camera-sample index, or the
#: pixel index for per-pixel numbers). Camera aperture: shift, angle (per pixel), radius.
_STREAM_CAMERA = 0
#: BSDF sampling at vertex k: streams ``_STREAM_BSDF + 3 k + (0, 1, 2)``.
_STREAM_BSDF = 16
#: Emitter (lights) sampling at vertex k: ``_STREAM_LIGHTS + 2 k + (0, 1)``.
_STREAM_LIGHTS = 64
#: Projector aperture at vertex k: angle ``_STREAM_PROJECTOR + k * 2048``, radius of sample
#: j ``... + 1 + j``.
_STREAM_PROJECTOR = 1 << 16


@dataclass(frozen=True, eq=False)
class Trace:
    """Result of one tracing pass.

    Attributes
    ----------
    height, width : camera image size in pixels.
    projector_width, projector_height : projector image size in pixels.
    spp : camera supersamples per pixel.
    weight : (P, S) float32, P = H * W pixels in row-major order, S = spp * bounces *
        aperture_samples taps (column ``s * T + k * aperture_samples + j`` for supersample s,
        path vertex k, projector aperture sample j, T = :attr:`taps_per_sample`): radiance each
        tap adds to its pixel under a white projector, already divided by ``spp`` and
        ``aperture_samples``; 0 where the tap is unlit (no hit, shadowed, outside the
        projector image, path ended).
    u_p, v_p : (P, S) float32 projector pixel coordinates of each tap; 0 where ``weight``
        is 0.
    ambient : (P,) float32 ambient radiance of each pixel (mean over its samples).
    gt : ground truth through the pixel centres.
    variant : the Mitsuba variant that traced it.
    bounces : path vertices per camera sample (1 = direct light only).
    aperture_samples : projector aperture samples per vertex (1 = pinhole projector).
    """

    height: int
    width: int
    spp: int
    projector_width: int
    projector_height: int
    weight: np.ndarray
    u_p: np.ndarray
    v_p: np.ndarray
    ambient: np.ndarray
    gt: GroundTruth
    variant: str
    bounces: int = 1
    aperture_samples: int = 1

    @property
    def taps_per_sample(self) -> int:
        """Taps per camera supersample, ``bounces * aperture_samples``."""
        return self.bounces * self.aperture_samples

    @functools.cached_property
    def direct(self) -> np.ndarray:
        """(P,) float32 radiance from a full-on projector (all bounces), without ambient."""
        # A matrix-vector product: numpy's sum over a short last axis is several times slower.
        return self.weight @ np.ones(self.weight.shape[1], dtype=np.float32)

    @property
    def white(self) -> np.ndarray:
        """(H, W) float32 radiance under a full-on projector, ambient included."""
        return (self.direct + self.ambient).reshape(self.height, self.width)

    @functools.cached_property
    def bounce_radiance(self) -> np.ndarray:
        """(bounces, P) float32 white-projector radiance by path vertex: row 0 is the direct
        light, row k the light that bounced k times before the camera's surface point."""
        return _by_vertex(self.weight, self.bounces, self.aperture_samples)


def _by_vertex(weight: np.ndarray, bounces: int, aperture_samples: int) -> np.ndarray:
    """(P, S) tap weights -> (bounces, P) float32 sums per path vertex."""
    n_pixels = weight.shape[0]
    per_vertex = weight.reshape(n_pixels, -1, bounces, aperture_samples).sum(axis=(1, 3))
    return np.ascontiguousarray(per_vertex.T, dtype=np.float32)


def _inside(u: np.ndarray, v: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """(N,) bool: projector coordinates inside the projector image (NaN -> False)."""
    with np.errstate(invalid="ignore"):
        return (
            (u >= -0.5) & (u < intrinsics.width - 0.5) & (v >= -0.5) & (v < intrinsics.height - 0.5)
        )


def _check_lens(name: str, lens: object) -> ThinLens | None:
    if lens is not None and not isinstance(lens, ThinLens):
        raise InputError(name, "a virtus.geometry.optics.ThinLens or None", type(lens).__name__)
    return lens


def _check_count(name: str, value: object, high: int) -> int:
    count = positive_int(name, value)
    if count > high:
        raise InputError(name, f"an integer in [1, {high}]", value)
    return count


def _device_constants(mi: Any, dr: Any, kind: Any, values: np.ndarray) -> Any:
    """A pose's constants as one small device array (one upload). The kernels read them
    with ``dr.gather`` at fixed indices, so they are kernel parameters, not literals in the
    kernels' source: the next pose (a calibration's board, a dataset's camera) reuses the
    compiled kernels instead of compiling them again (0.1-0.6 s a pose on 2 CPU cores)."""
    array = kind(np.ascontiguousarray(values).reshape(-1))
    dr.eval(array)
    return array


def coherent_camera_rays(variant: str) -> bool:
    """Whether camera rays are traced with Mitsuba's ``coherent`` hint: on LLVM only, where
    Embree uses it. Mitsuba's CUDA path drops the hint (``Scene::ray_intersect`` marks it
    unused and calls ``ray_intersect_gpu(ray, ray_flags, active)``), so there the plain call
    gives the same OptiX kernel and says what runs."""
    return variant.startswith("llvm")


class _Tracer:
    """Dr.Jit side of one pass: Mitsuba scene, camera and projector poses in its world."""

    def __init__(self, mi, dr, mscene, cam2world: Pose, proj2world: Pose) -> None:  # noqa: ANN001
        self.mi, self.dr, self.mscene = mi, dr, mscene
        # Every per-pose value lives in one device array, read through _bind, float32 as
        # Mitsuba's literals would be: floats 0-95 cam2world, proj2world, world2proj (each
        # its 4 x 4 matrix, then its inverse transpose, row-major), 96-98 the projector's
        # centre (world frame), 99-107 world2cam's rotation (row-major).
        transforms = [
            mi.ScalarTransform4f(pose.matrix.tolist())
            for pose in (cam2world, proj2world, proj2world.inverse())
        ]
        host = [np.asarray(m, dtype=np.float32)
                for t in transforms for m in (t.matrix, t.inverse_transpose)]  # fmt: skip
        host += [np.asarray(proj2world.t, np.float32), cam2world.R.T.astype(np.float32)]
        self._constants = _device_constants(
            mi, dr, mi.Float, np.concatenate([a.reshape(-1) for a in host])
        )
        self.has_lights = len(mscene.emitters()) > 0

    def _bind(self, n: int) -> None:
        """Set the pose's transforms (``cam2world``, ``proj2world``, ``world2proj``), the
        projector's centre and ``world2cam_R`` for kernels of ``n`` lanes: gathers at fixed
        indices of the pose's constants, so the kernels' source is the same for every pose
        (a width-1 value would cost a copy launch per entry, a literal a compilation)."""
        mi, dr, constants = self.mi, self.dr, self._constants

        def entry(index: int) -> Any:
            return dr.gather(mi.Float, constants, dr.full(mi.UInt32, index, n))

        def matrix(k: int) -> Any:
            return mi.Matrix4f([[entry(16 * k + 4 * i + j) for j in range(4)] for i in range(4)])

        self.cam2world, self.proj2world, self.world2proj = (
            mi.Transform4f(matrix(2 * k), matrix(2 * k + 1)) for k in range(3)
        )
        self.projector = mi.Point3f(entry(96), entry(97), entry(98))
        self.world2cam_R = [[entry(99 + 3 * i + j) for j in range(3)] for i in range(3)]  # noqa: N815

    def _rays(self, directions):  # noqa: ANN001, ANN202
        mi = self.mi
        d = directions
        if not isinstance(d, mi.Vector3f):
            d = mi.Vector3f(directions[0], directions[1], directions[2])
        ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), d)
        return self.cam2world @ ray

    def _camera_intersect(self, ray):  # noqa: ANN001, ANN202
        """The surface interactions of camera rays, traced as *coherent* rays (neighbouring
        lanes are neighbouring pixels) on LLVM: Embree then traverses them in packets, the
        trace of a pose taking 1.12-1.16x less CPU time on 2 cores, with the same hits bit for
        bit. On CUDA the plain call (see :func:`coherent_camera_rays`). Rays that bounce are
        incoherent: they take the plain call."""
        if coherent_camera_rays(variant_of(ray.d.x)):
            return self.mscene.ray_intersect(ray, self.mi.RayFlags.All, True)
        return self.mscene.ray_intersect(ray)

    def _indices(self, count: int, first: int):  # noqa: ANN202
        """UInt32 global sample indices ``first, ..., first + count - 1``; ``first`` is an
        opaque variable, so every chunk reuses one compiled kernel."""
        mi, dr = self.mi, self.dr
        return dr.arange(mi.UInt32, count) + dr.opaque(mi.UInt32, first)

    def _random(self, key, stream: int):  # noqa: ANN001, ANN202
        """Uniform [0, 1) Float per entry of ``key`` (UInt32), from stream ``stream``."""
        mi = self.mi
        return mi.sample_tea_float32(key, mi.UInt32(stream), _TEA_ROUNDS)

    def _disk(self, stratum, count: int, radius_sample, angle):  # noqa: ANN001, ANN202
        """Point of the unit disk in equal-area annulus ``stratum`` of ``count`` (a Vogel
        spiral turned by ``angle``): uniform over the disk when ``radius_sample`` is uniform in
        [0, 1) and ``angle`` uniform in [0, 2 pi)."""
        mi, dr = self.mi, self.dr
        index = mi.Float(stratum)
        r = dr.sqrt((index + radius_sample) * (1.0 / count))
        theta = angle + index * _GOLDEN_ANGLE
        return r * dr.cos(theta), r * dr.sin(theta)

    def _lens_rays(self, directions, first: int, spp: int, lens: ThinLens):  # noqa: ANN001, ANN202
        """Thin-lens camera rays: from a stratified aperture point toward the point where the
        pinhole ray meets the focus plane (see the module docstring)."""
        mi, dr = self.mi, self.dr
        d = directions
        if not isinstance(d, mi.Vector3f):
            d = mi.Vector3f(directions[0], directions[1], directions[2])
        index = self._indices(dr.width(d), first)
        pixel = index // spp
        shift = mi.sample_tea_32(pixel, mi.UInt32(_STREAM_CAMERA), _TEA_ROUNDS)[0] % spp
        angle = 2.0 * dr.pi * self._random(pixel, _STREAM_CAMERA + 1)
        x, y = self._disk((index % spp + shift) % spp, spp, self._random(index, 2), angle)
        radius = 0.5 * lens.aperture_m
        origin = mi.Point3f(radius * x, radius * y, 0.0)
        focus = d * (lens.focus_distance_m / d.z)
        return self.cam2world @ mi.Ray3f(origin, dr.normalize(focus - origin))

    def centre(self, directions: np.ndarray, cam2proj: Pose) -> dict[str, np.ndarray]:
        """:meth:`centre_device` of pixel-centre rays (3, N) float64 (camera frame), copied
        to the host."""
        d = [self.mi.Float64(directions[i]) for i in range(3)]
        out = self.centre_device(d, cam2proj)
        return {key: value.numpy() for key, value in out.items()}

    def centre_device(self, d: list[Any], cam2proj: Pose) -> dict[str, Any]:
        """Pixel-centre rays, three ``Float64`` (N,) direction components in the camera
        frame -> ground truth per ray as evaluated device arrays: point ``px, py, pz``
        (camera frame, Float64, NaN where missed), normal ``nx, ny, nz`` toward the camera,
        ``hit``, ``occluded`` (shadow), and the point's normalised projector coordinates
        ``xn, yn`` (``x/z, y/z``, Float64, NaN where missed or behind the projector).

        Points are ``t * d`` in float64 with Mitsuba's (float32) distance ``t``."""
        mi, dr = self.mi, self.dr
        lanes = dr.width(d[0])
        self._bind(lanes)
        si = self._camera_intersect(self._rays(mi.Vector3f(*(mi.Float(c) for c in d))))
        hit = si.is_valid()
        occluded = self.mscene.ray_test(si.spawn_ray_to(self.projector), hit)
        t = dr.select(hit, mi.Float64(si.t), dr.nan)
        point = [t * d[i] for i in range(3)]
        # Shading normal, world -> camera frame, turned toward the camera (two-sided).
        n = si.sh_frame.n
        R = self.world2cam_R  # noqa: N806
        normal = [R[i][0] * n.x + R[i][1] * n.y + R[i][2] * n.z for i in range(3)]
        facing = normal[0] * d[0] + normal[1] * d[1] + normal[2] * d[2] > 0
        normal = [dr.select(hit, dr.select(facing, -c, c), dr.nan) for c in normal]
        rt = _device_constants(mi, dr, mi.Float64, cam2proj.matrix[:3])
        Rt = [[dr.gather(mi.Float64, rt, dr.full(mi.UInt32, 4 * i + j, lanes)) for j in range(4)]  # noqa: N806
              for i in range(3)]  # fmt: skip
        x = [Rt[i][0] * point[0] + Rt[i][1] * point[1] + Rt[i][2] * point[2] + Rt[i][3]
             for i in range(3)]  # fmt: skip
        # A true division: dr.rcp may be an approximation on GPUs (rcp.approx.f64).
        in_front = x[2] > 0
        xn = dr.select(in_front, x[0] / x[2], dr.nan)
        yn = dr.select(in_front, x[1] / x[2], dr.nan)
        out = {
            "px": point[0], "py": point[1], "pz": point[2],
            "nx": normal[0], "ny": normal[1], "nz": normal[2],
            "xn": xn, "yn": yn,
            "hit": hit, "occluded": occluded & hit,
        }  # fmt: skip
        dr.eval(*out.values())
        return out

    def _tap(self, si, bsdf, active, throughput, scale: float, projector: Intrinsics, aperture):  # noqa: ANN001, ANN202
        """One tap of a path vertex: next-event estimation toward the projector centre
        (``aperture`` None) or toward an aperture point ``(x, y, focus distance)`` in the
        projector frame (metres). Returns Dr.Jit arrays: ``weight, u_p, v_p`` without
        projector distortion, else ``radiance, xn, yn`` for numpy to distort."""
        mi, dr = self.mi, self.dr
        if aperture is None:
            target = self.projector
        else:
            ax, ay, focus = aperture
            target = self.proj2world @ mi.Point3f(ax, ay, 0.0)
        occluded = self.mscene.ray_test(si.spawn_ray_to(target), active)
        p_proj = self.world2proj @ si.p
        z = p_proj.z
        lit = active & ~occluded & (z > 0)
        to_projector = dr.normalize(target - si.p)
        f_cos = bsdf.eval(mi.BSDFContext(), si, si.to_local(to_projector), lit)[0]
        # pi f cos(theta_o) / (d^2 cos^3(theta_p)) = pi f cos(theta_o) |X_p| / z_p^3
        radiance = scale * f_cos * dr.norm(p_proj) / (z * z * z)
        if throughput is not None:
            radiance = radiance * throughput
        inv_z = dr.select(lit, dr.rcp(z), 0.0)
        if aperture is None:
            xn, yn = p_proj.x * inv_z, p_proj.y * inv_z
        else:
            # The line a -> X meets z = d_f at a + (X - a) d_f / z: its pinhole projection.
            xn = dr.select(lit, ax / focus + (p_proj.x - ax) * inv_z, 0.0)
            yn = dr.select(lit, ay / focus + (p_proj.y - ay) * inv_z, 0.0)
        if projector.has_distortion:
            return {"xn": xn, "yn": yn, "radiance": dr.select(lit, radiance, 0.0)}
        u, v = project_normalized(projector, xn, yn)
        lit &= _inside(u, v, projector)
        return {
            "weight": dr.select(lit, radiance, 0.0),
            "u_p": dr.select(lit, u, 0.0),
            "v_p": dr.select(lit, v, 0.0),
        }

    def _seen(self, si):  # noqa: ANN001, ANN202
        """Radiance (Float) of the emitter a ray sees: the surface's area emitter where it
        hits one, the environment where it hits nothing, else 0."""
        return self.mi.Float(si.emitter(self.mscene).eval(si)[0])

    def _lights(self, si, bsdf, active, throughput, index, vertex: int):  # noqa: ANN001, ANN202
        """Radiance (Float) from the scene's emitters at a path vertex: one emitter sample
        (Mitsuba's ``sample_emitter_direction``, visibility tested) times the BSDF."""
        mi, dr = self.mi, self.dr
        sample = mi.Point2f(
            self._random(index, _STREAM_LIGHTS + 2 * vertex),
            self._random(index, _STREAM_LIGHTS + 2 * vertex + 1),
        )
        ds, emitted = self.mscene.sample_emitter_direction(si, sample, True, active)
        usable = active & (ds.pdf > 0)
        f_cos = bsdf.eval(mi.BSDFContext(), si, si.to_local(ds.d), usable)[0]
        radiance = dr.select(usable, f_cos * emitted[0], 0.0)
        return radiance if throughput is None else radiance * throughput

    def samples_device(
        self,
        directions: np.ndarray | object,
        first: int,
        projector: Intrinsics,
        spp: int,
        ambient: float,
        bounces: int = 1,
        projector_lens: ThinLens | None = None,
        aperture_samples: int = 1,
        camera_lens: ThinLens | None = None,
    ) -> tuple[list[dict], dict]:
        """Supersample rays (3, N) float32, camera frame (numpy, or a Dr.Jit ``Vector3f``
        already on the device), whose first has the global index ``first`` -> Dr.Jit arrays,
        evaluated, on the device: per tap (T dicts of (N,) Float) the white-projector radiance
        divided by ``spp * aperture_samples`` (0 where unlit) and the projector coordinates
        (0 where unlit); per sample (N,): with ambient light the diffuse reflectance
        ``rho_d``, with scene lights their radiance ``lights``.

        Without projector distortion the taps are ``weight, u_p, v_p``; with distortion
        the normalised coordinates ``(x/z, y/z)`` (keys ``xn``, ``yn``, and ``radiance``)
        for the projector model to distort.
        """
        mi, dr = self.mi, self.dr
        n = dr.width(directions) if isinstance(directions, mi.Vector3f) else directions.shape[1]
        self._bind(n)
        if camera_lens is None:
            ray = self._rays(directions)
        else:
            ray = self._lens_rays(directions, first, spp, camera_lens)
        index = self._indices(n, first)
        si = self._camera_intersect(ray)
        hit = si.is_valid()
        active, throughput = hit, None
        scale = dr.pi / (spp * aperture_samples)
        taps: list[dict] = []
        per_sample = {}
        # Scene lights: the emitters the camera ray sees (an area light, or the environment
        # where it hits nothing); at later vertices only next-event estimation counts them.
        lights = self._seen(si) if self.has_lights else None
        for vertex in range(bounces):
            bsdf = si.bsdf(ray)
            if projector_lens is None:
                taps.append(self._tap(si, bsdf, active, throughput, scale, projector, None))
            else:
                focus = projector_lens.focus_distance_m
                radius = 0.5 * projector_lens.aperture_m
                stream = _STREAM_PROJECTOR + vertex * 2048
                angle = 2.0 * dr.pi * self._random(index, stream)
                for j in range(aperture_samples):
                    x, y = self._disk(
                        j, aperture_samples, self._random(index, stream + 1 + j), angle
                    )
                    aperture = (radius * x, radius * y, focus)
                    taps.append(self._tap(si, bsdf, active, throughput, scale, projector, aperture))
            if lights is not None:
                lights += self._lights(si, bsdf, active, throughput, index, vertex)
            if vertex == 0 and ambient > 0:
                per_sample["rho_d"] = dr.select(hit, bsdf.eval_diffuse_reflectance(si, hit)[0], 0.0)
            if vertex + 1 == bounces:
                break
            stream = _STREAM_BSDF + 3 * vertex
            sample = mi.Point2f(self._random(index, stream + 1), self._random(index, stream + 2))
            bs, weight = bsdf.sample(
                mi.BSDFContext(), si, self._random(index, stream), sample, active
            )
            throughput = weight[0] if throughput is None else throughput * weight[0]
            active = active & (bs.pdf > 0) & (throughput > 0)
            ray = si.spawn_ray(si.to_world(bs.wo))
            # One kernel per vertex: the taps so far and the state the next vertex needs.
            state = [a for tap in taps for a in tap.values()]
            extra = [] if lights is None else [lights]
            dr.eval(*state, *per_sample.values(), *extra, ray, throughput, active)
            si = self.mscene.ray_intersect(ray, active)
            active = active & si.is_valid()
        if lights is not None:
            per_sample["lights"] = lights
        dr.eval(*[a for tap in taps for a in tap.values()], *per_sample.values())
        return taps, per_sample

    def samples(self, directions: np.ndarray, first: int, *args, **kwargs) -> dict[str, np.ndarray]:  # noqa: ANN002, ANN003
        """:meth:`samples_device` with every array copied to numpy: per sample and tap (N, T)
        float32 (``weight``, ``u_p``, ``v_p``, or ``radiance``, ``xn``, ``yn``), per sample
        (N,) ``rho_d`` and ``lights`` where present."""
        taps, per_sample = self.samples_device(directions, first, *args, **kwargs)
        if len(taps) == 1:  # a view, no copy (the ideal renderer's case)
            out = {key: value.numpy()[:, None] for key, value in taps[0].items()}
        else:
            out = {key: np.stack([tap[key].numpy() for tap in taps], axis=1) for key in taps[0]}
        out.update({key: value.numpy() for key, value in per_sample.items()})
        return out


@dataclass(frozen=True, eq=False)
class Pass:
    """One pose's checked tracing settings and its Mitsuba scene: what :func:`trace` and
    the device-resident :func:`virtus.render.jit.tracing.trace_device` share."""

    rig: Rig
    scene: Scene
    cam2world: Pose
    spp: int
    bounces: int
    aperture_samples: int
    projector_lens: ThinLens | None
    camera_lens: ThinLens | None
    mi: Any
    dr: Any
    variant: str
    tracer: _Tracer

    @property
    def camera(self) -> Intrinsics:
        return self.rig.camera.intrinsics

    @property
    def projector(self) -> Intrinsics:
        return self.rig.projector.intrinsics

    @property
    def height(self) -> int:
        return self.camera.height

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def n_pixels(self) -> int:
        return self.height * self.width

    @property
    def n_rays(self) -> int:
        """Camera supersamples of the pose."""
        return self.n_pixels * self.spp

    @property
    def taps_per_sample(self) -> int:
        """Taps per camera supersample, ``bounces * aperture_samples``."""
        return self.bounces * self.aperture_samples

    @property
    def chunk(self) -> int:
        """Supersamples per Mitsuba call (a whole number of pixels)."""
        return max(self.spp, _RAYS_PER_CHUNK // (self.spp * self.taps_per_sample) * self.spp)

    def options(self) -> dict[str, Any]:
        """Keyword arguments of :meth:`_Tracer.samples_device` besides the rays."""
        return {
            "projector": self.projector,
            "spp": self.spp,
            "ambient": self.scene.ambient,
            "bounces": self.bounces,
            "projector_lens": self.projector_lens,
            "aperture_samples": self.aperture_samples,
            "camera_lens": self.camera_lens,
        }


def prepare_pass(
    rig: Rig,
    scene: Scene,
    *,
    spp: int = 4,
    cam2world: Pose | None = None,
    variant: str | None = None,
    bounces: int = 1,
    projector_lens: ThinLens | None = None,
    camera_lens: ThinLens | None = None,
    aperture_samples: int | None = None,
) -> Pass:
    """Check the settings of :func:`trace` (same parameters) and load the scene into
    Mitsuba."""
    if not isinstance(rig, Rig):
        raise InputError("rig", "a virtus.geometry.devices.Rig", type(rig).__name__)
    if not isinstance(scene, Scene):
        raise InputError("scene", "a virtus.scene.model.Scene", type(scene).__name__)
    cam2world = Pose.identity() if cam2world is None else cam2world
    offsets = sample_offsets(spp)
    spp = len(offsets)
    bounces = _check_count("bounces", bounces, MAX_BOUNCES)
    projector_lens = _check_lens("projector_lens", projector_lens)
    camera_lens = _check_lens("camera_lens", camera_lens)
    if projector_lens is None:
        if aperture_samples not in (None, 1):
            raise InputError(
                "aperture_samples", "None or 1 without a projector_lens", aperture_samples
            )
        aperture_samples = 1
    elif aperture_samples is None:
        aperture_samples = DEFAULT_APERTURE_SAMPLES
    else:
        aperture_samples = _check_count("aperture_samples", aperture_samples, MAX_APERTURE_SAMPLES)
    check_in_front(scene, cam2world.inverse())

    mi, dr, variant_name = mitsuba(variant)
    mscene = load_scene(variant_name, scene)

    camera = rig.camera.intrinsics
    height, width = camera.height, camera.width
    n_pixels = height * width
    n_rays = n_pixels * spp
    if n_rays >= 2**32:
        raise InputError("spp", f"at most {2**32 // n_pixels - 1} for {width} x {height} px", spp)
    tracer = _Tracer(mi, dr, mscene, cam2world, cam2world @ rig.proj2cam)

    return Pass(
        rig, scene, cam2world, spp, bounces, aperture_samples, projector_lens, camera_lens,
        mi, dr, variant_name, tracer,
    )  # fmt: skip


def project_normalized(projector: Intrinsics, xn: Any, yn: Any) -> tuple[Any, Any]:
    """The projector model (as ``Intrinsics.project``: distortion, then focal lengths and
    principal point) on normalised projector coordinates ``xn, yn``: ``(u_p, v_p)`` px.
    Plain arithmetic, the one formula for numpy arrays on the host and Dr.Jit arrays on
    the device and inside the tracing kernels (NaN stays NaN)."""
    x, y = projector.distort_xy(xn, yn) if projector.has_distortion else (xn, yn)
    u = float(projector.fx) * x + float(projector.cx)
    v = float(projector.fy) * y + float(projector.cy)
    return u, v


def centre_truth(ps: Pass) -> GroundTruth:
    """Ground truth through the pixel centres (``mask_multibounce`` left empty: it needs
    the taps)."""
    rig, tracer, projector = ps.rig, ps.tracer, ps.projector
    height, width, n_pixels = ps.height, ps.width, ps.n_pixels
    centre_dirs, _ = camera_rays(ps.camera, ps.spp)
    parts = [
        tracer.centre(centre_dirs[:, i : i + _RAYS_PER_CHUNK], rig.cam2proj)
        for i in range(0, n_pixels, _RAYS_PER_CHUNK)
    ]
    c = _concatenate(parts)
    hit = c["hit"]
    points = np.stack([c["px"], c["py"], c["pz"]], axis=1)
    normals = np.stack([c["nx"], c["ny"], c["nz"]], axis=1).astype(np.float64)
    u, v = project_normalized(projector, c["xn"], c["yn"])
    proj_uv = np.stack([u, v], axis=1)
    outside = hit & ~_inside(u, v, projector)

    return GroundTruth(
        depth=points[:, 2].reshape(height, width),
        points=points.reshape(height, width, 3),
        normals=normals.reshape(height, width, 3),
        proj_uv=proj_uv.reshape(height, width, 2),
        mask_hit=hit.reshape(height, width),
        mask_shadow=c["occluded"].reshape(height, width),
        mask_outside=outside.reshape(height, width),
    )


def trace(
    rig: Rig,
    scene: Scene,
    *,
    spp: int = 4,
    cam2world: Pose | None = None,
    variant: str | None = None,
    bounces: int = 1,
    projector_lens: ThinLens | None = None,
    camera_lens: ThinLens | None = None,
    aperture_samples: int | None = None,
) -> Trace:
    """Trace one pose of ``rig`` in ``scene`` (see the module docstring for the model).

    Parameters
    ----------
    rig : camera, projector and ``proj2cam``.
    scene : the scene; its world frame is the camera frame unless ``cam2world`` is given.
    spp : camera supersamples per pixel, a perfect square (default 4 = 2 x 2). With a
        ``camera_lens`` each supersample also has its own aperture point, so depth of field
        needs more (64 gives a smooth blur).
    cam2world : pose of the camera in the scene's world frame (default: identity).
    variant : Mitsuba variant (default: automatic, see :mod:`virtus.render.backend`).
    bounces : path vertices per camera sample, 1 to :data:`MAX_BOUNCES`: 1 = direct light
        only (the default), 2 adds light that bounced once (interreflections), ...
    projector_lens : thin lens of the projector (defocus), or None for a pinhole.
    camera_lens : thin lens of the camera (depth of field), or None for a pinhole.
    aperture_samples : projector aperture samples per path vertex, 1 to
        :data:`MAX_APERTURE_SAMPLES` (default :data:`DEFAULT_APERTURE_SAMPLES` with a
        ``projector_lens``); only with a ``projector_lens``.

    Returns
    -------
    :class:`Trace` with ``spp * bounces * aperture_samples`` taps per pixel.
    """
    ps = prepare_pass(
        rig, scene, spp=spp, cam2world=cam2world, variant=variant, bounces=bounces,
        projector_lens=projector_lens, camera_lens=camera_lens,
        aperture_samples=aperture_samples,
    )  # fmt: skip
    spp, bounces, aperture_samples = ps.spp, ps.bounces, ps.aperture_samples
    projector, tracer, variant_name = ps.projector, ps.tracer, ps.variant
    height, width, n_pixels, n_rays = ps.height, ps.width, ps.n_pixels, ps.n_rays
    _, sample_dirs = camera_rays(ps.camera, spp)
    truth = centre_truth(ps)

    # ---- supersamples: taps of projector coordinates and white-projector radiance ----
    taps, step = ps.taps_per_sample, ps.chunk
    parts = [
        tracer.samples(sample_dirs[:, i : i + step], i, **ps.options())
        for i in range(0, n_rays, step)
    ]
    s = _concatenate(parts)
    if projector.has_distortion:
        # distorted in float64, as on the device (the taps' coordinates are float32)
        xn, yn = (s[key].ravel().astype(np.float64) for key in ("xn", "yn"))
        u_p, v_p = (c.astype(np.float32) for c in project_normalized(projector, xn, yn))
        radiance = s["radiance"].ravel()
        lit = (radiance > 0) & _inside(u_p, v_p, projector)
        weight = np.where(lit, radiance, np.float32(0.0))
        u_p = np.where(lit, u_p, np.float32(0.0))
        v_p = np.where(lit, v_p, np.float32(0.0))
    else:
        weight, u_p, v_p = s["weight"], s["u_p"], s["v_p"]
    ambient = np.zeros(n_pixels, dtype=np.float32)
    if "rho_d" in s:
        ambient += np.float32(scene.ambient) * s["rho_d"].reshape(n_pixels, spp).mean(axis=1)
    if "lights" in s:
        ambient += s["lights"].reshape(n_pixels, spp).mean(axis=1, dtype=np.float32)
    weight = weight.reshape(n_pixels, spp * taps)
    if bounces == 1:  # no light from later vertices (summing the taps cost 0.1 s a pose)
        multibounce = np.zeros((height, width), dtype=bool)
    else:
        per_vertex = _by_vertex(weight, bounces, aperture_samples)
        multibounce = (per_vertex[1:].sum(axis=0) > per_vertex[0]).reshape(height, width)
    gt = dataclasses.replace(truth, mask_multibounce=multibounce)
    return Trace(
        height=height,
        width=width,
        spp=spp,
        projector_width=projector.width,
        projector_height=projector.height,
        weight=weight,
        u_p=u_p.reshape(n_pixels, spp * taps),
        v_p=v_p.reshape(n_pixels, spp * taps),
        ambient=ambient.astype(np.float32),
        gt=gt,
        variant=variant_name,
        bounces=bounces,
        aperture_samples=aperture_samples,
    )


def _concatenate(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Join the per-chunk arrays of each key along their first axis."""
    if len(parts) == 1:
        return parts[0]
    return {key: np.concatenate([part[key] for part in parts]) for key in parts[0]}
