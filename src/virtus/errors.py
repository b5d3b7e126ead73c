"""Exception types.

Every error caused by bad input is an :class:`InputError` (a ``ValueError``) whose message
names the argument, what was expected and what came. The CLI prints such errors as one line
and exits non-zero.
"""


class VirtusError(Exception):
    """Base class of every error virtus raises on purpose."""


class InputError(VirtusError, ValueError):
    """Bad input: the message names the argument, what was expected and what came."""

    def __init__(self, name: str, expected: str, got: object) -> None:
        self.name = name
        self.expected = expected
        self.got = got
        super().__init__(f"{name}: expected {expected}, got {_short(got)}")


def _short(value: object, limit: int = 80) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."
