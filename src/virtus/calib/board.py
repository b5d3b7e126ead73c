"""Calibration boards: asymmetric circle grids (the paper's scale equations) and
checkerboards; their geometry, textures and text specs (:func:`board_from_spec`).

Board frame (metres): origin at the centre of the plane (= centre of the texture), x along
the texture columns, y along the texture rows, z = x cross y (pointing into the board, away
from a viewer who sees x to the right and y downwards, as OpenCV's calibration boards).
The circles lie in z = 0.

Layout of a board with ``rows`` R and ``cols`` C (the paper's 4x7, 5x9, 7x13): C columns of
circles, ``D_centers / 2`` apart along x; each column holds R circles ``D_centers`` apart
along y, and odd columns are shifted by ``D_centers / 2`` along y (the asymmetric grid of
OpenCV). The paper sizes the printed pattern as (DESIGN.md section 4)

    W_pat = (2 L_b + (C - 1) D_centers / 2 + D_circle) k
    H_pat = (2 L_b + (R - 1) D_centers + D_circle) k,     k = 0.001 m/mm

and scales it onto a plane of size (W_plane, H_plane) by S = min(W_plane / W_pat,
H_plane / H_pat), so every length D (mm) becomes D_sim = D k S in the scene. ``H_pat``
ignores the half-spacing shift of odd columns, so the circles reach ``D_centers / 4`` into
the top and bottom borders; :class:`CircleBoard` checks that every circle stays on the plane.

Circles are dark on a light board (black-on-white, ``circle_level < background_level``) or
light on a dark one (white-on-black, ``circle_level > background_level``).

:class:`CheckerBoard`: ``rows`` x ``cols`` *inner* corners (OpenCV's ``patternSize`` is
``(cols, rows)``) of squares ``square_mm`` wide, in the same board frame: corner ``r * cols +
c`` at ``((c - (cols - 1) / 2) s, (r - (rows - 1) / 2) s, 0)``; the square beyond corner 0
(towards -x, -y) is dark. ``rows + cols`` must be odd: the board then differs from its half
turn, so the order of its corners is unambiguous.

Specs (:func:`board_from_spec`; lengths in millimetres, always stated)::

    7x13                                   the paper's circle board (scaled onto 0.2 x 0.2 m)
    circles:4x11,spacing_mm=40,diameter_mm=20[,border_mm=20][,white_on_black]
    checker:6x9,square_mm=25[,border_mm=20]
    board.json / board.yaml                a board's to_dict() (its "type" says which)
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from virtus.checks import as_float_array, finite, positive, positive_int
from virtus.errors import InputError

#: metres per millimetre, the paper's ``k``.
MM = 1e-3

#: the paper's example boards (rows, cols) with the defaults used here for them.
PAPER_BOARDS = ("4x7", "5x9", "7x13")


def _edge_blur(coverage: np.ndarray, blur_m: float, step_x: float, step_y: float) -> np.ndarray:
    """A board texture's dark-area coverage blurred by a Gaussian of ``blur_m`` metres
    (texels of ``step_x`` x ``step_y`` m), so supersampling integrates its edges."""
    if blur_m < 0:
        raise InputError("blur_m", "a standard deviation >= 0 (m)", blur_m)
    if blur_m == 0:
        return coverage
    import cv2

    return cv2.GaussianBlur(
        coverage, (0, 0), sigmaX=blur_m / step_x, sigmaY=blur_m / step_y,
        borderType=cv2.BORDER_REPLICATE,
    )  # fmt: skip


@dataclass(frozen=True)
class CircleBoard:
    """An asymmetric circle grid printed on a rectangular plane.

    Parameters
    ----------
    rows : circles per column (R, >= 2).
    cols : number of columns (C, odd, >= 3); the columns alternate between two heights.
        An odd C makes the grid asymmetric under a half turn, so its orientation and the
        order of its circles are unambiguous.
    circle_diameter_mm : D_circle of the printed pattern, millimetres.
    center_distance_mm : D_centers, distance between neighbouring circles of one column, mm.
    border_mm : L_b, the white border of the printed pattern, mm.
    plane_size_m : (width, height) of the plane in the scene, metres.
    circle_level, background_level : texture values (albedo factors in [0, 1]) of the circles
        and of the paper. Dark grey rather than black circles keep the fringe modulation
        inside the circles high enough to decode the phase there (0.25 keeps a 4:1
        contrast, ample for blob detection). ``circle_level > background_level`` describes
        a white-on-black board (light circles).
    """

    rows: int = 7
    cols: int = 13
    circle_diameter_mm: float = 20.0
    center_distance_mm: float = 40.0
    border_mm: float = 20.0
    plane_size_m: tuple[float, float] = (0.2, 0.2)
    circle_level: float = 0.25
    background_level: float = 1.0

    def __post_init__(self) -> None:
        positive_int("rows", self.rows, 2)
        positive_int("cols", self.cols, 3)
        if self.cols % 2 == 0:
            # With an even number of columns the grid is symmetric under a half turn, so
            # its orientation (and the order of the circles) would be ambiguous.
            raise InputError("cols", "an odd number of columns (e.g. 7, 9, 13)", self.cols)
        positive("circle_diameter_mm", self.circle_diameter_mm)
        positive("center_distance_mm", self.center_distance_mm)
        if finite("border_mm", self.border_mm) < 0:
            raise InputError("border_mm", "a number >= 0", self.border_mm)
        size = as_float_array("plane_size_m", self.plane_size_m, (2,))
        if (size <= 0).any():
            raise InputError("plane_size_m", "two positive lengths (m)", self.plane_size_m)
        object.__setattr__(self, "plane_size_m", (float(size[0]), float(size[1])))
        for name in ("circle_level", "background_level"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise InputError(name, "a value in [0, 1]", value)
        if self.circle_level == self.background_level:
            raise InputError(
                "circle_level",
                f"a value different from background_level={self.background_level}",
                self.circle_level,
            )
        # Neighbouring circles (one column apart) are D_centers / sqrt(2) apart.
        if self.circle_diameter_mm >= self.center_distance_mm / np.sqrt(2.0):
            raise InputError(
                "circle_diameter_mm",
                f"less than center_distance_mm / sqrt(2) = {self.center_distance_mm / 2**0.5:.3g}"
                " (circles would touch)",
                self.circle_diameter_mm,
            )
        half_w, half_h = 0.5 * size
        extent = np.abs(self.object_points[:, :2]).max(axis=0) + 0.5 * self.circle_diameter_m
        if extent[0] > half_w or extent[1] > half_h:
            raise InputError("plane_size_m", "a plane that holds every circle", self.plane_size_m)

    #: Kind of board, as written in :meth:`to_dict`.
    TYPE = "asymmetric_circles"

    @property
    def light_features(self) -> bool:
        """True for a white-on-black board (circles lighter than the background)."""
        return self.circle_level > self.background_level

    @property
    def spacing_m(self) -> float:
        """Distance between neighbouring circles of one column (D_centers^sim), metres."""
        return self.center_distance_m

    # -- the paper's scale equations -------------------------------------------------------
    @property
    def pattern_size_m(self) -> tuple[float, float]:
        """(W_pat, H_pat): the printed pattern's size in metres (paper's equations, k=0.001)."""
        w = 2 * self.border_mm + (self.cols - 1) * self.center_distance_mm / 2
        h = 2 * self.border_mm + (self.rows - 1) * self.center_distance_mm
        return ((w + self.circle_diameter_mm) * MM, (h + self.circle_diameter_mm) * MM)

    @property
    def scale(self) -> float:
        """S = min(W_plane / W_pat, H_plane / H_pat), dimensionless."""
        w_pat, h_pat = self.pattern_size_m
        return min(self.plane_size_m[0] / w_pat, self.plane_size_m[1] / h_pat)

    @property
    def circle_diameter_m(self) -> float:
        """D_circle^sim = D_circle k S, metres in the scene."""
        return self.circle_diameter_mm * MM * self.scale

    @property
    def center_distance_m(self) -> float:
        """D_centers^sim = D_centers k S, metres in the scene."""
        return self.center_distance_mm * MM * self.scale

    # -- geometry --------------------------------------------------------------------------
    @property
    def n_points(self) -> int:
        """Number of circles, R * C."""
        return self.rows * self.cols

    @property
    def pattern_shape(self) -> tuple[int, int]:
        """``patternSize`` for ``cv2.findCirclesGrid`` (points per grid row, grid rows).

        OpenCV's asymmetric grid has rows ``s`` apart holding points ``2 s`` apart; here
        those are the board's columns (C of them) holding R circles each.
        """
        return (self.rows, self.cols)

    @property
    def object_points(self) -> np.ndarray:
        """Circle centres, (R*C, 3) float64, metres, board frame, z = 0.

        Ordered column by column (left to right along +x), each column top to bottom
        (along +y): index ``j * R + i`` is circle ``i`` of column ``j``.
        """
        half = 0.5 * self.center_distance_m
        j, i = np.meshgrid(np.arange(self.cols), np.arange(self.rows), indexing="ij")
        x = j * half
        y = (2 * i + (j % 2)) * half
        points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
        # Centre the grid on the plane's origin.
        points[:, 0] -= 0.5 * (self.cols - 1) * half
        points[:, 1] -= 0.5 * (2 * (self.rows - 1) + 1) * half
        return points

    @property
    def plane_corners(self) -> np.ndarray:
        """Corners of the plane, (4, 3) float64, metres, board frame (z = 0)."""
        w, h = 0.5 * np.asarray(self.plane_size_m)
        return np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])

    def circle_outline(self, n: int = 64) -> np.ndarray:
        """Points on every circle's edge, (R*C, n, 3) float64, metres, board frame."""
        angle = np.linspace(0.0, 2.0 * np.pi, positive_int("n", n, 8), endpoint=False)
        r = 0.5 * self.circle_diameter_m
        ring = np.stack([r * np.cos(angle), r * np.sin(angle), np.zeros(n)], axis=1)
        return self.object_points[:, None, :] + ring[None, :, :]

    # -- texture ---------------------------------------------------------------------------
    def texture(
        self, pixel_size_m: float = 1e-4, supersample: int = 4, blur_m: float = 0.0
    ) -> np.ndarray:
        """Draw the board as an albedo texture covering the whole plane.

        Parameters
        ----------
        pixel_size_m : texel size, metres (the default 0.1 mm is about a quarter of a
            camera pixel at 1 m for the default rig).
        supersample : each texel is the mean of ``supersample**2`` point samples of the
            circles, so edges are anti-aliased without shifting any circle's centroid.
        blur_m : standard deviation (metres, board plane) of a Gaussian that softens the
            circle edges, like a slightly defocused lens. A symmetric blur keeps every
            circle's centroid; a soft edge lets a renderer with few samples per pixel
            (4 spp) integrate it accurately.

        Returns
        -------
        (H, W) float32 array in [0, 1]; rows along the board's +y, columns along +x, its
        centre at the board origin (as ``virtus.scene.model.TexturedPlaneObject`` expects).
        """
        pixel = positive("pixel_size_m", pixel_size_m)
        ss = positive_int("supersample", supersample)
        width = int(np.ceil(self.plane_size_m[0] / pixel))
        height = int(np.ceil(self.plane_size_m[1] / pixel))
        # Texel centres span the plane exactly (texel size adjusted per axis).
        step_x = self.plane_size_m[0] / width
        step_y = self.plane_size_m[1] / height
        coverage = np.zeros((height, width), dtype=np.float64)
        radius = 0.5 * self.circle_diameter_m
        offsets = (np.arange(ss) + 0.5) / ss - 0.5
        for cx, cy, _ in self.object_points:
            # Texel index range touching this circle.
            c0 = max(int(np.floor((cx - radius) / step_x + 0.5 * width)) - 1, 0)
            c1 = min(int(np.ceil((cx + radius) / step_x + 0.5 * width)) + 1, width)
            r0 = max(int(np.floor((cy - radius) / step_y + 0.5 * height)) - 1, 0)
            r1 = min(int(np.ceil((cy + radius) / step_y + 0.5 * height)) + 1, height)
            cols = np.arange(c0, c1)
            rows = np.arange(r0, r1)
            xs = (cols[:, None] + 0.5 + offsets[None, :]) * step_x - 0.5 * self.plane_size_m[0]
            ys = (rows[:, None] + 0.5 + offsets[None, :]) * step_y - 0.5 * self.plane_size_m[1]
            dx2 = (xs - cx) ** 2  # (ncols, ss)
            dy2 = (ys - cy) ** 2  # (nrows, ss)
            inside = dy2[:, None, :, None] + dx2[None, :, None, :] <= radius**2
            coverage[r0:r1, c0:c1] += inside.mean(axis=(2, 3))
        coverage = _edge_blur(coverage, blur_m, step_x, step_y)
        levels = self.background_level + (self.circle_level - self.background_level) * coverage
        return levels.astype(np.float32)

    # -- description -----------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain description (JSON-ready), with the derived scene sizes in metres."""
        return {
            "type": self.TYPE,
            "rows": self.rows,
            "cols": self.cols,
            "circle_diameter_mm": self.circle_diameter_mm,
            "center_distance_mm": self.center_distance_mm,
            "border_mm": self.border_mm,
            "plane_size_m": list(self.plane_size_m),
            "circle_level": self.circle_level,
            "background_level": self.background_level,
            "white_on_black": self.light_features,
            "scale": self.scale,
            "circle_diameter_m": self.circle_diameter_m,
            "center_distance_m": self.center_distance_m,
        }

    @classmethod
    def from_dict(cls, data: dict) -> CircleBoard:
        """Inverse of :meth:`to_dict` (derived keys are ignored)."""
        keys = (
            "rows",
            "cols",
            "circle_diameter_mm",
            "center_distance_mm",
            "border_mm",
            "plane_size_m",
            "circle_level",
            "background_level",
        )
        try:
            return cls(**{k: data[k] for k in keys if k in data})
        except TypeError as error:
            raise InputError("board", "a board description", data) from error


