"""The virtual scanner: one frozen value that says everything about how captures are made.

A :class:`Scanner` holds the rig, the pattern sequence, the projector pixel model, the
camera sensor and the render settings. ``scanner.capture(scene, cam2world=..., rng=...)``
renders one pose into a :class:`virtus.capture.capture.Capture`. Every job (capture, scan,
calibrate, demo, turntable) takes a scanner; the command line builds it in one place
(:func:`virtus.cli.options.build_scanner`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from virtus.capture.capture import Capture, rendered_provenance
from virtus.checks import positive_int
from virtus.errors import InputError
from virtus.geometry.devices import Rig, default_rig
from virtus.geometry.optics import ThinLens
from virtus.geometry.transforms import Pose
from virtus.patterns import DecodeResult, PatternSequence, default_sequence
from virtus.sensor.camera import Sensor, as_seed
from virtus.sensor.projector import Lookup, ProjectorModel

#: Largest supersample count (a 32 x 32 grid): beyond it a pose needs > 10 GB of samples
#: at 960 x 960.
MAX_SPP = 1024
#: Largest number of camera rays per pose (pixels x spp): ~100 bytes each in the trace.
MAX_RAYS = 1 << 27


@dataclass(frozen=True, eq=False)
class DecodedView:
    """One pose decoded where it was rendered, without ground truth or a capture: what a
    calibration observes (:meth:`Scanner.decoded_view`).

    Attributes
    ----------
    decoded : the decode (as :meth:`virtus.capture.capture.Capture.decode` gives it).
    white : (H, W) the sequence's first white frame (digital numbers), or None without one.
    """

    decoded: DecodeResult
    white: np.ndarray | None


@dataclass(frozen=True)
class Scanner:
    """A camera-projector scanner that renders captures.

    Parameters
    ----------
    rig : camera, projector and ``proj2cam`` (default: the paper's rig).
    sequence : the projected patterns (default: the paper's 52 frames for the projector).
    projector : the projector model (:class:`virtus.sensor.projector.ProjectorModel`: response,
        black level, pixel model and PSF, fall-off; default: ideal sharp DMD pixels).
    sensor : camera model (:class:`virtus.sensor.camera.Sensor`: bit depth, exposure, EMVA 1288).
    spp : supersamples per camera pixel, a perfect square.
    variant : Mitsuba variant (default: ``$VIRTUS_MITSUBA_VARIANT`` or automatic).
    bounces : path vertices per camera sample that see the projector (1 = direct light;
        more = interreflections, one tap per bounce).
    projector_lens, camera_lens : thin lenses (:class:`virtus.geometry.optics.ThinLens`) for
        projector defocus and camera depth of field; None = pinhole (in focus everywhere).
    aperture_samples : projector aperture samples per path vertex (default: the renderer's
        with a projector lens).
    """

    rig: Rig = field(default_factory=default_rig)
    sequence: PatternSequence | None = None
    projector: ProjectorModel = field(default_factory=ProjectorModel)
    sensor: Sensor = field(default_factory=Sensor)
    spp: int = 4
    variant: str | None = None
    bounces: int = 1
    projector_lens: ThinLens | None = None
    camera_lens: ThinLens | None = None
    aperture_samples: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.rig, Rig):
            raise InputError("rig", "a virtus.geometry.devices.Rig", type(self.rig).__name__)
        projector = self.rig.projector.intrinsics
        if self.sequence is None:
            object.__setattr__(
                self, "sequence", default_sequence(projector.width, projector.height)
            )
        elif not isinstance(self.sequence, PatternSequence):
            raise InputError("sequence", "a PatternSequence", type(self.sequence).__name__)
        if (self.sequence.width, self.sequence.height) != (projector.width, projector.height):
            raise InputError(
                "sequence",
                f"patterns for the rig's {projector.width}x{projector.height} px projector",
                f"{self.sequence.width}x{self.sequence.height} px",
            )
        if not isinstance(self.projector, ProjectorModel):
            raise InputError(
                "projector",
                "a virtus.sensor.projector.ProjectorModel",
                type(self.projector).__name__,
            )
        if not isinstance(self.sensor, Sensor):
            raise InputError("sensor", "a virtus.sensor.camera.Sensor", type(self.sensor).__name__)
        spp = positive_int("spp", self.spp)
        if spp > MAX_SPP:
            raise InputError("spp", f"at most {MAX_SPP} supersamples per pixel", spp)
        camera = self.rig.camera.intrinsics
        if camera.width * camera.height * spp > MAX_RAYS:
            raise InputError(
                "spp",
                f"camera pixels x spp <= {MAX_RAYS} rays per pose",
                f"{camera.width} x {camera.height} x {spp}",
            )
        object.__setattr__(self, "spp", spp)
        for name in ("projector_lens", "camera_lens"):
            lens = getattr(self, name)
            if lens is not None and not isinstance(lens, ThinLens):
                raise InputError(
                    name, "a virtus.geometry.optics.ThinLens or None", type(lens).__name__
                )

    @property
    def lookup(self) -> Lookup:
        """The projector's pixel model."""
        return self.projector.pixel

    def with_(self, **changes: Any) -> Scanner:
        """A copy with some fields replaced (checked again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (rig schema, sequence, pixel model, sensor, settings)."""
        return {
            "rig": self.rig.to_dict(),
            "sequence": self.sequence.to_dict(),  # type: ignore[union-attr]
            "projector": self.projector.to_dict(),
            "sensor": self.sensor.to_dict(),
            "spp": self.spp,
            "variant": self.variant,
            "bounces": self.bounces,
            "projector_lens": None
            if self.projector_lens is None
            else self.projector_lens.to_dict(),
            "camera_lens": None if self.camera_lens is None else self.camera_lens.to_dict(),
            "aperture_samples": self.aperture_samples,
        }

    def _trace_options(self) -> dict[str, Any]:
        """The tracing settings every render of this scanner passes on (spp, variant,
        bounces, lenses, aperture samples)."""
        return {
            "spp": self.spp,
            "variant": self.variant,
            "bounces": self.bounces,
            "projector_lens": self.projector_lens,
            "camera_lens": self.camera_lens,
            "aperture_samples": self.aperture_samples,
        }

    @property
    def renders_on_gpu(self) -> bool:
        """Whether this scanner's Mitsuba variant runs on a GPU (a CUDA variant): there,
        frames are best kept on the device (:meth:`render_on_device`)."""
        from virtus.render.backend import on_gpu

        return on_gpu(self.variant)

    def render_on_device(
        self,
        scene: Any,
        *,
        cam2world: Pose | None = None,
        rng: np.random.Generator | int | None = None,
    ) -> Any:
        """Render one pose and keep it on the device that traced it: a
        :class:`virtus.render.renderer.DeviceRendering` (frames, taps, ground truth on
        demand), with :meth:`capture`'s settings and seed: on a GPU the frames are
        :meth:`capture`'s, on a CPU variant they agree within 1 DN (``render``'s
        ``synthesis``)."""
        from virtus.render.renderer import render_device

        return render_device(
            self.rig, scene, self.sequence, projector=self.projector, sensor=self.sensor,
            seed=as_seed(rng), cam2world=cam2world, **self._trace_options(),
        )  # fmt: skip

    def decoded_view(
        self,
        scene: Any,
        *,
        cam2world: Pose | None = None,
        rng: np.random.Generator | int | None = None,
        on_device: bool | None = None,
    ) -> DecodedView:
        """Render one pose and decode it, as ``capture(...).decode()`` does, without the
        ground truth.

        With ``on_device`` (default: on CUDA variants) the frames never leave the device
        that rendered them: they are decoded there (:mod:`virtus.render.jit.decode`) and
        only the decode and the white frame are copied. Otherwise this is exactly
        ``capture(...).decode()``.
        """
        kinds = [frame.kind for frame in self.sequence.frames]  # type: ignore[union-attr]
        white = kinds.index("white") if "white" in kinds else None
        if on_device is None:
            on_device = self.renders_on_gpu
        if not on_device:
            capture = self.capture(scene, cam2world=cam2world, rng=rng, command=[])
            frame = None if white is None else capture.frames[white]
            return DecodedView(capture.decode(), frame)
        from virtus.render.jit.decode import decode_on_device

        frames = self.render_on_device(scene, cam2world=cam2world, rng=rng).frames
        decoded = decode_on_device(
            frames.data,
            self.sequence,
            frames.height,
            frames.width,  # type: ignore[arg-type]
            full_scale=self.sensor.full_scale,
        ).to_host(self.sequence, neighbour_check=None)  # type: ignore[arg-type]
        frame = None if white is None else frames.frame(white)
        return DecodedView(decoded, frame)

    def capture(
        self,
        scene: Any,
        *,
        cam2world: Pose | None = None,
        rng: np.random.Generator | int | None = None,
        command: list[str] | None = None,
        threads: int | None = None,
        block_pixels: int | None = None,
    ) -> Capture:
        """Render one pose of the scanner in ``scene``.

        Parameters
        ----------
        scene : a :class:`virtus.scene.model.Scene` (world frame = camera frame unless
            ``cam2world`` places the camera).
        cam2world : camera pose in the scene's world frame (default identity).
        rng : seed of the sensor's counter-based noise streams (int, Generator or None = 0).
        command : command line recorded in the provenance (default ``sys.argv``).
        threads, block_pixels : host synthesis parallelism (the frames do not depend on it).

        Returns
        -------
        A :class:`Capture` with frames, ground truth, scene and settings.
        """
        from virtus.render import render

        seed = as_seed(rng)
        pose = Pose.identity() if cam2world is None else cam2world
        rendering = render(
            self.rig,
            scene,
            self.sequence,
            projector=self.projector,
            rng=seed,
            cam2world=pose,
            sensor=self.sensor,
            threads=threads,
            block_pixels=block_pixels,
            **self._trace_options(),
        )
        return Capture(
            sequence=self.sequence,  # type: ignore[arg-type]
            rig=self.rig,
            frame_data=rendering.frames,
            cam2world=pose,
            bit_depth=self.sensor.bit_depth,
            sensor=self.sensor,
            seed=seed,
            scene=scene,
            gt_data=rendering.gt,
            render=rendering.metadata(),
            provenance=rendered_provenance(command),
        )
