"""``virtus decode DIR``: decode a capture's frames into projector coordinates, with checks."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.output import JsonOption, Output, QuietOption, Summary


def register(app: typer.Typer) -> None:
    @app.command("decode")
    def decode(
        directory: Annotated[
            Path, typer.Argument(help="Capture directory (virtus capture or virtus import).")
        ],
        min_modulation: Annotated[
            float,
            typer.Option(
                help="Modulation threshold: fringe amplitude B as a fraction of full scale."
            ),
        ] = 0.02,
        saturation_level: Annotated[
            float | None,
            typer.Option(help="Digital number at or above which a pixel is saturated (invalid)."),
        ] = None,
        repair: Annotated[
            bool,
            typer.Option("--repair", help="Repair fringe orders that disagree with the phase."),
        ] = False,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Decode a capture into projector coordinates.

        Decode DIR/frames into DIR/decoded/: phase_v.npy, phase_h.npy (absolute phase, rad),
        proj_uv.npy (H, W, 2 projector px), mask.npy, modulation.npy, flagged.npy (likely
        fringe-order errors), summary.json; NaN where invalid. Warns when many valid pixels
        are flagged: the sequence description probably does not match the frames. No valid
        pixel at all (black, saturated or wrongly scaled frames) is an error (exit 2) that
        says why; nothing is written then. Holds DIR's lock while writing."""
        from virtus.capture import scandir as layout
        from virtus.pipeline.scan import decode_capture

        output = Output(json_out, quiet)
        start = time.perf_counter()
        decoded = decode_capture(
            directory,
            min_modulation=min_modulation,
            saturation_level=saturation_level,
            repair=repair,
        )
        mask = decoded.mask
        valid = int(mask.sum())
        flagged = int(decoded.flagged.sum())
        data = {
            "directory": str(directory / layout.DECODED_DIR),
            "pixels_decoded": valid,
            "pixels": int(mask.size),
            "decoded_fraction": float(mask.mean()),
            "valid_fraction_v": float(decoded.mask_v.mean()),
            "valid_fraction_h": float(decoded.mask_h.mean()),
            "flagged": flagged,
            "flagged_fraction": flagged / max(valid, 1),
            "summary": str(directory / layout.DECODED_DIR / layout.DECODE_SUMMARY),
            "time_s": time.perf_counter() - start,
        }
        output.emit(Summary(data, _print_decode))


def _print_decode(console, d) -> None:  # noqa: ANN001
    from rich.table import Table

    table = Table(title=f"virtus decode -> {d['directory']}", show_header=False)
    table.add_row(
        "pixels decoded", f"{d['pixels_decoded']} of {d['pixels']} ({d['decoded_fraction']:.1%})"
    )
    table.add_row("vertical fringes (u_p)", f"{d['valid_fraction_v']:.1%} valid")
    table.add_row("horizontal fringes (v_p)", f"{d['valid_fraction_h']:.1%} valid")
    table.add_row(
        "flagged (likely order errors)",
        f"{d['flagged']} ({d['flagged_fraction']:.2%} of decoded pixels)",
    )
    table.add_row("summary", d["summary"])
    table.add_row("time", f"{d['time_s']:.2f} s")
    console.print(table)