@dataclass(frozen=True)
class CheckerBoard:
    """A checkerboard printed on a rectangular plane (OpenCV's ``findChessboardCornersSB``).

    Parameters
    ----------
    rows, cols : inner corners along the board's y and x axes (>= 2 each, ``rows + cols``
        odd so the board is not symmetric under a half turn).
    square_mm : side of a square, millimetres (printed size: no scale equation applies).
    border_mm : light margin around the squares, millimetres (OpenCV's detector needs one).
    plane_size_m : (width, height) of the plane, metres; default: the squares plus the
        border, ``((cols + 1) s + 2 b, (rows + 1) s + 2 b)``.
    dark_level, light_level : texture values (albedo factors in [0, 1]) of the dark squares
        and of the light squares and border. Dark grey (0.25) keeps the fringes decodable
        on the dark squares, as for the circle boards.
    """

    rows: int = 6
    cols: int = 9
    square_mm: float = 20.0
    border_mm: float = 20.0
    plane_size_m: tuple[float, float] | None = None
    dark_level: float = 0.25
    light_level: float = 1.0

    #: Kind of board, as written in :meth:`to_dict`.
    TYPE = "checkerboard"

    def __post_init__(self) -> None:
        positive_int("rows", self.rows, 2)
        positive_int("cols", self.cols, 2)
        if (self.rows + self.cols) % 2 == 0:
            raise InputError(
                "rows, cols",
                "inner corner counts with an odd sum (e.g. 6x9), so the board's orientation "
                "is unambiguous",
                f"{self.rows}x{self.cols}",
            )
        positive("square_mm", self.square_mm)
        if finite("border_mm", self.border_mm) < 0:
            raise InputError("border_mm", "a number >= 0 (mm)", self.border_mm)
        squares = np.array([self.cols + 1, self.rows + 1]) * self.square_mm * MM
        minimum = squares + 2 * self.border_mm * MM
        size = minimum if self.plane_size_m is None else self.plane_size_m
        size = as_float_array("plane_size_m", size, (2,))
        if (size < squares - 1e-12).any():
            raise InputError(
                "plane_size_m", f"a plane that holds the squares ({squares.tolist()} m)", size
            )
        object.__setattr__(self, "plane_size_m", (float(size[0]), float(size[1])))
        for name in ("dark_level", "light_level"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise InputError(name, "a value in [0, 1]", value)
        if self.dark_level >= self.light_level:
            raise InputError(
                "dark_level", f"a value below light_level={self.light_level}", self.dark_level
            )

    @property
    def square_m(self) -> float:
        """Side of a square, metres."""
        return self.square_mm * MM

    @property
    def spacing_m(self) -> float:
        """Distance between neighbouring corners (one square), metres."""
        return self.square_m

    @property
    def center_distance_m(self) -> float:
        """Neighbourhood scale of the projector's local homographies, metres: two squares,
        so :mod:`virtus.calib.projector` fits each corner's homography on a disc one square
        in radius (its four squares)."""
        return 2.0 * self.square_m

    @property
    def n_points(self) -> int:
        """Number of inner corners, rows * cols."""
        return self.rows * self.cols

    @property
    def pattern_shape(self) -> tuple[int, int]:
        """``patternSize`` for ``cv2.findChessboardCornersSB``: (corners per row, rows)."""
        return (self.cols, self.rows)

    @property
    def object_points(self) -> np.ndarray:
        """Inner corners, (rows * cols, 3) float64, metres, board frame, z = 0; row by row
        (along +y), each row along +x: index ``r * cols + c``."""
        r, c = np.meshgrid(np.arange(self.rows), np.arange(self.cols), indexing="ij")
        x = (c.ravel() - 0.5 * (self.cols - 1)) * self.square_m
        y = (r.ravel() - 0.5 * (self.rows - 1)) * self.square_m
        return np.stack([x, y, np.zeros(x.size)], axis=1)

    @property
    def plane_corners(self) -> np.ndarray:
        """Corners of the plane, (4, 3) float64, metres, board frame (z = 0)."""
        w, h = 0.5 * np.asarray(self.plane_size_m)
        return np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])

    def square_centres(self) -> np.ndarray:
        """Centres of the squares, ((rows + 1) * (cols + 1), 2) float64, metres, board frame,
        row by row, and whether each is dark (bool array of the same length)."""
        r, c = np.meshgrid(np.arange(self.rows + 1), np.arange(self.cols + 1), indexing="ij")
        x = (c.ravel() - 0.5 * self.cols) * self.square_m
        y = (r.ravel() - 0.5 * self.rows) * self.square_m
        return np.stack([x, y], axis=1), (r.ravel() + c.ravel()) % 2 == 0

    def texture(
        self, pixel_size_m: float = 1e-4, supersample: int = 4, blur_m: float = 0.0
    ) -> np.ndarray:
        """Draw the board as an albedo texture covering the whole plane.

        Each texel holds the exact area fraction of dark squares it covers (box filter; the
        squares are axis-aligned, so the fraction is separable per axis), optionally
        softened by a Gaussian of ``blur_m`` (m); ``supersample`` is accepted for the circle
        boards' signature and not needed here. Layout as :meth:`CircleBoard.texture`:
        (H, W) float32 in [0, 1], rows along +y, columns along +x, centred on the origin.
        """
        pixel = positive("pixel_size_m", pixel_size_m)
        positive_int("supersample", supersample)
        width_m, height_m = self.plane_size_m
        width = int(np.ceil(width_m / pixel))
        height = int(np.ceil(height_m / pixel))
        s = self.square_m
        fx = _cell_fractions(width, width_m, self.cols + 1, s)
        fy = _cell_fractions(height, height_m, self.rows + 1, s)
        # dark squares: even + even or odd + odd cell indices
        coverage = np.outer(fy[0], fx[0]) + np.outer(fy[1], fx[1])
        coverage = _edge_blur(coverage, blur_m, width_m / width, height_m / height)
        levels = self.light_level + (self.dark_level - self.light_level) * coverage
        return levels.astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """Plain description (JSON-ready)."""
        return {
            "type": self.TYPE,
            "rows": self.rows,
            "cols": self.cols,
            "square_mm": self.square_mm,
            "border_mm": self.border_mm,
            "plane_size_m": list(self.plane_size_m),  # type: ignore[arg-type]
            "dark_level": self.dark_level,
            "light_level": self.light_level,
        }

    @classmethod
    def from_dict(cls, data: dict) -> CheckerBoard:
        """Inverse of :meth:`to_dict`."""
        keys = ("rows", "cols", "square_mm", "border_mm", "plane_size_m", "dark_level")
        keys += ("light_level",)
        try:
            return cls(**{k: data[k] for k in keys if k in data})
        except TypeError as error:
            raise InputError("board", "a checkerboard description", data) from error


