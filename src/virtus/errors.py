"""Exception types: one base, and the kinds a caller would catch.

Every error virtus raises on purpose is a :class:`VirtusError`; the CLI prints it as one line
and exits 2. The kinds also inherit the matching built-in (as zarr's ``errors.py`` does), so
``except ValueError`` or ``except ImportError`` keeps working:

* :class:`InputError` (``ValueError``) -- bad input: names the argument, what was expected
  and what came;
* :class:`RunConflict` -- an output directory or file belongs to another
  run, another configuration, or is in use: resume, overwrite or choose another place;
* :class:`DegenerateData` (``ValueError``) -- well-formed data that carries too little
  information for the computation (coplanar points, parallel board poses, nothing decoded);
* :class:`MissingDependency` (``ImportError``) -- an optional package is not installed; the
  message names the extra that installs it;
* :class:`BackendUnavailable` (``RuntimeError``) -- no working renderer backend (Mitsuba
  variant) on this machine.
"""

__all__ = [
    "BackendUnavailable",
    "DegenerateData",
    "InputError",
    "MissingDependency",
    "RunConflict",
    "VirtusError",
]


class VirtusError(Exception):
    """Base class of every error virtus raises on purpose."""


class InputError(VirtusError, ValueError):
    """Bad input: the message names the argument, what was expected and what came."""

    def __init__(self, name: str, expected: str, got: object) -> None:
        self.name = name
        self.expected = expected
        self.got = got
        super().__init__(f"{name}: expected {expected}, got {_short(got)}")


class RunConflict(VirtusError):
    """An output directory or file is another run's, another configuration's, or in use."""


class DegenerateData(VirtusError, ValueError):
    """Data too degenerate for the computation (the message says what was missing)."""


class MissingDependency(VirtusError, ImportError):
    """An optional dependency is not installed (the message says how to install it)."""


class BackendUnavailable(VirtusError, RuntimeError):
    """No renderer backend works on this machine (the message says what is missing)."""


def _short(value: object, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
