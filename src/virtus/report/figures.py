"""Report figures: matplotlib PNGs with labelled units and one colour map per quantity.

Every figure is drawn on its own :class:`matplotlib.figure.Figure` (no pyplot state, the
Agg canvas) and returned as PNG bytes without time stamps or software tags, so the same
data give the same bytes. Each quantity has one colour map everywhere (:data:`QUANTITIES`):
a reader who learnt that ``RdBu_r`` is signed error in mm in one figure reads it so in all.

Images are ``(H, W)`` arrays indexed ``[row, col]``; axes are drawn in camera pixels with the
OpenCV convention (centre of the top-left pixel at (0, 0), ``v`` growing downwards).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "QUANTITIES",
    "Quantity",
    "bar_chart",
    "histogram_chart",
    "image_map",
    "mask_overlay",
    "png_bytes",
    "scatter_fields",
    "poses_3d",
    "vector_field",
]


@dataclass(frozen=True)
class Quantity:
    """How one physical quantity is drawn: its label with unit, colour map, and whether its
    colour scale is symmetric about zero (signed errors)."""

    label: str
    cmap: str
    symmetric: bool = False


#: The colour map and unit of every quantity a report draws (one per quantity).
QUANTITIES: dict[str, Quantity] = {
    "intensity": Quantity("intensity (DN)", "gray"),
    "wrapped_phase": Quantity("wrapped phase (rad)", "twilight"),
    "absolute_phase": Quantity("absolute phase (rad)", "viridis"),
    "modulation": Quantity("modulation B (DN)", "magma"),
    "depth": Quantity("depth z (mm)", "turbo"),
    "signed_error": Quantity("signed error (mm)", "RdBu_r", symmetric=True),
    "difference": Quantity("difference (real − twin)", "RdBu_r", symmetric=True),
    "proj_distance": Quantity("distance (proj. px)", "inferno"),
    "proj_u": Quantity("projector column u_p (proj. px)", "viridis"),
    "sigma_px": Quantity("predicted σ (proj. px)", "YlOrBr"),
    "sigma_um": Quantity("predicted σ (µm)", "cividis"),
}

#: Figure width (inches) and resolution: 6.4 in at 80 dpi = 512 px wide.
_WIDTH_IN = 6.4
_DPI = 80


def _figure(width: float = _WIDTH_IN, height: float = 4.8) -> Any:
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), dpi=_DPI)
    figure.subplots_adjust(left=0.12, right=0.95, bottom=0.13, top=0.9, wspace=0.35)
    return figure


def png_bytes(figure: Any) -> bytes:
    """The figure as PNG bytes, without metadata (identical data give identical bytes)."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=_DPI, metadata={"Software": None})
    return buffer.getvalue()


def _limits(values: np.ndarray, quantity: Quantity, limits: tuple[float, float] | None):
    if limits is not None:
        return limits
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return (-1.0, 1.0) if quantity.symmetric else (0.0, 1.0)
    if quantity.symmetric:
        bound = float(np.percentile(np.abs(finite), 99.5)) or 1.0
        return -bound, bound
    low, high = np.percentile(finite, [0.5, 99.5])
    return float(low), float(high) if high > low else float(low) + 1.0


def image_map(
    values: np.ndarray,
    quantity: str,
    title: str,
    *,
    limits: tuple[float, float] | None = None,
) -> bytes:
    """An ``(H, W)`` map drawn with the quantity's colour map and a labelled colour bar;
    NaN pixels (no data) are light grey. Limits: the 0.5-99.5 percentiles (symmetric
    quantities: +-99.5th percentile of the magnitude) unless given."""
    spec = QUANTITIES[quantity]
    data = np.asarray(values, dtype=np.float64)
    low, high = _limits(data, spec, limits)
    figure = _figure()
    axes = figure.add_subplot()
    from matplotlib import colormaps

    cmap = colormaps[spec.cmap].with_extremes(bad="#d9d9d9")
    shown = axes.imshow(np.ma.masked_invalid(data), cmap=cmap, vmin=low, vmax=high,
                        interpolation="nearest")  # fmt: skip
    figure.colorbar(shown, ax=axes, label=spec.label, shrink=0.9)
    axes.set_title(title)
    axes.set_xlabel("u (camera px)")
    axes.set_ylabel("v (camera px)")
    return png_bytes(figure)


