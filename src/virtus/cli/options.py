"""Options shared by several sub-commands; the scanner options as one bundle
(:func:`scanner_options`), and the one place that builds a Scanner from them."""

from __future__ import annotations

import inspect
from collections.abc import Callable, Collection
from dataclasses import dataclass, fields
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import typer

from virtus.sensor import Lookup

if TYPE_CHECKING:
    from virtus.geometry import Rig
    from virtus.scanner import Scanner

LOOKUP_HELP = (
    "Projector pixel model: nearest (sharp DMD pixels), bilinear (blurred by ~1 px) or psf; "
    "overrides the --projector model's."
)

#: ``--rig``: the true rig of the virtual scanner.
RigOption = Annotated[
    Path | None,
    typer.Option(
        help="Rig JSON (or a calibration file in the rig schema); default: the paper's rig."
    ),
]
#: ``--sequence``: the projected patterns.
SequenceOption = Annotated[
    Path | None,
    typer.Option(
        help="Pattern sequence file (YAML/JSON, see `virtus patterns`); default: the paper's "
        "52 frames."
    ),
]


class LengthUnit(StrEnum):
    """Length unit of a calibration file's translations."""

    mm = "mm"
    m = "m"


#: ``--units``: for calibration files that state no unit (never guessed).
UnitsOption = Annotated[
    LengthUnit | None,
    typer.Option(help="Length unit of a calibration file that states none: mm or m."),
]
#: ``--camera-size W,H``: the camera's image size (pixels), for a calibration that lacks it;
#: parsed by :func:`parse_size`. Options whose one value holds commas are declared as lists
#: so that a repetition is seen and refused (:func:`once`), never last-wins.
CameraSizeOption = Annotated[
    list[str] | None,
    typer.Option(
        "--camera-size",
        metavar="W,H",
        help="Camera image size 'W,H' in pixels, for a calibration file that states none "
        "(checked against the images and the file).",
    ),
]
#: ``--pixel-size-um``: the camera's pixel pitch, recorded for a digital twin.
PixelSizeOption = Annotated[
    float | None,
    typer.Option(
        "--pixel-size-um",
        help="Camera pixel pitch in micrometres (recorded in capture.json for a digital twin).",
    ),
]
#: ``--overwrite``: the run may replace another run's directory (its files are removed first).
OverwriteOption = Annotated[
    bool, typer.Option("--overwrite", help="Remove an earlier run's files in OUT first.")
]
#: ``--resume``: continue an interrupted run in its directory (commands that keep finished
#: parts say which in their own help).
ResumeOption = Annotated[
    bool, typer.Option("--resume", help="Continue an interrupted run in OUT (same settings).")
]
LookupOption = Annotated[Lookup | None, typer.Option(help=LOOKUP_HELP)]
ProjectorOption = Annotated[
    str,
    typer.Option(
        help="Projector model: a preset (ideal, paper, lightcrafter) or a YAML/JSON file "
        "(gamma, contrast_ratio, pixel, fill_factor, psf_sigma_px, falloff, ...)."
    ),
]
SppOption = Annotated[int, typer.Option(help="Supersamples per pixel (a square: 1, 4, 9...).")]
BitDepthOption = Annotated[
    int | None,
    typer.Option(help="Camera ADC bit depth: 8, 10, 12 or 16 (default: the sensor's)."),
]
SensorOption = Annotated[
    str,
    typer.Option(
        help="Camera sensor: a preset (ideal, paper, imx174, webcam) or a YAML/JSON file of "
        "EMVA 1288 parameters."
    ),
]
BouncesOption = Annotated[
    int,
    typer.Option(help="Light bounces that see the projector (1 = direct; 2+ = interreflections)."),
]
ProjectorLensOption = Annotated[
    list[str] | None,
    typer.Option(
        metavar="APERTURE_M,FOCUS_M",
        help="Projector thin lens 'APERTURE_M,FOCUS_M' (defocus); default: pinhole.",
    ),
]
CameraLensOption = Annotated[
    list[str] | None,
    typer.Option(
        metavar="APERTURE_M,FOCUS_M",
        help="Camera thin lens 'APERTURE_M,FOCUS_M' (depth of field); default: pinhole.",
    ),
]
#: Scanner options that take one value holding commas (declared as lists: see :func:`once`).
_ONE_VALUE = {"projector_lens": "--projector-lens", "camera_lens": "--camera-lens"}
VariantOption = Annotated[
    str | None, typer.Option(help="Mitsuba variant (default: CUDA if it works, else LLVM).")
]
SeedOption = Annotated[
    int, typer.Option(help="Seed of the random streams (noise, random poses), >= 0.")
]


