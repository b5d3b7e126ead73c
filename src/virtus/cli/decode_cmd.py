"""``virtus decode DIR``: decode a capture's frames into projector coordinates."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    @app.command("decode")
    def decode(
        directory: Annotated[Path, typer.Argument(help="Capture directory (from virtus capture).")],
    ) -> None:
        """Decode DIR/frames into DIR/decoded/: phase_v.npy, phase_h.npy (absolute phase, rad),
        proj_uv.npy (H, W, 2 projector px), mask.npy, modulation.npy; NaN where invalid."""
        from rich.console import Console
        from rich.table import Table

        from virtus.pipeline import layout
        from virtus.pipeline.scan import decode_capture

        start = time.perf_counter()
        decoded = decode_capture(directory)
        elapsed = time.perf_counter() - start
        mask = decoded.mask
        table = Table(title=f"virtus decode -> {directory / layout.DECODED_DIR}", show_header=False)
        table.add_row("pixels decoded", f"{int(mask.sum())} of {mask.size} ({mask.mean():.1%})")
        for name, valid in (("vertical fringes (u_p)", decoded.mask_v),
                            ("horizontal fringes (v_p)", decoded.mask_h)):  # fmt: skip
            table.add_row(name, f"{valid.mean():.1%} valid")
        table.add_row("files", ", ".join(f"{n}.npy" for n in layout.DECODED_FILES))
        table.add_row("time", f"{elapsed:.2f} s")
        Console().print(table)
