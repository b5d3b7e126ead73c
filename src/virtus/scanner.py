"""The virtual scanner: one frozen value that says everything about how captures are made.

A :class:`Scanner` holds the rig, the pattern sequence, the projector model, the camera
sensor and the render settings (one :class:`virtus.render.settings.RenderSettings`).
``scanner.capture(scene, cam2world=..., rng=...)`` renders one pose into a
:class:`virtus.capture.capture.Capture`; ``scanner.check(scene, cam2world)`` refuses, before a
job starts, what the renderer would refuse only later. Every job (capture, scan, calibrate,
demo, turntable) takes a scanner; the command line builds it in one place
(:func:`virtus.cli.options.build_scanner`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from virtus.capture.capture import Capture, check_capture_bytes, rendered_provenance
from virtus.errors import InputError
from virtus.geometry.devices import Rig, default_rig
from virtus.geometry.transforms import Pose
from virtus.patterns import DecodeResult, PatternSequence, default_sequence
from virtus.sensor.camera import Sensor
from virtus.sensor.noise import as_seed
from virtus.sensor.projector import Lookup, ProjectorModel

if TYPE_CHECKING:
    from virtus.render.settings import RenderSettings

__all__ = ["DecodedMaps", "DecodedView", "Scanner"]


def _default_render() -> RenderSettings:
    # virtus.render is imported where it is used, so that reading captures (virtus.pipeline.scan
    # imports this module) never loads the renderer.
    from virtus.render.settings import RenderSettings

    return RenderSettings()


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


@dataclass(frozen=True, eq=False)
class DecodedMaps:
    """Some fields of a pose's decode and its white frame (:meth:`Scanner.decoded_maps`).

    Attributes
    ----------
    maps : the asked :class:`~virtus.patterns.DecodeResult` fields by name, equal to those of
        :attr:`DecodedView.decoded`.
    white : (H, W) the sequence's first white frame (digital numbers), or None without one.
    """

    maps: dict[str, np.ndarray]
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
    render : the render settings (:class:`virtus.render.settings.RenderSettings`: spp,
        Mitsuba variant, bounces, lenses, aperture samples; default ``RenderSettings()``),
        passed to every render of the scanner. Camera pixels x spp are at most
        :data:`virtus.render.settings.MAX_RAYS`.
    """

    rig: Rig = field(default_factory=default_rig)
    #: Never None once constructed: None gives the paper's default sequence for the rig's
    #: projector.
    sequence: PatternSequence = None  # type: ignore[assignment]
    projector: ProjectorModel = field(default_factory=ProjectorModel)
    sensor: Sensor = field(default_factory=Sensor)
    render: RenderSettings = field(default_factory=_default_render)

    def __post_init__(self) -> None:
        from virtus.render.settings import MAX_RAYS, RenderSettings

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
        if not isinstance(self.render, RenderSettings):
            raise InputError(
                "render", "a virtus.render.settings.RenderSettings", type(self.render).__name__
            )
        spp = self.render.spp
        camera = self.rig.camera.intrinsics
        if camera.width * camera.height * spp > MAX_RAYS:
            raise InputError(
                "spp",
                f"camera pixels x spp <= {MAX_RAYS} rays per pose",
                f"{camera.width} x {camera.height} x {spp}",
            )

    @property
    def lookup(self) -> Lookup:
        """The projector's pixel model."""
        return self.projector.pixel

    def with_(self, **changes: Any) -> Scanner:
        """A copy with some fields replaced (checked again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (rig schema, sequence, pixel model, sensor, and the render
        settings' keys at the top level, as :meth:`RenderSettings.to_dict` writes them)."""
        return {
            "rig": self.rig.to_dict(),
            "sequence": self.sequence.to_dict(),
            "projector": self.projector.to_dict(),
            "sensor": self.sensor.to_dict(),
            **self.render.to_dict(),
        }

    def check(self, scene: Any = None, cam2world: Pose | None = None) -> int:
        """Everything the renderer would refuse only after a job started, checked before it
        claims or renders anything; returns the bytes one capture needs.

        The memory (:func:`virtus.capture.capture.capture_bytes`: frames plus the trace's ``spp
        x bounces x aperture samples`` taps per pixel) against
        :data:`virtus.capture.capture.MAX_CAPTURE_BYTES`; spp a perfect square; the Mitsuba
        variant's name; the light-transport counts; and, given a ``scene``, that every object
        lies in front of the camera placed at ``cam2world``.
        """
        from virtus.render.backend import SUPPORTED_VARIANTS
        from virtus.render.rays import sample_offsets
        from virtus.render.tracing import (
            DEFAULT_APERTURE_SAMPLES,
            MAX_APERTURE_SAMPLES,
            MAX_BOUNCES,
        )

        settings = self.render
        sample_offsets(settings.spp)  # a perfect square
        if settings.variant is not None and settings.variant not in SUPPORTED_VARIANTS:
            raise InputError("variant", f"one of {', '.join(SUPPORTED_VARIANTS)}", settings.variant)
        bounces = _count("bounces", settings.bounces, MAX_BOUNCES)
        if settings.projector_lens is None:
            aperture = 1
        elif settings.aperture_samples is None:
            aperture = DEFAULT_APERTURE_SAMPLES
        else:
            aperture = _count("aperture_samples", settings.aperture_samples, MAX_APERTURE_SAMPLES)
        if scene is not None and not isinstance(scene, str):
            from virtus.render.mitsuba_scene import check_in_front

            with np.errstate(all="ignore"):  # a far-off mesh is refused by name, not warned about
                check_in_front(scene, (cam2world or Pose.identity()).inverse())
        camera = self.rig.camera.intrinsics
        return check_capture_bytes(
            len(self.sequence),
            camera.width,
            camera.height,
            np.dtype(self.sensor.dtype).itemsize,
            settings.spp * bounces * aperture,
            what="capture (--spp, --bounces, camera size, sequence length)",
        )

    @property
    def renders_on_gpu(self) -> bool:
        """Whether this scanner's Mitsuba variant runs on a GPU (a CUDA variant): there,
        frames are best kept on the device (:meth:`render_on_device`)."""
        from virtus.render.backend import on_gpu

        return on_gpu(self.render.variant)

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
            self.rig, scene, self.sequence, self.render, projector=self.projector,
            sensor=self.sensor, seed=as_seed(rng), cam2world=cam2world,
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
        decoded, white = self._decode(scene, cam2world, rng, on_device, None)
        return DecodedView(decoded, white)

    def decoded_maps(
        self,
        scene: Any,
        fields: tuple[str, ...],
        *,
        cam2world: Pose | None = None,
        rng: np.random.Generator | int | None = None,
        on_device: bool | None = None,
    ) -> DecodedMaps:
        """:meth:`decoded_view` for only some of the decode's fields, bit for bit: names of
        :data:`virtus.render.jit.decode.HOST_FIELDS` (e.g. ``("proj_uv", "background")``, what
        a calibration observes). On the device only these are formed and copied (with the
        white frame), not the whole decode (:meth:`DeviceDecode.to_host
        <virtus.render.jit.decode.DeviceDecode.to_host>`)."""
        from virtus.render.jit.decode import host_field_names

        names = tuple(host_field_names(fields))
        maps, white = self._decode(scene, cam2world, rng, on_device, names)
        return DecodedMaps(maps, white)

    def _decode(
        self,
        scene: Any,
        cam2world: Pose | None,
        rng: np.random.Generator | int | None,
        on_device: bool | None,
        only: tuple[str, ...] | None,
    ) -> tuple[Any, np.ndarray | None]:
        """The decode (or its fields ``only``) and the white frame of one rendered pose."""
        kinds = [frame.kind for frame in self.sequence.frames]
        white = kinds.index("white") if "white" in kinds else None
        if on_device is None:
            on_device = self.renders_on_gpu
        if not on_device:
            capture = self.capture(scene, cam2world=cam2world, rng=rng, command=[])
            frame = None if white is None else capture.frames[white]
            decoded = capture.decode()
            if only is None:
                return decoded, frame
            return {name: getattr(decoded, name) for name in only}, frame
        from virtus.render.jit.decode import decode_on_device

        frames = self.render_on_device(scene, cam2world=cam2world, rng=rng).frames
        decoded = decode_on_device(
            frames.data,
            self.sequence,
            frames.height,
            frames.width,
            full_scale=self.sensor.full_scale,
        ).to_host(self.sequence, neighbour_check=None, only=only)
        frame = None if white is None else frames.frame(white)
        return decoded, frame

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
            self.render,
            projector=self.projector,
            rng=seed,
            cam2world=pose,
            sensor=self.sensor,
            threads=threads,
            block_pixels=block_pixels,
        )
        return Capture(
            sequence=self.sequence,
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


def _count(name: str, value: object, largest: int) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or not (1 <= value <= largest)
    ):
        raise InputError(name, f"an integer in 1..{largest}", value)
    return int(value)