def mask_overlay(
    base: np.ndarray, layers: Sequence[tuple[np.ndarray, str, str]], title: str
) -> bytes:
    """A grey image with boolean ``(mask, colour, label)`` layers drawn over it, with a
    legend giving each layer's pixel count."""
    from matplotlib.patches import Patch

    data = np.asarray(base, dtype=np.float64)
    finite = data[np.isfinite(data)]
    top = float(finite.max()) if finite.size and finite.max() > 0 else 1.0
    rgb = np.repeat(np.nan_to_num(data / top, nan=0.0)[..., None], 3, axis=2) * 0.6
    handles = []
    from matplotlib.colors import to_rgb

    for mask, colour, label in layers:
        mask = np.asarray(mask, dtype=bool)
        rgb[mask] = to_rgb(colour)
        handles.append(Patch(color=colour, label=f"{label} ({int(mask.sum())} px)"))
    figure = _figure()
    axes = figure.add_subplot()
    axes.imshow(np.clip(rgb, 0, 1), interpolation="nearest")
    axes.legend(handles=handles, loc="lower right", fontsize=8)
    axes.set_title(title)
    axes.set_xlabel("u (camera px)")
    axes.set_ylabel("v (camera px)")
    return png_bytes(figure)


def histogram_chart(
    counts: Sequence[float],
    edges: Sequence[float],
    xlabel: str,
    title: str,
    *,
    marks: Sequence[tuple[float, str]] = (),
    note: str = "",
) -> bytes:
    """A histogram from its ``counts`` and ``edges`` (as the metrics files store them),
    vertical lines at ``marks`` ``(value, label)``, and a text box ``note`` (the fit)."""
    counts = np.asarray(counts, dtype=np.float64)
    edges = np.asarray(edges, dtype=np.float64)
    figure = _figure(height=3.8)
    axes = figure.add_subplot()
    axes.stairs(counts, edges, fill=True, color="#4c72b0", alpha=0.8)
    for index, (value, label) in enumerate(marks):
        axes.axvline(value, color=f"C{index + 1}", linestyle="--", label=label)
    if marks:
        axes.legend(fontsize=8, loc="upper left")
    if note:
        axes.text(0.98, 0.97, note, transform=axes.transAxes, ha="right", va="top", fontsize=8,
                  bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "#999999"})  # fmt: skip
    axes.set_xlabel(xlabel)
    axes.set_ylabel("points")
    axes.set_title(title)
    return png_bytes(figure)


def bar_chart(
    names: Sequence[str], series: dict[str, Sequence[float]], ylabel: str, title: str
) -> bytes:
    """Grouped bars: one group per name, one bar per series (label -> values)."""
    figure = _figure(height=3.8)
    axes = figure.add_subplot()
    x = np.arange(len(names))
    width = 0.8 / max(1, len(series))
    for index, (label, values) in enumerate(series.items()):
        values = np.asarray(values, dtype=np.float64)
        axes.bar(x + (index - (len(series) - 1) / 2) * width, values, width, label=label)
    axes.set_xticks(x, list(names), rotation=60, ha="right", fontsize=7)
    figure.subplots_adjust(bottom=0.3)  # room for the rotated names
    axes.set_ylabel(ylabel)
    axes.set_title(title)
    if len(series) > 1:
        axes.legend(fontsize=8)
    return png_bytes(figure)


