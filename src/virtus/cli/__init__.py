"""The ``virtus`` command: a thin layer that parses arguments, calls library functions, prints.

Each sub-command lives in its own module here and exposes ``register(app)``. Heavy imports
(Mitsuba, OpenCV) happen inside the command functions so ``virtus --help`` stays fast.
Usage errors and errors caused by bad input (:class:`virtus.VirtusError`, ``OSError``) are
printed as one line on stderr, with exit status 2 and no traceback.
"""

from __future__ import annotations

import errno
import inspect
import sys
import warnings

import typer

from virtus.allocator import keep_freed_memory
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
        ablation_cmd,
        acceptance_cmd,
        calibrate_cmd,
        capture_cmd,
        dataset_cmd,
        decode_cmd,
        demo_cmd,
        design_cmd,
        evaluate_cmd,
        export_usd_cmd,
        handeye_cmd,
        import_cmd,
        learn_cmd,
        patterns_cmd,
        predict_cmd,
        reconstruct_cmd,
        report_cmd,
        rig_cmd,
        robot_scan_cmd,
        scan_cmd,
        twin_cmd,
    )

    for module in (
        demo_cmd,
        rig_cmd,
        patterns_cmd,
        calibrate_cmd,
        capture_cmd,
        import_cmd,
        decode_cmd,
        reconstruct_cmd,
        scan_cmd,
        evaluate_cmd,
        robot_scan_cmd,
        handeye_cmd,
        ablation_cmd,
        predict_cmd,
        design_cmd,
        dataset_cmd,
        learn_cmd,
        twin_cmd,
        export_usd_cmd,
        acceptance_cmd,
        report_cmd,
    ):
        module.register(app)


_register_commands()


def _first_sentence(text: str) -> str:
    """The first sentence of a help text's first paragraph, on one line."""
    paragraph = " ".join(inspect.cleandoc(text).split("\n\n")[0].split())
    end = paragraph.find(". ")
    return paragraph if end < 0 else paragraph[: end + 1]


def _one_line_help(group: typer.Typer) -> None:
    """Each command of ``group`` (and of its sub-groups) is listed in the group's ``--help``
    by the first sentence of its help, on one line (``short_help``); its own ``--help``
    keeps the whole text."""
    for info in group.registered_commands:
        text = info.help or inspect.getdoc(info.callback) or ""
        if info.short_help is None and text:
            info.short_help = _first_sentence(text)
    for sub in group.registered_groups:
        if sub.typer_instance is not None:
            _one_line_help(sub.typer_instance)


_one_line_help(app)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:  # noqa: ANN001
    """Warnings as one line on stderr, without the source line."""
    print(f"virtus: warning: {message}", file=sys.stderr)


def _os_error_line(error: OSError) -> str:
    """An ``OSError`` as one line naming its path; a full disk says so in plain words
    ("no space left on device writing PATH; free some space or write elsewhere")."""
    where = error.filename
    if error.errno == errno.ENOSPC:
        target = f" writing {where}" if where else ""
        return f"no space left on device{target}; free some space or write elsewhere"
    text = error.strerror or str(error) or type(error).__name__
    return f"{text}: {where}" if where else text


def main(argv: list[str] | None = None) -> None:
    """Entry point of the console script; ``argv`` defaults to ``sys.argv[1:]``.

    Every error ends as one line on stderr and a non-zero exit status, never a traceback:
    usage errors found by Typer (unknown command or option, a value of the wrong type or
    not among the choices; status 2), and errors raised by the library for bad input or
    missing files (:class:`VirtusError`, ``OSError``; status 2).
    """
    warnings.showwarning = _show_warning
    keep_freed_memory()  # numpy's temporaries reuse freed pages (virtus.allocator)
    try:
        status = app(args=argv, prog_name="virtus", standalone_mode=False)
    except typer.TyperException as error:
        # NoArgsIsHelpError: Typer has printed the help already.
        if type(error).__name__ != "NoArgsIsHelpError":
            format_message = getattr(error, "format_message", None)
            message = format_message() if format_message else str(error)
            message = " ".join(message.replace("Value error, ", "").split())
            print(f"virtus: error: {message}", file=sys.stderr)
        sys.exit(getattr(error, "exit_code", 2))
    except typer.Abort:
        print("virtus: aborted", file=sys.stderr)
        sys.exit(1)
    except VirtusError as error:
        print(f"virtus: error: {error}", file=sys.stderr)
        sys.exit(2)
    except OSError as error:
        print(f"virtus: error: {_os_error_line(error)}", file=sys.stderr)
        sys.exit(2)
    # Without standalone mode Typer returns the status of --help or typer.Exit, or what the
    # command returned (None); exit as standalone mode would.
    sys.exit(status if isinstance(status, int) else 0)
