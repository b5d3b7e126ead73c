"""The ground-truth signal pass: one noise-free rendering of a pose, for predictions.

:func:`signal_pass` traces the pose once (:func:`virtus.render.tracing.trace`) and
synthesises every frame of the scanner's sequence as noise-free radiance
(:func:`virtus.render.synthesis.synthesize` without a sensor), with the exposure the
renderer would choose. That is everything the uncertainty model needs
(:func:`virtus.uncertainty.predict_uncertainty`): each pixel's noise-free phase-step
signals (``A`` and ``B`` with the projector's response and blur, the pixel's footprint,
ambient light) and its true projector coordinates.

The same pass also gives noisy frames cheaply (:meth:`SignalPass.digitize`): the sensor's
noise is a pure function of ``(seed, frame, pixel)`` (:mod:`virtus.sensor.noise`), so
digitising the noise-free radiance with a seed gives exactly the frames
``scanner.capture(scene, rng=seed)`` renders -- re-rendering a pose for another noise draw
costs only the sensor model (the Monte Carlo check of the model uses this).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.capture.groundtruth import GroundTruth
from virtus.geometry.transforms import Pose
from virtus.scanner import Scanner
from virtus.uncertainty import Prediction, finest_phase_set, predict_uncertainty

__all__ = ["SignalPass", "predict_pass", "signal_pass"]


@dataclass(frozen=True, eq=False)
class SignalPass:
    """The noise-free frames of one pose.

    Attributes
    ----------
    scanner : the scanner that made them.
    radiance : (F, H, W) float32 noise-free radiance of every frame, sequence order.
    exposure : digital numbers per unit radiance (the renderer's choice for the sensor).
    gt : ground truth of the pass (true projector coordinates, points, masks).
    """

    scanner: Scanner
    radiance: np.ndarray
    exposure: float
    gt: GroundTruth

    def signal_dn(self, indices: Any) -> np.ndarray:
        """(len(indices), H, W) float64 noise-free signals (DN above the black level)."""
        return self.radiance[list(indices)].astype(np.float64) * self.exposure

    def phase_frames_dn(self) -> dict[str, np.ndarray]:
        """Direction -> the noise-free signals of its finest phase set (the directions the
        sequence codes with phase frames)."""
        sequence = self.scanner.sequence
        out = {}
        for direction in sequence.directions:
            plan = sequence.plan(direction)
            if plan is not None and plan.sets:
                out[direction] = self.signal_dn(finest_phase_set(sequence, direction)[0])
        return out

    def digitize(self, seed: int) -> np.ndarray:
        """(F, H, W) digital frames with the sensor noise of ``seed``: the frames a capture
        of this pose with ``rng=seed`` holds."""
        sensor = self.scanner.sensor
        frames, height, width = self.radiance.shape
        flat = self.radiance.reshape(frames, -1)
        values = sensor.digitize(
            flat, self.exposure, seed=seed, frames=np.arange(frames),
            pixels=slice(0, height * width),
        )  # fmt: skip
        return values.reshape(frames, height, width)


def signal_pass(scanner: Scanner, scene: Any, cam2world: Pose | None = None) -> SignalPass:
    """Trace one pose of ``scanner`` in ``scene`` and synthesise its noise-free frames
    (module docstring); the exposure is the one :func:`virtus.render.render` uses."""
    from virtus.render.synthesis import synthesize
    from virtus.render.tracing import trace

    settings = scanner.render
    traced = trace(
        scanner.rig, scene, spp=settings.spp, cam2world=cam2world, variant=settings.variant,
        bounces=settings.bounces, projector_lens=settings.projector_lens,
        camera_lens=settings.camera_lens, aperture_samples=settings.aperture_samples,
    )  # fmt: skip
    sensor = scanner.sensor
    if sensor.vignetting != "none":  # as the renderer does: the lens fall-off scales all light
        gain = sensor.vignetting_gain(scanner.rig.camera.intrinsics)
        traced = dataclasses.replace(
            traced, weight=traced.weight * gain[:, None], ambient=traced.ambient * gain
        )
    exposure = sensor.exposure_for(traced.white)
    radiance = synthesize(
        traced, scanner.sequence, scanner.projector,
        projector_intrinsics=scanner.rig.projector.intrinsics,
    )  # fmt: skip
    return SignalPass(scanner, radiance, float(exposure), traced.gt)


def predict_pass(passed: SignalPass, use: str = "uv") -> Prediction:
    """:func:`virtus.uncertainty.predict_uncertainty` of a pass: its noise-free signals, true
    projector coordinates and lit pixels, with the pass's scanner."""
    scanner = passed.scanner
    return predict_uncertainty(
        scanner.rig, scanner.sequence, scanner.sensor, passed.phase_frames_dn(),
        passed.gt.proj_uv, passed.gt.mask, use=use,
    )  # fmt: skip
