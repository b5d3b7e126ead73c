"""The differentiable phase -> depth layer (virtus.learn.triangulate) against
virtus.reconstruct's triangulation on random rigs with distortion, and its gradient against
finite differences."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from tests.tolerances import LEARN_LAYER_M  # noqa: E402
from virtus.errors import InputError  # noqa: E402
from virtus.geometry.devices import Camera, Projector, Rig  # noqa: E402
from virtus.geometry.optics import Intrinsics  # noqa: E402
from virtus.geometry.transforms import Pose  # noqa: E402
from virtus.learn.triangulate import DepthLayer, phase_to_coordinate  # noqa: E402
from virtus.reconstruct import points_from_decoded  # noqa: E402


def random_rig(rng: np.random.Generator, distortion: bool = True) -> Rig:
    """A small random rig: 20 x 16 camera, 120 x 90 projector, both distorted, toed in."""

    def dist() -> tuple[float, ...]:
        if not distortion:
            return ()
        return tuple(rng.uniform([-0.2, -0.1, -2e-3, -2e-3, -0.05], [0.2, 0.1, 2e-3, 2e-3, 0.05]))

    cam = Intrinsics(
        *rng.uniform(40, 60, 2), *rng.uniform([8.5, 6.5], [10.5, 8.5]), 20, 16, dist=dist()
    )
    proj = Intrinsics(
        *rng.uniform(200, 260, 2), *rng.uniform([55, 40], [65, 50]), 120, 90, dist=dist()
    )
    t = np.array([rng.uniform(-0.2, -0.08), rng.uniform(-0.1, 0.1), rng.uniform(-0.02, 0.02)])
    pose = Pose.from_euler("xyz", rng.uniform(-4, 4, 3) + [0, 6, 0], t=t)
    return Rig(Camera(cam), Projector(proj), pose)


def scene_coordinates(rig: Rig, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random depths 0.4-2 m per camera pixel and the exact projector ``(u_p, v_p)``."""
    intr = rig.camera.intrinsics
    rays = intr.unproject(intr.pixel_grid().reshape(-1, 2))
    depth = rng.uniform(0.4, 2.0, rays.shape[0])
    points = rays * (depth / rays[:, 2])[:, None]
    uv = rig.projector.intrinsics.project(rig.cam2proj.apply(points))
    shape = (intr.height, intr.width)
    return depth.reshape(shape), uv.reshape(shape + (2,))


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("direction", ["v", "h"])
def test_layer_matches_reconstruct_with_distortion(seed: int, direction: str) -> None:
    rng = np.random.default_rng(seed)
    rig = random_rig(rng)
    depth, uv = scene_coordinates(rig, rng)
    axis = 0 if direction == "v" else 1
    use = "u" if direction == "v" else "v"
    reference = points_from_decoded(rig, uv, use=use)
    layer = DepthLayer(rig, direction)
    ours = layer(torch.from_numpy(uv[..., axis])).numpy()
    ok = np.isfinite(reference).all(-1)
    assert ok.mean() > 0.95  # the test sees the distorted case, not NaN everywhere
    np.testing.assert_array_equal(np.isfinite(ours).all(-1), ok)
    assert np.max(np.abs(ours[ok] - reference[ok])) < LEARN_LAYER_M
    # and both are the scene's depth: the comparison is not between two wrong answers
    assert np.max(np.abs(ours[ok][:, 2] - depth[ok])) < LEARN_LAYER_M


def test_layer_without_distortion_and_in_float32() -> None:
    rng = np.random.default_rng(7)
    rig = random_rig(rng, distortion=False)
    depth, uv = scene_coordinates(rig, rng)
    layer = DepthLayer(rig)
    ours = layer.depth(torch.from_numpy(uv[..., 0]))
    assert np.max(np.abs(ours.numpy() - depth)) < LEARN_LAYER_M
    # float32 in, float32 out: float32 u_p (~8e-6 px ulp at 100 px) moves depth by < 1e-5 m
    single = layer.depth(torch.from_numpy(uv[..., 0]).float())
    assert single.dtype == torch.float32
    assert np.max(np.abs(single.numpy() - depth)) < 1e-4


def test_invalid_input_is_nan_with_zero_gradient() -> None:
    rng = np.random.default_rng(3)
    rig = random_rig(rng)
    _, uv = scene_coordinates(rig, rng)
    coord = torch.from_numpy(uv[..., 0].copy())
    coord[0, 0] = float("nan")
    coord[0, 1] = -1e9  # far outside: the plane is behind the camera
    coord.requires_grad_(True)
    depth = DepthLayer(rig).depth(coord)
    assert torch.isnan(depth[0, 0]) and torch.isnan(depth[0, 1])
    torch.nan_to_num(depth, nan=0.0).sum().backward()
    assert torch.isfinite(coord.grad).all()
    assert coord.grad[0, 0] == 0 and coord.grad[0, 1] == 0
    assert (coord.grad[1:] != 0).all()


@pytest.mark.parametrize("distortion", [False, True])
def test_gradient_matches_finite_differences(distortion: bool) -> None:
    rng = np.random.default_rng(11)
    rig = random_rig(rng, distortion)
    _, uv = scene_coordinates(rig, rng)
    layer = DepthLayer(rig)
    full = torch.from_numpy(uv[..., 0].copy())
    window = (slice(4, 8), slice(6, 11))  # 20 pixels, corners of the image excluded

    def depth(sub):
        coord = full.clone()
        coord[window] = sub
        return layer.depth(coord)[window]

    sub = full[window].clone().requires_grad_(True)
    # eps 1e-4 px: central differences of a smooth map are exact to ~eps^2 * curvature,
    # and the Newton residual (1e-9 px) is 1e-5 of the step
    assert torch.autograd.gradcheck(depth, (sub,), eps=1e-4, atol=1e-9, rtol=1e-5)


def test_phase_to_coordinate_and_bad_input() -> None:
    phase = torch.tensor([0.0, np.pi, 2 * np.pi], dtype=torch.float64)
    assert phase_to_coordinate(phase, 18.0).tolist() == pytest.approx([0.0, 9.0, 18.0])
    with pytest.raises(InputError, match="period_px"):
        phase_to_coordinate(phase, 0.0)
    layer = DepthLayer(random_rig(np.random.default_rng(0)))
    with pytest.raises(InputError, match="coord"):
        layer(torch.zeros(3, 4, dtype=torch.float64))
    with pytest.raises(InputError, match="direction"):
        DepthLayer(random_rig(np.random.default_rng(0)), "x")