#: The scanner options by parameter name, in the order ``--help`` lists them.
SCANNER_OPTIONS: dict[str, Any] = {
    "rig": RigOption,
    "sequence": SequenceOption,
    "spp": SppOption,
    "lookup": LookupOption,
    "projector": ProjectorOption,
    "bit_depth": BitDepthOption,
    "sensor": SensorOption,
    "variant": VariantOption,
    "bounces": BouncesOption,
    "projector_lens": ProjectorLensOption,
    "camera_lens": CameraLensOption,
}
#: The parameter of a command that receives the bundle (see :func:`scanner_options`).
BUNDLE_PARAMETER = "options"


@dataclass(frozen=True)
class ScannerOptions:
    """The values of the scanner options (:data:`SCANNER_OPTIONS`) a command was given; the
    defaults are those of a command that lacks an option. :meth:`build` makes the Scanner,
    when the command is ready for its checks (a command may never need one)."""

    rig: Path | None = None
    sequence: Path | None = None
    spp: int = 4
    lookup: Lookup | None = None
    projector: str = "ideal"
    bit_depth: int | None = None
    sensor: str = "ideal"
    variant: str | None = None
    bounces: int = 1
    projector_lens: str | None = None
    camera_lens: str | None = None

    def build(self) -> Scanner:
        """The Scanner these options describe (:func:`build_scanner`)."""
        return build_scanner(**{f.name: getattr(self, f.name) for f in fields(self)})


_Command = TypeVar("_Command", bound=Callable[..., Any])


def scanner_options(
    *names: str, omit: Collection[str] = (), **defaults: Any
) -> Callable[[_Command], _Command]:
    """Give a command the scanner options: a decorator of the command function (then
    registered with ``app.command(...)`` as usual).

    The command declares a keyword parameter ``options: ScannerOptions`` where the scanner
    options are to appear in its ``--help``; the decorator replaces it with the options'
    parameters (``names``, default: all of :data:`SCANNER_OPTIONS`, less ``omit``; each
    declared once, above) in the signature Typer reads (``__signature__``), and calls the
    command with ``options`` holding their values (:class:`ScannerOptions`, whose
    :meth:`~ScannerOptions.build` makes the Scanner). ``defaults`` overrides an option's
    default for this command.
    """
    chosen = [name for name in (names or SCANNER_OPTIONS) if name not in omit]
    unknown = sorted({*chosen, *defaults} - set(SCANNER_OPTIONS))
    if unknown:
        raise ValueError(f"not scanner options: {unknown}")
    fallback = {f.name: f.default for f in fields(ScannerOptions)}

    def decorate(command: _Command) -> _Command:
        signature = inspect.signature(command, eval_str=True)
        own = [p.replace(kind=inspect.Parameter.KEYWORD_ONLY)
               for p in signature.parameters.values()]  # fmt: skip
        at = [p.name for p in own].index(BUNDLE_PARAMETER)
        bundle = [
            inspect.Parameter(
                name,
                inspect.Parameter.KEYWORD_ONLY,
                default=defaults.get(name, fallback[name]),
                annotation=SCANNER_OPTIONS[name],
            )
            for name in chosen
        ]
        parameters = [*own[:at], *bundle, *own[at + 1 :]]

        def wrapper(**kwargs: Any) -> Any:
            values = {name: kwargs.pop(name) for name in chosen}
            for name, option in _ONE_VALUE.items():
                if name in values:
                    values[name] = once(values[name], option)
            return command(**kwargs, **{BUNDLE_PARAMETER: ScannerOptions(**values)})

        for attribute in ("__module__", "__name__", "__qualname__", "__doc__"):
            setattr(wrapper, attribute, getattr(command, attribute))
        wrapper.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
        wrapper.__annotations__ = {p.name: p.annotation for p in parameters}
        return wrapper  # type: ignore[return-value]

    return decorate


def load_rig_option(path: Path | None) -> Rig:
    """The rig of ``--rig``: a rig or calibration file, read by
    :func:`virtus.calib.io.load_rig_file` (a rig JSON that states no units is in metres,
    as the rig schema has it), or the paper's rig."""
    from virtus.errors import InputError
    from virtus.geometry import default_rig

    if path is None:
        return default_rig()
    from virtus.calib import load_rig_file

    if not path.exists():
        raise InputError("rig", "an existing JSON file", str(path))
    return load_rig_file(path, units="m" if path.suffix.lower() == ".json" else None)


