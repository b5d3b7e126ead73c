"""The ``virtus`` command: a thin layer that parses arguments, calls library functions, prints.

Each sub-command lives in its own module here and exposes ``register(app)``. Heavy imports
(Mitsuba, OpenCV) happen inside the command functions so ``virtus --help`` stays fast.
Errors caused by bad input (:class:`virtus.VirtusError`, ``OSError``) are printed as one line
on stderr, with exit status 2 and no traceback.
"""

from __future__ import annotations

import sys

import typer

from virtus.errors import VirtusError

app = typer.Typer(
    name="virtus",
    help="virtus: a virtual fringe projection profilometry sensor.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _register_commands() -> None:
    # One module per sub-command (import order = order in --help).
    from virtus.cli import (
        calibrate_cmd,
        capture_cmd,
        decode_cmd,
        demo_cmd,
        evaluate_cmd,
        patterns_cmd,
        reconstruct_cmd,
        rig_cmd,
        scan_cmd,
    )

    for module in (
        demo_cmd,
        rig_cmd,
        patterns_cmd,
        calibrate_cmd,
        capture_cmd,
        decode_cmd,
        reconstruct_cmd,
        scan_cmd,
        evaluate_cmd,
    ):
        module.register(app)


_register_commands()


def main(argv: list[str] | None = None) -> None:
    """Entry point of the console script; ``argv`` defaults to ``sys.argv[1:]``.

    Typer handles usage errors itself (exit 2 with a usage line); errors raised by the
    library for bad input or missing files become one line on stderr, exit status 2.
    """
    try:
        app(args=argv, prog_name="virtus")
    except VirtusError as error:
        print(f"virtus: error: {error}", file=sys.stderr)
        sys.exit(2)
    except OSError as error:
        where = f": {error.filename}" if error.filename else ""
        print(f"virtus: error: {error.strerror or error}{where}", file=sys.stderr)
        sys.exit(2)
