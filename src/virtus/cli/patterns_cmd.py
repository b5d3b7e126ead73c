"""``virtus patterns``: write a fringe sequence as 8-bit PNGs plus ``sequence.json``."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from virtus.cli.options import SequenceOption
from virtus.cli.output import JsonOption, Output, QuietOption, Summary


def register(app: typer.Typer) -> None:
    @app.command("patterns")
    def patterns(
        out: Annotated[Path, typer.Option(help="Output folder.")] = Path("patterns"),
        sequence: SequenceOption = None,
        width: Annotated[
            int, typer.Option(help="Projector width, px (the default sequence).")
        ] = 912,
        height: Annotated[
            int, typer.Option(help="Projector height, px (the default sequence).")
        ] = 1140,
        json_out: JsonOption = False,
        quiet: QuietOption = False,
    ) -> None:
        """Write a pattern sequence as PNG frames.

        Write a sequence's frames as DIR/000.png ... (what the projector shows, 8-bit) and
        DIR/sequence.json, the description every job reads with --sequence. Default: the
        paper's 52 frames (18-step phase shift, T = 18 px, 6-bit Gray + complementary,
        vertical and horizontal, white, black); --sequence FILE writes that sequence."""
        from virtus.geometry import Intrinsics
        from virtus.patterns import default_sequence, load_sequence_file

        if sequence is not None:
            the_sequence, _files = load_sequence_file(sequence)
        else:
            # The projector's size within the bounds of any device image (checked before the
            # patterns are built or written).
            Intrinsics(1.0, 1.0, 0.0, 0.0, width, height)
            the_sequence = default_sequence(width, height)
        path = the_sequence.save(out)
        data = {
            "frames": len(the_sequence),
            "width": the_sequence.width,
            "height": the_sequence.height,
            "bit_depth": 8,
            "directory": str(out),
            "sequence": str(path),
        }
        summary = Summary(data)
        summary.lines.append(
            f"wrote {data['frames']} frames ({data['width']} x {data['height']} px, 8-bit) "
            f"and {path}"
        )
        Output(json_out, quiet).emit(summary)
