"""``virtus patterns``: write the default fringe sequence as 8-bit PNGs plus ``sequence.json``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def register(app: typer.Typer) -> None:
    @app.command("patterns")
    def patterns(
        out: Annotated[Path, typer.Option(help="Output folder.")] = Path("patterns"),
        width: Annotated[int, typer.Option(help="Projector width, px.")] = 912,
        height: Annotated[int, typer.Option(help="Projector height, px.")] = 1140,
    ) -> None:
        """Write the paper's 52-frame sequence (18-step phase shift, T = 18 px, 6-bit Gray +
        complementary, vertical and horizontal, white, black) as DIR/000.png ... and
        DIR/sequence.json describing every frame."""
        from virtus.optics import Intrinsics
        from virtus.patterns import default_sequence

        # The projector's size within the bounds of any device image (checked before the
        # patterns are built or written).
        Intrinsics(1.0, 1.0, 0.0, 0.0, width, height)
        sequence = default_sequence(width, height)
        path = sequence.save(out)
        typer.echo(
            f"wrote {len(sequence)} frames ({sequence.width} x {sequence.height} px, 8-bit) "
            f"and {path}"
        )
