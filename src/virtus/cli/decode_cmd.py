"""``virtus decode DIR``: decode a capture's frames into projector coordinates, with checks."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer


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
    ) -> None:
        """Decode DIR/frames into DIR/decoded/: phase_v.npy, phase_h.npy (absolute phase, rad),
        proj_uv.npy (H, W, 2 projector px), mask.npy, modulation.npy, flagged.npy (likely
        fringe-order errors), summary.json; NaN where invalid. Warns when many valid pixels
        are flagged: the sequence description probably does not match the frames. No valid
        pixel at all (black, saturated or wrongly scaled frames) is an error (exit 2) that
        says why; nothing is written then. Holds DIR's lock while writing."""
        from rich.console import Console
        from rich.table import Table

        from virtus.capture import scandir as layout
        from virtus.pipeline.scan import decode_capture

        start = time.perf_counter()
        decoded = decode_capture(
            directory,
            min_modulation=min_modulation,
            saturation_level=saturation_level,
            repair=repair,
        )
        elapsed = time.perf_counter() - start
        mask = decoded.mask
        table = Table(title=f"virtus decode -> {directory / layout.DECODED_DIR}", show_header=False)
        table.add_row("pixels decoded", f"{int(mask.sum())} of {mask.size} ({mask.mean():.1%})")
        for name, valid in (("vertical fringes (u_p)", decoded.mask_v),
                            ("horizontal fringes (v_p)", decoded.mask_h)):  # fmt: skip
            table.add_row(name, f"{valid.mean():.1%} valid")
        flagged = int(decoded.flagged.sum())
        table.add_row(
            "flagged (likely order errors)",
            f"{flagged} ({flagged / max(int(mask.sum()), 1):.2%} of decoded pixels)",
        )
        table.add_row("summary", str(directory / layout.DECODED_DIR / layout.DECODE_SUMMARY))
        table.add_row("time", f"{elapsed:.2f} s")
        Console().print(table)