#: Any calibration board.
Board = CircleBoard | CheckerBoard


def _cell_fractions(texels: int, length_m: float, cells: int, cell_m: float) -> np.ndarray:
    """Fractions of each texel (of ``texels`` spanning ``length_m``, centred on 0) covered by
    the even and the odd ones of ``cells`` cells of ``cell_m`` centred on 0: (2, texels)."""
    edges = (np.arange(texels + 1) / texels - 0.5) * length_m
    start = -0.5 * cells * cell_m
    out = np.zeros((2, texels))
    for k in range(cells):
        lo, hi = start + k * cell_m, start + (k + 1) * cell_m
        covered = np.clip(np.minimum(edges[1:], hi) - np.maximum(edges[:-1], lo), 0.0, None)
        out[k % 2] += covered / np.diff(edges)
    return out


def board_from_dict(data: dict) -> Board:
    """A board from its :meth:`to_dict` (``type`` picks the class; circles by default)."""
    if not isinstance(data, dict):
        raise InputError("board", "a board description (an object)", data)
    kind = data.get("type", CircleBoard.TYPE)
    if kind == CircleBoard.TYPE:
        return CircleBoard.from_dict(data)
    if kind == CheckerBoard.TYPE:
        return CheckerBoard.from_dict(data)
    raise InputError("board.type", f"{CircleBoard.TYPE!r} or {CheckerBoard.TYPE!r}", kind)