def load_sequence_option(path: Path | None, width: int, height: int):  # noqa: ANN201
    """The sequence of ``--sequence`` (checked against the projector size), or the paper's."""
    from virtus.errors import InputError
    from virtus.patterns import default_sequence, load_sequence_file

    if path is None:
        return default_sequence(width, height)
    sequence, _files = load_sequence_file(path)
    if (sequence.width, sequence.height) != (width, height):
        raise InputError(
            "--sequence",
            f"patterns for the rig's {width}x{height} px projector",
            f"{sequence.width}x{sequence.height} px in {path}",
        )
    return sequence


def once(values: str | list[str] | tuple[str, ...] | None, option: str) -> str | None:
    """The one value of ``option``, an option that takes a single value holding commas
    (``--camera-size 64,48``), declared as a list so that giving it twice is refused by
    name rather than the last one silently winning; None when it was not given."""
    from virtus.errors import InputError

    if values is None or isinstance(values, str):
        return values
    if len(values) > 1:
        given = " ".join(f"{option} {value}" for value in values)
        raise InputError(option, "the option once (it takes one value)", given)
    return values[0] if values else None


def names_option(values: list[str] | None) -> list[str] | None:
    """The names of a list option given comma-separated, repeated, or both
    (``--materials matte,glossy --materials metal`` -> ``[matte, glossy, metal]``), in order;
    None when it was not given. Empty parts are dropped (``--materials ,`` gives ``[]``,
    which the job refuses, naming the option)."""
    if not values:
        return None
    return [part.strip() for value in values for part in value.split(",") if part.strip()]


def parse_size(
    text: str | list[str] | None, option: str = "--camera-size"
) -> tuple[int, int] | None:
    """``(width, height)`` from ``'W,H'`` (or ``'WxH'``), both at least 1 px, or None; a
    list (the option given several times) is refused (:func:`once`)."""
    from virtus.errors import InputError

    text = once(text, option)
    if text is None:
        return None
    parts = text.replace("x", ",").replace("X", ",").split(",")
    try:
        width, height = (int(part.strip()) for part in parts)
    except ValueError:
        raise InputError(option, "'W,H' (two whole numbers of pixels)", text) from None
    if width < 1 or height < 1:
        raise InputError(option, "'W,H' of at least 1 px each", text)
    return width, height


def parse_lens(text: str | list[str] | None, option: str):  # noqa: ANN201
    """A :class:`virtus.geometry.optics.ThinLens` from ``'APERTURE_M,FOCUS_M'``, or None."""
    from virtus.errors import InputError
    from virtus.geometry import ThinLens

    text = once(text, option)
    if text is None:
        return None
    parts = text.split(",")
    try:
        aperture, focus = (float(part) for part in parts)
    except ValueError:
        raise InputError(option, "'APERTURE_M,FOCUS_M' (two numbers, metres)", text) from None
    try:
        return ThinLens(aperture, focus)
    except InputError as error:  # name the option the value came from
        raise InputError(f"{option} {error.name}", error.expected, error.got) from None


def build_scanner(
    *,
    rig: Path | None = None,
    sequence: Path | None = None,
    lookup: Lookup | None = None,
    projector: str = "ideal",
    spp: int = 4,
    sensor: str = "ideal",
    bit_depth: int | None = None,
    variant: str | None = None,
    bounces: int = 1,
    projector_lens: str | None = None,
    camera_lens: str | None = None,
) -> Scanner:
    """The Scanner the command-line options describe (every job builds it here), with the
    one :class:`~virtus.render.settings.RenderSettings` of ``--spp``, ``--variant``,
    ``--bounces`` and the lenses."""
    from virtus.render.settings import RenderSettings
    from virtus.scanner import Scanner
    from virtus.sensor import load_projector, load_sensor

    the_sensor = load_sensor(sensor)
    if bit_depth is not None:
        the_sensor = the_sensor.with_(bit_depth=bit_depth)
    the_projector = load_projector(projector)
    if lookup is not None:
        the_projector = the_projector.with_(pixel=lookup)
    the_rig = load_rig_option(rig)
    projector = the_rig.projector.intrinsics
    the_sequence = load_sequence_option(sequence, projector.width, projector.height)
    settings = RenderSettings(
        spp=spp,
        variant=variant,
        bounces=bounces,
        projector_lens=parse_lens(projector_lens, "--projector-lens"),
        camera_lens=parse_lens(camera_lens, "--camera-lens"),
    )
    return Scanner(
        rig=the_rig,
        sequence=the_sequence,
        projector=the_projector,
        sensor=the_sensor,
        render=settings,
    )
