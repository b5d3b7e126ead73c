"""Light transport beyond direct light through pinholes, against theory and Mitsuba:
interreflections (multi-bounce paths with next-event estimation toward the projector),
thin-lens projector defocus and camera depth of field, scene lights."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.optimize import least_squares

from tests import tolerances as tol
from tests.render.test_renderer import interior
from tests.support import LAMBERT, cropped_rig, small_rig, sphere_and_plane
from virtus.capture.groundtruth import ARRAY_NAMES, GroundTruth
from virtus.errors import InputError
from virtus.geometry.devices import Camera, Rig, default_rig
from virtus.geometry.optics import Intrinsics, ThinLens
from virtus.geometry.transforms import Pose
from virtus.patterns import default_sequence
from virtus.render import RenderSettings, render, synthesize, trace, tracing
from virtus.render.rays import sample_offsets
from virtus.render.reference import ReferenceRenderer
from virtus.scene.model import (
    AreaLight,
    EnvironmentLight,
    Material,
    PlaneObject,
    Scene,
    SphereObject,
    TexturedPlaneObject,
)
from virtus.sensor.camera import Sensor

#: Bright Lambertian walls: strong interreflections.
WALL = Material(albedo=0.9, specular=0.0)
#: Corner line of the concave corner (camera frame, metres), and the walls' width.
CORNER = np.array([0.0, 0.0, 1.15])
WALL_WIDTH_M = 0.4


def corner_walls(material: Material = WALL) -> list[PlaneObject]:
    """Two walls meeting at 90 deg along a vertical line through :data:`CORNER`, opening
    toward the camera (each 45 deg from the camera axis)."""
    walls = []
    for side in (-1.0, 1.0):
        along = np.array([side, 0.0, -1.0]) / np.sqrt(2.0)  # from the corner outward
        R = np.stack([along, [0.0, 1.0, 0.0], np.cross(along, [0.0, 1.0, 0.0])], axis=1)
        centre = CORNER + WALL_WIDTH_M / 2 * along
        walls.append(PlaneObject((WALL_WIDTH_M, 0.6), Pose(R, centre), material))
    return walls


class StepPattern:
    """A one-frame vertical-fringe sequence: projector columns >= ``edge`` white, the rest
    black (with nearest lookup the step lies at ``u_p = edge - 0.5``)."""

    def __init__(self, length: int, edge: int) -> None:
        self.frames = [SimpleNamespace(direction="v")]
        self.length, self.edge = length, edge

    def profile(self, index: int) -> np.ndarray:
        return (np.arange(self.length) >= self.edge).astype(np.float32)


def disk_esf(x: np.ndarray, diameter: float) -> np.ndarray:
    """Edge-spread function of a uniform disk of ``diameter``: the share of the disk centred
    at signed distance ``x`` from a straight edge that lies beyond it."""
    t = np.clip(2.0 * x / diameter, -1.0, 1.0)
    return 0.5 + (t * np.sqrt(1.0 - t * t) + np.arcsin(t)) / np.pi


def fit_blur(x: np.ndarray, y: np.ndarray, guess: float, box: np.ndarray) -> float:
    """Blur diameter of samples ``y`` of a disk ESF at positions ``x`` (offset fitted too),
    each averaged over the sub-sample offsets ``box`` (a pixel's footprint)."""

    def residual(q: np.ndarray) -> np.ndarray:
        return np.mean([disk_esf(x + o - q[1], q[0]) for o in box], axis=0) - y

    return float(least_squares(residual, [0.7 * guess, 0.0]).x[0])


# --- interreflections ---------------------------------------------------------------------


@pytest.fixture(scope="module")
def corner():
    """Corner walls seen by a 80 x 80 px camera, and two frames (white, a vertical phase)."""
    sequence = default_sequence()
    indices = [
        sequence.index_of("white"),
        sequence.index_of("phase", "v", step=1, steps=18, period=18.0),
    ]
    return small_rig(1 / 12), Scene(corner_walls()), sequence, indices


def column_bands(image: np.ndarray, bands: int = 4) -> np.ndarray:
    """Means of ``bands`` vertical bands of the image (the walls vary along columns)."""
    return np.array([band.mean() for band in np.array_split(image, bands, axis=1)])


@pytest.mark.parametrize("bounces", [2, 3])
def test_corner_interreflections_match_mitsubas_path_tracer(corner, bounces: int) -> None:
    rig, scene, sequence, indices = corner
    spp = 64  # the same 8 x 8 positions as Mitsuba's stratified sampler without jitter
    traced = trace(rig, scene, spp=spp, bounces=bounces)
    ours = synthesize(traced, sequence, "bilinear")[indices]
    mitsuba = ReferenceRenderer(
        rig, scene, spp=spp, lookup="bilinear", jitter=False, bounces=bounces
    )
    theirs = mitsuba.render_frames(sequence, indices, seed=1)
    for k in range(len(indices)):
        difference = column_bands(ours[k]) / column_bands(theirs[k]) - 1.0
        assert np.abs(difference).max() < tol.INTERREFLECTION_MITSUBA_REL, (k, difference)
    # The corner (the middle bands) gets much more light than direct light alone gives.
    direct = trace(rig, scene, spp=spp, bounces=1)
    gain = column_bands(theirs[0]) / column_bands(direct.white) - 1.0
    assert gain[1:3].min() > tol.INTERREFLECTION_GAIN_MIN, gain
    # The vertex-0 taps of a multi-bounce trace are the direct light's, bit for bit.
    first = traced.weight.reshape(-1, spp, bounces)[..., 0]
    np.testing.assert_array_equal(first, direct.weight)


def test_multibounce_mask_marks_shadows_lit_by_the_other_wall() -> None:
    # A sphere between the projector and the walls casts a shadow that only the other wall
    # lights: there the indirect light exceeds the (zero) direct light.
    rig = small_rig(1 / 12)
    scene = Scene([*corner_walls(), SphereObject(0.03, (-0.06, 0.0, 0.8), LAMBERT)])
    traced = trace(rig, scene, spp=16, bounces=2)
    gt = traced.gt
    walls = gt.mask_hit & (gt.depth > 0.84)
    # Away from the shadow's edge, where a pixel's supersamples are partly lit.
    shadow = walls & interior(gt.mask_shadow)
    lit = walls & interior(gt.mask)
    assert shadow.sum() > 20
    assert gt.mask_multibounce[shadow].mean() > 0.95
    assert not gt.mask_multibounce[lit].any()
    assert traced.bounce_radiance.shape == (2, traced.height * traced.width)
    assert not trace(rig, scene, spp=4).gt.mask_multibounce.any()


def test_trace_does_not_depend_on_chunking(monkeypatch) -> None:
    # Counter-based random numbers: the same paths whatever the chunk size.
    rig, scene = small_rig(1 / 12), Scene(corner_walls())
    options = {
        "spp": 4,
        "bounces": 3,
        "projector_lens": ThinLens(0.01, 1.0),
        "aperture_samples": 3,
        "camera_lens": ThinLens(0.01, 1.0),
    }
    whole = trace(rig, scene, **options)
    monkeypatch.setattr(tracing, "_RAYS_PER_CHUNK", 4 * 9 * 1001)
    chunked = trace(rig, scene, **options)
    for name in ("weight", "u_p", "v_p", "ambient"):
        np.testing.assert_array_equal(getattr(chunked, name), getattr(whole, name), name)
    assert whole.weight.shape == (80 * 80, 4 * 3 * 3)


# --- projector defocus and camera depth of field --------------------------------------------


@pytest.mark.parametrize("depth_m", [0.8, 1.3])
def test_projector_defocus_blurs_a_step_by_the_circle_of_confusion(depth_m: float) -> None:
    # A plane facing the projector at depth d, in front of / behind its focus plane at 1 m:
    # a projected step edge is spread by a uniform disk of the thin-lens diameter.
    rig = cropped_rig(64)
    projector = rig.projector.intrinsics
    lens = ThinLens(aperture_m=0.02, focus_distance_m=1.0)
    pose = Pose(rig.proj2cam.R, rig.proj2cam.t + depth_m * rig.proj2cam.R[:, 2])
    scene = Scene([PlaneObject((2.0, 2.0), pose, LAMBERT)])
    traced = trace(rig, scene, spp=16, projector_lens=lens, aperture_samples=16)
    u_p = traced.gt.proj_uv[..., 0]
    edge = int(np.round(u_p[32, 32]))
    frame = synthesize(traced, StepPattern(projector.width, edge), "nearest")[0]
    expected = float(lens.blur_diameter_px(depth_m, projector.fx))
    assert expected > 8.0
    # Camera pixels span ~0.8 projector pixels: negligible against the blur (a 0.2 % bias).
    x = (u_p - (edge - 0.5)).ravel()
    fitted = fit_blur(x, (frame / traced.white).ravel(), expected, np.zeros(1))
    assert abs(fitted / expected - 1.0) < tol.DEFOCUS_BLUR_REL, (fitted, expected)


@pytest.mark.parametrize("depth_m", [0.8, 1.3])
def test_camera_depth_of_field_blurs_a_texture_edge_by_the_circle_of_confusion(
    depth_m: float,
) -> None:
    # A board with a vertical albedo step through the optical axis, lit by uniform ambient
    # light, at depth d in front of / behind the camera's focus plane at 1 m.
    rig = cropped_rig(64)
    camera = rig.camera.intrinsics
    lens = ThinLens(aperture_m=0.02, focus_distance_m=1.0)
    texture = np.repeat(np.array([[0.2, 1.0]]), 1000, axis=1)  # 0.25 mm texels
    matte = Material(albedo=1.0, specular=0.0)
    board = TexturedPlaneObject((0.5, 0.5), texture, Pose(np.eye(3), (0, 0, depth_m)), matte)
    spp = 64
    traced = trace(rig, Scene([board], ambient=1.0), spp=spp, camera_lens=lens)
    image = traced.ambient.reshape(camera.height, camera.width)
    x = np.broadcast_to(np.arange(camera.width) - camera.cx, image.shape).ravel()
    expected = float(lens.blur_diameter_px(depth_m, camera.fx))
    assert expected > 8.0
    box = np.unique(sample_offsets(spp)[:, 0])  # the pixel's own footprint
    fitted = fit_blur(x, ((image - 0.2) / 0.8).ravel(), expected, box)
    assert abs(fitted / expected - 1.0) < tol.DEFOCUS_BLUR_REL, (fitted, expected)
    # Ground truth keeps the pinhole geometry: the board's depth everywhere.
    np.testing.assert_allclose(traced.gt.depth, depth_m, rtol=1e-6)


def test_lenses_focused_on_the_surface_change_nothing_visible() -> None:
    # In focus, every aperture sample lands on the same projector pixel: same frames as the
    # pinhole up to float rounding.
    rig, scene = small_rig(1 / 12), sphere_and_plane(LAMBERT)
    proj2cam = rig.proj2cam
    pose = Pose(proj2cam.R, proj2cam.t + 1.1 * proj2cam.R[:, 2])
    scene = Scene([PlaneObject((3.0, 3.0), pose, LAMBERT)])
    pinhole = trace(rig, scene, spp=4)
    lens = trace(rig, scene, spp=4, projector_lens=ThinLens(0.02, 1.1), aperture_samples=4)
    lit = pinhole.weight > 0
    np.testing.assert_allclose(
        lens.u_p.reshape(-1, 4, 4)[..., 0][lit], pinhole.u_p[lit], atol=tol.FOCUSED_LENS_PX
    )
    interior = pinhole.gt.mask.ravel()
    np.testing.assert_allclose(lens.direct[interior], pinhole.direct[interior], rtol=1e-3)


# --- plumbing and errors ----------------------------------------------------------------------


def test_render_passes_the_light_transport_options() -> None:
    rig, scene = small_rig(1 / 12), Scene(corner_walls())
    sequence = default_sequence()
    lens = ThinLens(0.01, 1.0)
    settings = RenderSettings(spp=4, bounces=2, projector_lens=lens, aperture_samples=2)
    rendering = render(rig, scene, sequence, settings, sensor=Sensor(exposure=100.0))
    traced = trace(rig, scene, spp=4, bounces=2, projector_lens=lens, aperture_samples=2)
    white = sequence.index_of("white")
    expected = np.clip(np.rint(traced.white * np.float32(100.0)), 0, 255)
    assert np.abs(rendering.frames[white].astype(float) - expected).max() <= 1
    meta = rendering.metadata()
    assert meta["bounces"] == 2 and meta["aperture_samples"] == 2
    assert meta["projector_lens"] == lens.to_dict() and meta["camera_lens"] is None


def test_ground_truth_without_the_multibounce_mask_still_loads() -> None:
    gt = trace(small_rig(1 / 12), Scene(corner_walls()), spp=1).gt
    arrays = gt.arrays()
    assert "mask_multibounce" in ARRAY_NAMES and "mask_multibounce" in arrays
    del arrays["mask_multibounce"]  # a capture written before the mask existed
    loaded = GroundTruth.from_arrays(arrays)
    assert loaded.mask_multibounce.shape == gt.shape and not loaded.mask_multibounce.any()


@pytest.mark.parametrize(
    ("options", "name"),
    [
        ({"bounces": 0}, "bounces"),
        ({"bounces": tracing.MAX_BOUNCES + 1}, "bounces"),
        ({"bounces": 1.5}, "bounces"),
        ({"projector_lens": 0.02}, "projector_lens"),
        ({"camera_lens": {"aperture_m": 0.02}}, "camera_lens"),
        ({"aperture_samples": 4}, "aperture_samples"),  # without a projector lens
        ({"projector_lens": ThinLens(0.01, 1.0), "aperture_samples": 0}, "aperture_samples"),
        (
            {
                "projector_lens": ThinLens(0.01, 1.0),
                "aperture_samples": tracing.MAX_APERTURE_SAMPLES + 1,
            },
            "aperture_samples",
        ),
    ],
)
def test_bad_light_transport_options_are_errors(options: dict, name: str) -> None:
    with pytest.raises(InputError, match=name):
        trace(small_rig(1 / 12), Scene(corner_walls()), **options)


@pytest.mark.parametrize(
    ("arguments", "name"),
    [
        ({"aperture_m": -0.01, "focus_distance_m": 1.0}, "aperture_m"),
        ({"aperture_m": 0.01, "focus_distance_m": 0.0}, "focus_distance_m"),
        ({"aperture_m": 0.01, "focus_distance_m": 1.0, "focal_length_m": 2.0}, "focal_length_m"),
        ({"aperture_m": float("nan"), "focus_distance_m": 1.0}, "aperture_m"),
    ],
)
def test_nonsense_lenses_are_errors(arguments: dict, name: str) -> None:
    with pytest.raises(InputError, match=name):
        ThinLens(**arguments)


# --- scene lights -------------------------------------------------------------------------


def lit_room() -> Scene:
    """The sphere before a wall, a 3.0-radiance panel above it facing down, and a 0.2
    environment."""
    panel = AreaLight((0.5, 0.5), Pose.from_euler("xyz", [-90, 0, 0], t=(0.0, -0.45, 1.0)), 3.0)
    return Scene(
        [SphereObject(0.1, (0.0, 0.0, 1.0), LAMBERT)],
        background=PlaneObject((2.0, 2.0), Pose(np.eye(3), (0.0, 0.0, 1.3)), LAMBERT),
        lights=[panel, EnvironmentLight(0.2)],
    )


@pytest.mark.parametrize("bounces", [1, 2])
def test_scene_lights_match_mitsuba(bounces: int) -> None:
    # Pattern-independent light in Trace.ambient vs Mitsuba (direct / path integrator) with
    # the projector black: shadows of the sphere, the panel's fall-off, the environment seen
    # where the camera rays miss, interreflections.
    rig, scene = small_rig(1 / 12), lit_room()
    traced = trace(rig, scene, spp=64, bounces=bounces)
    projector = rig.projector.intrinsics
    black = np.zeros((projector.height, projector.width), dtype=np.float32)
    theirs = ReferenceRenderer(rig, scene, spp=256, bounces=bounces).render_image(black)
    ours = traced.ambient.reshape(theirs.shape)
    for axis in (0, 1):
        bands = np.array_split(np.arange(ours.shape[axis]), 4)
        difference = [
            ours.take(band, axis).mean() / theirs.take(band, axis).mean() - 1 for band in bands
        ]
        assert np.abs(difference).max() < tol.LIGHTS_MITSUBA_REL, (axis, difference)
    # The projector's taps are unchanged by the lights.
    plain = Scene(scene.objects, background=scene.background)
    np.testing.assert_array_equal(trace(rig, plain, spp=4).weight, trace(rig, scene, spp=4).weight)


def test_environment_on_an_open_plane_is_the_uniform_ambient_level() -> None:
    # An unoccluded Lambertian plane under a constant environment L: radiance rho L, as
    # Scene.ambient = L gives.
    plane = PlaneObject((3.0, 3.0), Pose(np.eye(3), (0.0, 0.0, 1.0)), LAMBERT)
    traced = trace(small_rig(1 / 12), Scene([plane], lights=[EnvironmentLight(0.5)]), spp=64)
    assert abs(traced.ambient.mean() / (0.8 * 0.5) - 1) < tol.ENVIRONMENT_MEAN_REL


def test_scene_lights_round_trip_and_validate() -> None:
    scene = lit_room()
    again = Scene.from_dict(scene.to_dict())
    assert again.lights == scene.lights
    with pytest.raises(InputError, match="lights"):
        Scene(scene.objects, lights=[EnvironmentLight(0.1), EnvironmentLight(0.2)])
    with pytest.raises(InputError, match="radiance"):
        EnvironmentLight(radiance=-1.0)
    with pytest.raises(InputError, match="size_m"):
        AreaLight((0.0, 1.0), Pose.identity(), 1.0)


def test_third_path_vertex_alone_matches_mitsuba(corner) -> None:
    # The light that bounced exactly twice before the camera's surface point (vertex 2,
    # Trace.bounce_radiance[2]) against Mitsuba's path tracer: its 3-bounce frame minus its
    # 2-bounce frame with the same seed (the same paths up to the last vertex, so what is
    # left is that vertex's light). The total at 3 bounces hides a wrong third vertex (it
    # is ~5 % of the light); alone it shows: a throughput reset at each bounce drops the
    # first bounce's albedo, 1 / 0.9 - 1 = +11 %.
    rig, scene, sequence, indices = corner
    white = [sequence.index_of("white")]
    spp = 64
    traced = trace(rig, scene, spp=spp, bounces=3)
    ours = traced.bounce_radiance[2].reshape(rig.camera.intrinsics.height, -1)
    frames = {
        bounces: ReferenceRenderer(
            rig, scene, spp=spp, lookup="bilinear", jitter=False, bounces=bounces
        ).render_frames(sequence, white, seed=1)[0]
        for bounces in (2, 3)
    }
    theirs = frames[3] - frames[2]
    assert theirs.mean() > 0.02 * frames[3].mean()  # the vertex carries light
    # The middle bands (the corner), where the third vertex gathers most of its light.
    difference = column_bands(ours)[1:3] / column_bands(theirs)[1:3] - 1.0
    assert np.abs(difference).max() < tol.INTERREFLECTION_THIRD_VERTEX_REL, difference


@pytest.mark.parametrize("cx", [-700.0, 31.5, 760.0], ids=["18deg-right", "on-axis", "18deg-left"])
def test_camera_lens_focused_on_a_plane_is_sharp_across_the_field(cx: float) -> None:
    # The thin lens focuses on the plane z = d_f, not on a sphere of radius d_f: every ray
    # of a supersample passes through the point where its pinhole ray meets that plane, so
    # a board lying in it is imaged exactly as by a pinhole, on axis and 18 deg off it. A
    # sphere of focus would put off-axis points of the board (1 / cos 18 deg - 1 = 5 %
    # beyond it) out of focus: a blur of ~0.5 mm against the 2 mm stripes.
    k = default_rig().camera.intrinsics
    camera = Intrinsics(k.fx, k.fy, cx, 31.5, 64, 64)
    rig = Rig(Camera(camera), default_rig().projector, default_rig().proj2cam)
    depth = 1.0
    centre_x = (31.5 - cx) / k.fx * depth  # where the image's centre column looks
    x = (np.arange(400) + 0.5) * 0.25e-3  # 0.25 mm texels over 0.1 m
    texture = np.repeat((0.5 + 0.4 * np.sin(2 * np.pi * x / 2e-3))[None, :], 400, axis=0)
    matte = Material(albedo=1.0, specular=0.0)
    pose = Pose(np.eye(3), (centre_x, 0.0, depth))
    scene = Scene([TexturedPlaneObject((0.1, 0.1), texture, pose, matte)], ambient=1.0)
    lens = ThinLens(aperture_m=0.02, focus_distance_m=depth)
    pinhole = trace(rig, scene, spp=16).ambient
    focused = trace(rig, scene, spp=16, camera_lens=lens).ambient
    assert pinhole.std() > 0.1  # the stripes are resolved (4.6 px per period)
    np.testing.assert_allclose(focused, pinhole, rtol=0, atol=tol.FOCUSED_LENS_ALBEDO)
