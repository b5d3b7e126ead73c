"""Projected frames as data: the frame kinds (:data:`KINDS`), the fringe directions
(:data:`DIRECTIONS`) and :class:`Frame`, one record of plain fields per projected frame that
gives the coding it belongs to (:mod:`virtus.patterns.codings`, conventions there).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from virtus.checks import finite, positive, positive_int
from virtus.errors import InputError
from virtus.patterns.codings import (
    ALIGNS,
    MAX_BITS,
    PROFILES,
    BitCode,
    PhaseCoding,
    _choice,
)

__all__ = ["DIRECTIONS", "KINDS", "MAX_FRAMES", "Frame"]

#: Frame kinds.
KINDS = (
    "phase",
    "gray",
    "binary",
    "gray_complement",
    "binary_complement",
    "white",
    "black",
    "ignore",
)
#: Code frame kinds -> the code they belong to.
_CODE_KINDS = {"gray": "gray", "binary": "binary"}
_COMPLEMENT_KINDS = {"gray_complement": "gray", "binary_complement": "binary"}
_UNIFORM_KINDS = ("white", "black", "ignore")
#: Fringe directions: "v" varies along u_p (columns), "h" along v_p (rows).
DIRECTIONS = ("v", "h")
#: Most frames in one sequence (bounds checked before allocating).
MAX_FRAMES = 4096
_FIELDS = (
    "kind",
    "direction",
    "period",
    "step",
    "steps",
    "bit",
    "bits",
    "profile",
    "offset",
    "sign",
    "align",
    "inverted",
)
_DEFAULTS = {
    "profile": "sinusoidal",
    "offset": 0.0,
    "sign": 1,
    "align": "centre",
    "inverted": False,
}


@dataclass(frozen=True)
class Frame:
    """One projected frame (plain fields; :meth:`coding` gives the coding it belongs to).

    Attributes
    ----------
    kind : one of :data:`KINDS`.
    direction : ``"v"`` (varies along u_p), ``"h"`` (varies along v_p), ``None`` for the
        uniform white, black and ignore frames.
    period : fringe period ``T`` in pattern units (phase frames; for code frames the period
        whose fringe order they encode, or in a direction without phase frames the code's
        stripe width), ``None`` for uniform frames.
    step, steps : phase frames only: shift index ``n`` in ``1..N`` and ``N >= 3``.
    bit, bits : Gray/binary bit frames only: bit index in ``1..bits``, 1 the most
        significant; ``bits <= MAX_BITS``.
    profile, offset, sign : phase frames only (defaults ``"sinusoidal"``, ``0.0`` rad, ``+1``).
    align, inverted : code and complementary frames only (defaults ``"centre"``, False).
    """

    kind: str
    direction: str | None = None
    period: float | None = None
    step: int | None = None
    steps: int | None = None
    bit: int | None = None
    bits: int | None = None
    profile: str | None = None
    offset: float | None = None
    sign: int | None = None
    align: str | None = None
    inverted: bool | None = None

    def __post_init__(self) -> None:
        _choice("kind", self.kind, KINDS)
        if self.kind in _UNIFORM_KINDS:
            self._none(_FIELDS[1:])
            return
        if self.direction not in DIRECTIONS:
            raise InputError("direction", f"one of {DIRECTIONS}", self.direction)
        self._set("period", positive("period", self.period))
        if self.kind == "phase":
            self._none(("bit", "bits", "align", "inverted"))
            steps = positive_int("steps", self.steps, minimum=3)
            if steps > MAX_FRAMES:
                raise InputError("steps", f"an integer in 3..{MAX_FRAMES}", self.steps)
            step = positive_int("step", self.step)
            if step > steps:
                raise InputError("step", f"an integer in 1..{steps}", self.step)
            sign = _DEFAULTS["sign"] if self.sign is None else self.sign
            if isinstance(sign, bool) or sign not in (1, -1):
                raise InputError("sign", "+1 or -1", self.sign)
            offset = _DEFAULTS["offset"] if self.offset is None else self.offset
            profile = _DEFAULTS["profile"] if self.profile is None else self.profile
            self._set("steps", steps)
            self._set("step", step)
            self._set("profile", _choice("profile", profile, PROFILES))
            self._set("offset", finite("offset", offset))
            self._set("sign", int(sign))
            return
        self._none(("step", "steps", "profile", "offset", "sign"))
        align = _DEFAULTS["align"] if self.align is None else self.align
        inverted = _DEFAULTS["inverted"] if self.inverted is None else self.inverted
        self._set("align", _choice("align", align, ALIGNS))
        if not isinstance(inverted, bool | np.bool_):
            raise InputError("inverted", "true or false", self.inverted)
        self._set("inverted", bool(inverted))
        if self.kind in _COMPLEMENT_KINDS:
            self._none(("bit", "bits"))
            return
        bits = positive_int("bits", self.bits)
        if bits > MAX_BITS:
            raise InputError("bits", f"an integer in 1..{MAX_BITS}", self.bits)
        bit = positive_int("bit", self.bit)
        if bit > bits:
            raise InputError("bit", f"an integer in 1..{bits}", self.bit)
        self._set("bits", bits)
        self._set("bit", bit)

    def _set(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)

    def _none(self, names: Iterable[str]) -> None:
        for name in names:
            if getattr(self, name) is not None:
                raise InputError(name, f"None for a {self.kind} frame", getattr(self, name))

    @property
    def uniform(self) -> bool:
        """True for the white, black and ignore frames."""
        return self.direction is None

    def coding(self, bits: int | None = None, complement: bool = False) -> PhaseCoding | BitCode:
        """The coding this frame belongs to (phase and code frames only). A complementary
        frame does not know the code's length: pass ``bits`` (and ``complement``)."""
        if self.kind == "phase":
            return PhaseCoding(self.period, self.steps, self.profile, self.offset, self.sign)  # type: ignore[arg-type]
        if self.uniform:
            raise InputError("frame", "a phase or code frame", self.kind)
        code = _CODE_KINDS.get(self.kind) or _COMPLEMENT_KINDS[self.kind]
        return BitCode(code, self.period, self.bits or bits or 1, self.align, complement)  # type: ignore[arg-type]

    def values(self, coordinate: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """The pattern before 8-bit quantisation, at any projector coordinate.

        Sinusoidal phase frames give the cosine at the exact coordinate; binary and dithered
        phase frames and code frames the value of the projector pixel containing it;
        uniform frames 1 (white) or 0 (black, ignore).

        Parameters
        ----------
        coordinate : (...) float, projector px along the frame's axis (u_p for ``"v"``,
            v_p for ``"h"``).
        scale : pattern units per projector px on that axis.

        Returns
        -------
        (...) float64 in [0, 1], same shape as ``coordinate``.
        """
        u = np.asarray(coordinate, dtype=np.float64)
        if self.uniform:
            return np.full_like(u, 1.0 if self.kind == "white" else 0.0)
        coding = self.coding()
        if isinstance(coding, PhaseCoding):
            return coding.values(self.step, u, scale)  # type: ignore[arg-type]
        value = coding.bit_values(self.bit, u, scale)
        return 1.0 - value if self.inverted else value

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict holding ``kind`` and the fields that apply to it (defaults left
        out)."""
        out = {}
        for name in _FIELDS:
            value = getattr(self, name)
            if value is not None and not (name in _DEFAULTS and value == _DEFAULTS[name]):
                out[name] = value
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Frame:
        """Inverse of :meth:`to_dict`; ``index`` and ``file`` keys (written by
        :meth:`PatternSequence.describe` and :meth:`PatternSequence.save`) are ignored."""
        if not isinstance(data, Mapping) or "kind" not in data:
            raise InputError("frame", "a mapping with a 'kind' key", data)
        _known_keys("frame", data, (*_FIELDS, "index", "file"))
        return cls(**{k: data[k] for k in _FIELDS if k in data})


def _known_keys(name: str, data: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Refuse keys of ``data`` outside ``allowed``, naming them."""
    unknown = sorted(str(key) for key in set(data) - set(allowed))
    if unknown:
        raise InputError(name, f"keys among {sorted(allowed)}", f"unknown keys {unknown}")