_SPEC_FORMS = (
    "'ROWSxCOLS' (the paper's circle boards, e.g. '7x13'), "
    "'circles:ROWSxCOLS,spacing_mm=S,diameter_mm=D[,border_mm=B][,white_on_black]', "
    "'checker:ROWSxCOLS,square_mm=S[,border_mm=B]' or a board .json/.yaml file"
)


def board_from_spec(
    spec: str | Path | Board, plane_size_m: tuple[float, float] | None = None
) -> Board:
    """Build a board from a spec (module docstring) or return a given board.

    ``"ROWSxCOLS"`` (e.g. ``"4x7"``) is the paper's circle board: the printed pattern keeps
    the default proportions (D_circle = D_centers / 2, border = D_centers / 2) and the
    paper's scale equations fit it onto the plane (default 0.2 m x 0.2 m, which keeps every
    paper pose inside the common field of the default rig). ``circles:`` and ``checker:``
    describe printed boards at their true size (millimetres, S = 1; the plane is the
    pattern with its border unless ``plane_size_m`` is given).
    """
    if isinstance(spec, CircleBoard | CheckerBoard):
        return spec
    text = str(spec).strip()
    if Path(text).suffix.lower() in (".json", ".yaml", ".yml"):
        from virtus.io.safeio import read_json, read_yaml

        path = Path(text)
        if path.suffix.lower() == ".json":
            data = read_json(path, "board", expect=dict)
        else:
            data = read_yaml(path, "board", expect=dict)
        return board_from_dict(data)
    match = re.fullmatch(r"(\d+)\s*[xX]\s*(\d+)", text)
    if match is not None:
        rows, cols = int(match.group(1)), int(match.group(2))
        size = (0.2, 0.2) if plane_size_m is None else plane_size_m
        return CircleBoard(rows=rows, cols=cols, plane_size_m=size)
    match = re.fullmatch(r"(circles|checker):\s*(\d+)\s*[xX]\s*(\d+)((?:\s*,[^,]*)*)", text)
    if match is None:
        raise InputError("board", _SPEC_FORMS, spec)
    kind, rows, cols = match.group(1), int(match.group(2)), int(match.group(3))
    options: dict[str, Any] = {}
    for item in filter(None, (part.strip() for part in match.group(4).split(","))):
        key, equals, value = item.partition("=")
        key = key.strip().replace("-", "_")
        options[key] = _spec_option(key, value.strip()) if equals else True
    allowed = (
        {"spacing_mm", "diameter_mm", "border_mm", "white_on_black"}
        if kind == "circles"
        else {"square_mm", "border_mm"}
    )
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise InputError("board", f"options among {sorted(allowed)}", unknown)
    for key, value in options.items():  # a length given as a bare word, a flag given a value
        if (key == "white_on_black") != (value is True):
            form = "a flag without '='" if key == "white_on_black" else "'=' and a length in mm"
            raise InputError(f"board {key}", form, _item_text(key, value))
    if kind == "checker":
        if "square_mm" not in options:
            raise InputError("board square_mm", "the square size in mm (no default)", None)
        return CheckerBoard(
            rows=rows,
            cols=cols,
            square_mm=options["square_mm"],
            border_mm=options.get("border_mm", 20.0),
            plane_size_m=plane_size_m,
        )
    missing = [key for key in ("spacing_mm", "diameter_mm") if key not in options]
    if missing:
        raise InputError("board", "spacing_mm and diameter_mm (no defaults)", f"missing {missing}")
    spacing, diameter = options["spacing_mm"], options["diameter_mm"]
    border = options.get("border_mm", spacing / 2)
    w = (2 * border + (cols - 1) * spacing / 2 + diameter) * MM
    h = (2 * border + (rows - 1) * spacing + diameter + spacing / 2) * MM
    levels = (1.0, 0.25) if options.get("white_on_black") else (0.25, 1.0)
    try:
        return CircleBoard(
            rows=rows,
            cols=cols,
            circle_diameter_mm=diameter,
            center_distance_mm=spacing,
            border_mm=border,
            plane_size_m=(w, h) if plane_size_m is None else plane_size_m,
            circle_level=levels[0],
            background_level=levels[1],
        )
    except InputError as error:  # the spec's names, not the dataclass's
        raise InputError(
            f"board {_SPEC_NAMES.get(error.name, error.name)}",
            _spec_words(error.expected),
            error.got,
        ) from None


#: The spec's names of :class:`CircleBoard`'s parameters.
_SPEC_NAMES = {"center_distance_mm": "spacing_mm", "circle_diameter_mm": "diameter_mm"}


def _spec_words(text: str) -> str:
    for name, spec_name in _SPEC_NAMES.items():
        text = text.replace(name, spec_name)
    return text


def _item_text(key: str, value: object) -> str:
    """A spec item as written: ``key`` or ``key=value``."""
    return key if value is True else f"{key}={value:g}"


def _spec_option(key: str, text: str) -> float:
    """The millimetres of a spec item ``key=text``: a finite number, > 0 (``border_mm``:
    >= 0), or :class:`InputError` naming ``board <key>``."""
    name = f"board {key}"
    expected = "a length >= 0 (mm)" if key == "border_mm" else "a length > 0 (mm)"
    try:
        value = float(text)
    except ValueError:
        raise InputError(name, expected, text) from None
    if not np.isfinite(value) or value < 0 or (value == 0 and key != "border_mm"):
        raise InputError(name, expected, text)
    return value