def scatter_fields(
    panels: Sequence[tuple[str, tuple[int, int], Sequence[tuple[str, np.ndarray]]]],
    title: str,
) -> bytes:
    """Side-by-side image planes, each ``(name, (width, height), [(label, (N, 2) uv)])``:
    where the observed points fall (coverage of each device's field)."""
    figure = _figure(width=_WIDTH_IN * 1.4, height=4.0)
    grid = figure.subplots(1, len(panels), squeeze=False)[0]
    for axes, (name, (width, height), sets) in zip(grid, panels, strict=True):
        for index, (_, uv) in enumerate(sets):
            uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
            axes.plot(uv[:, 0], uv[:, 1], ".", markersize=2, color=f"C{index % 10}")
        _pixel_axes(axes, (width, height), f"{name} ({width}x{height} px)")
    figure.suptitle(title)
    return png_bytes(figure)


def _pixel_axes(axes: Any, size: tuple[int, int], title: str) -> None:
    """Set ``axes`` up as a device's image: pixel centres at integers, v down, square px."""
    width, height = size
    axes.set_xlim(-0.5, width - 0.5)
    axes.set_ylim(height - 0.5, -0.5)
    axes.set_aspect("equal")
    axes.set_title(title, fontsize=9)
    axes.set_xlabel("u (px)")
    axes.set_ylabel("v (px)")


def vector_field(
    panels: Sequence[tuple[str, tuple[int, int], np.ndarray, np.ndarray]], title: str
) -> bytes:
    """Residual vectors per device, each ``(name, (width, height), uv (N, 2) px,
    residual (N, 2) px)``, magnified to be seen; the arrow scale is printed."""
    figure = _figure(width=_WIDTH_IN * 1.4, height=4.0)
    grid = figure.subplots(1, len(panels), squeeze=False)[0]
    for axes, (name, (width, height), uv, residual) in zip(grid, panels, strict=True):
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        residual = np.asarray(residual, dtype=np.float64).reshape(-1, 2)
        size = np.hypot(residual[:, 0], residual[:, 1])
        top = float(np.percentile(size, 99)) if size.size else 0.0
        gain = 0.05 * max(width, height) / top if top > 0 else 1.0
        axes.quiver(uv[:, 0], uv[:, 1], residual[:, 0] * gain, residual[:, 1] * gain,
                    size, cmap="viridis", angles="xy", scale_units="xy", scale=1,
                    width=0.004)  # fmt: skip
        rms = float(np.sqrt(np.mean(size**2))) if size.size else float("nan")
        _pixel_axes(axes, (width, height), f"{name}: RMS {rms:.4f} px, arrows x{gain:.0f}")
    figure.suptitle(title)
    return png_bytes(figure)


def poses_3d(
    devices: Sequence[tuple[str, np.ndarray]],
    boards: Sequence[tuple[str, np.ndarray]],
    title: str,
) -> bytes:
    """Board poses in 3D in the camera frame (mm): each device as its optical centre and
    viewing frustum ``(name, (5, 3) apex + four corners, mm)``, each board as its outline
    ``(name, (4, 3) corners, mm)``. Drawn with y and z swapped so the camera's "down" (+y)
    points down on the page and the optical axis (+z) goes into it."""
    figure = _figure(width=_WIDTH_IN * 1.2, height=5.2)
    axes = figure.add_subplot(projection="3d")

    def draw(points: np.ndarray, **style: Any) -> None:
        points = np.asarray(points, dtype=np.float64)
        axes.plot(points[:, 0], points[:, 2], -points[:, 1], **style)

    for index, (name, frustum) in enumerate(devices):
        apex, corners = frustum[0], frustum[1:]
        colour = ("black", "darkorange")[index % 2]
        for corner in corners:
            draw(np.stack([apex, corner]), color=colour, linewidth=0.8)
        draw(np.vstack([corners, corners[:1]]), color=colour, linewidth=0.8,
             label=name)  # fmt: skip
    for index, (_, outline) in enumerate(boards):
        draw(np.vstack([outline, outline[:1]]), color=f"C{index % 10}", linewidth=1.2)
    axes.set_xlabel("x (mm)")
    axes.set_ylabel("z (mm)")
    axes.set_zlabel("-y (mm)")
    axes.legend(fontsize=8, loc="upper left")
    axes.set_title(title)
    axes.view_init(elev=20, azim=-60)
    return png_bytes(figure)
