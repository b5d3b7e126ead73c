"""``virtus twin``: the digital twin of a calibrated rig for Isaac Sim, its light fitted to
real captures, and its validation against them (:mod:`virtus.pipeline.twin`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from virtus.cli.options import CameraSizeOption, PixelSizeOption, UnitsOption, once, parse_size
from virtus.cli.output import JsonOption, Output, QuietOption, Summary

ProjectorSizeOption = Annotated[
    list[str] | None,
    typer.Option(
        "--projector-size",
        metavar="W,H",
        help="Projector image size 'W,H' in pixels, for a calibration file that states none.",
    ),
]
FitOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--fit",
        help="Real captures (phase shifts with white and black frames, e.g. of a matte plane at "
        "several distances; directories or folders of them) to fit the twin's camera and "
        "projector to: OUT/sensor.yaml, OUT/projector.yaml, OUT/photometric.json; --validate "
        "then renders with them.",
    ),
]
ValidateOption = Annotated[
    list[Path] | None,
    typer.Option(
        "--validate",
        help="Real calibration captures (directories or folders of them) to re-render "
        "with the twin and compare (a board the calibration file does not pose is posed "
        "from both devices); more may follow as arguments.",
    ),
]
MoreOption = Annotated[
    list[Path] | None,
    typer.Argument(help="More captures (of --fit or --validate, whichever is given)."),
]
PriorSensorOption = Annotated[
    str | None,
    typer.Option(
        "--sensor", help="With --fit: the camera as known (preset or file): black level, PRNU."
    ),
]
PriorProjectorOption = Annotated[
    str | None,
    typer.Option(
        "--projector",
        help="With --fit: the projector as known (preset or file): contrast, fill factor.",
    ),
]
#: Columns of the printed tables: geometry, then light.
GEOMETRY_COLUMNS = (
    "centre_diff_mean_px", "centre_diff_max_px", "proj_uv_rms_px", "cloud_mae_mm",
    "cloud_rmse_mm",
)  # fmt: skip
LIGHT_COLUMNS = ("white_rms", "black_rms", "fringe_rms", "code_rms", "point_noise_ratio")


def _print_twin(console: Any, data: dict[str, Any]) -> None:
    """The twin's files, then its validation (when it ran) from the summary."""
    for path in data["written"].values():
        console.print(f"wrote {path}", markup=False, soft_wrap=True)
    if data["validation"] is not None:
        _print_validation(console, data["validation"])


def _print_validation(console: Any, result: dict[str, Any]) -> None:
    from rich.table import Table

    rows = [*result["per_pose"], {"name": "overall", **result["overall"]}]
    for title, columns in (
        ("real - twin", GEOMETRY_COLUMNS),
        ("real - twin, light", LIGHT_COLUMNS),
    ):
        table = Table(title=title)
        table.add_column("pose")
        for column in columns:
            table.add_column(column, justify="right")
        for row in rows:
            table.add_row(row["name"], *(f"{row.get(c, float('nan')):.4f}" for c in columns))
        console.print(table)
    console.print(
        f"paper: real-to-virtual MAE {result['overall']['paper_cloud_mae_mm']} mm; "
        f"wrote {result['file']}"
    )
    for name, reason in result["dropped"].items():
        console.print(f"[yellow]dropped {name}:[/yellow] {reason}")


def register(app: typer.Typer) -> None:
    @app.command("twin")
    def twin(
        calibration: Annotated[
            Path,
            typer.Argument(help="Calibration file (calibration.json, OpenCV YAML, txt folder)."),
        ],
        out: Annotated[Path, typer.Option(help="Output directory.")] = Path("virtus-twin"),
        fit: FitOption = None,
        validate: ValidateOption = None,
        more_captures: MoreOption = None,
        albedo: Annotated[
            float, typer.Option(help="With --fit: albedo of the captured surface.")
        ] = 1.0,
        sensor: PriorSensorOption = None,
        projector: PriorProjectorOption = None,
        board: Annotated[
            list[str] | None,
            typer.Option(metavar="SPEC", help="Board spec (default: the calibration file's)."),
        ] = None,
        meters_per_unit: Annotated[
            float, typer.Option(help="The stage's metersPerUnit (1 = metres, 0.01 = cm).")
        ] = 1.0,
        spp: Annotated[int, typer.Option(help="Supersamples of the twin renders.")] = 1,
        units: UnitsOption = None,
        camera_size: CameraSizeOption = None,
        projector_size: ProjectorSizeOption = None,
        pixel_size_um: PixelSizeOption = None,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Build a digital twin of a rig for Isaac Sim.

        Write OUT/rig.json, OUT/isaac.json (Isaac Sim parameters in USD's convention:
        lens and film values in tenths of a scene unit, metersPerUnit, lens distortion,
        projector RectLight size at 1 m, poses in Isaac's world) and, with usd-core,
        OUT/twin.usda. With --fit, fit the twin's light (projector gamma and blur,
        vignetting and fall-off, exposure, ambient level, gain and noise) to real captures.
        With --validate, re-render every captured pose with the twin and write
        OUT/validation.json."""
        from virtus.errors import InputError
        from virtus.pipeline.twin import VALIDATION_FILE, check_validation, run_twin

        board = once(board, "--board")
        extra = list(more_captures or [])
        if extra and not (validate or fit):
            raise InputError("arguments", "captures after --fit or --validate", extra)
        if extra and validate and fit:
            raise InputError(
                "arguments",
                "captures after only one of --fit and --validate (repeat the option, or give "
                "a folder of captures)",
                extra,
            )
        fits = [*(fit or []), *(extra if not validate else [])]
        unit = None if units is None else units.value
        output = Output(json_out, quiet)
        validated = [*validate, *(extra if not fit else [])] if validate else []
        if validate:  # refuse bad validation inputs before the twin is written
            check_validation(calibration, validated, board=board, units=unit)
        if pixel_size_um is not None and not 0 < pixel_size_um < 1000:  # NaN fails too
            raise InputError("--pixel-size-um", "a pixel pitch in (0, 1000) um", pixel_size_um)
        pitch = {} if pixel_size_um is None else {"pixel_size_m": pixel_size_um * 1e-6}
        written, result = run_twin(
            calibration, out, validate=validated or None, board=board, spp=spp,
            meters_per_unit=meters_per_unit, units=unit, fit=fits or None,
            albedo=albedo, sensor=sensor, projector=projector,
            camera_size=parse_size(camera_size),
            projector_size=parse_size(projector_size, "--projector-size"), **pitch,
        )  # fmt: skip
        data: dict[str, Any] = {"written": dict(written), "validation": None}
        if result is None:
            output.emit(Summary(data, _print_twin))
            return
        data["validation"] = {
            "per_pose": list(result.per_pose),
            "overall": dict(result.overall),
            "dropped": dict(result.dropped),
            "file": str(out / VALIDATION_FILE),
        }
        output.emit(Summary(data, _print_twin))
