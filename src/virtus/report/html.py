"""Page assembly: one self-contained HTML file (figures inlined as base64 ``data:`` URIs,
the 3D viewer's script inline, no external request of any kind).

A :class:`Page` collects :class:`Section` objects; each holds blocks of HTML in order:
figures (:meth:`Section.figure`, each with a stable ``id`` and ``data-figure`` name that the
browser test looks for), tables (:meth:`Section.table`, nested mappings flattened to dotted
keys), notes, links and 3D views. :meth:`Page.render` returns the page's text; the same
content gives the same text (nothing depends on time or the machine).
"""

from __future__ import annotations

import base64
import html
import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

from virtus.report.viewer import VIEWER_JS, CloudView, still_image

__all__ = ["Page", "Section", "flatten", "format_value"]

_CSS = """
body { font-family: system-ui, sans-serif; margin: 0; color: #222; background: #fafafa; }
header { background: #23395d; color: white; padding: 12px 24px; }
header h1 { margin: 0; font-size: 1.4em; }
nav { background: #e8ecf3; padding: 6px 24px; position: sticky; top: 0; z-index: 2; }
nav a { margin-right: 14px; color: #23395d; text-decoration: none; font-size: 0.95em; }
main { padding: 8px 24px 40px; }
section { margin-top: 18px; border-top: 1px solid #ccc; }
h2 { font-size: 1.2em; color: #23395d; }
.figures { display: flex; flex-wrap: wrap; gap: 12px; }
figure { margin: 0; background: white; border: 1px solid #ddd; padding: 6px; }
figure img { display: block; max-width: 100%; }
figcaption { font-size: 0.85em; color: #555; max-width: 512px; }
table { border-collapse: collapse; margin: 8px 12px 8px 0; display: inline-table;
        font-size: 0.88em; background: white; }
td, th { border: 1px solid #ddd; padding: 3px 8px; text-align: left; vertical-align: top; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.note { font-size: 0.9em; color: #444; }
.virtus-cloud { background: white; border: 1px solid #ddd; padding: 6px; display: inline-block; }
.virtus-cloud canvas { width: 640px; height: 480px; display: block; cursor: grab; }
.virtus-still { display: none; }
"""


def format_value(value: Any) -> str:
    """A table cell: floats to 6 significant digits, lists shortened, None as '-'."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return f"{value:.6g}"
    if isinstance(value, (list, tuple)):
        if len(value) > 12:
            shown = ", ".join(format_value(v) for v in value[:12])
            return f"[{shown}, ... ({len(value)} items)]"
        return "[" + ", ".join(format_value(v) for v in value) + "]"
    return str(value)


def flatten(data: Mapping[str, Any], prefix: str = "", depth: int = 4) -> list[tuple[str, Any]]:
    """``{"a": {"b": 1}}`` -> ``[("a.b", 1)]`` down to ``depth`` levels (deeper mappings are
    shown as text)."""
    rows: list[tuple[str, Any]] = []
    for key, value in data.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, Mapping) and depth > 0 and value:
            rows.extend(flatten(value, name, depth - 1))
        else:
            rows.append((name, value))
    return rows


def _slug(text: str) -> str:
    """``"Sphere scan: frames"`` -> ``"sphere-scan-frames"`` (an id/anchor)."""
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


@dataclass
class Section:
    """One part of the page: a heading and its blocks (HTML text, in order)."""

    title: str
    key: str
    blocks: list[str] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)

    def _claim(self, ident: str) -> str:
        if ident in self.figures:
            raise ValueError(f"report figure {ident!r} added twice")
        self.figures.append(ident)
        return ident

    def figure(self, name: str, png: bytes, caption: str) -> None:
        """Add a PNG figure named ``name`` (unique in the page: ``id="fig-<key>-<name>"``)."""
        data = base64.b64encode(png).decode("ascii")
        ident = self._claim(f"fig-{self.key}-{_slug(name)}")
        self.blocks.append(
            f'<figure id="{ident}" data-figure="{html.escape(ident)}">'
            f'<img alt="{html.escape(caption)}" src="data:image/png;base64,{data}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )

    def table(self, title: str, rows: Iterable[tuple[str, Any]] | Mapping[str, Any]) -> None:
        """A two-column table (name, value); a mapping is flattened to dotted names."""
        items = flatten(rows) if isinstance(rows, Mapping) else list(rows)
        body = "".join(
            f"<tr><th>{html.escape(str(k))}</th><td class='num'>{html.escape(format_value(v))}"
            "</td></tr>"
            for k, v in items
        )
        self.blocks.append(f"<table><caption>{html.escape(title)}</caption>{body}</table>")

    def grid(self, title: str, header: list[str], rows: list[list[Any]]) -> None:
        """A table with a header row."""
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join(
            "<tr>"
            + "".join(f"<td class='num'>{html.escape(format_value(v))}</td>" for v in row)
            + "</tr>"
            for row in rows
        )
        self.blocks.append(
            f"<table><caption>{html.escape(title)}</caption><tr>{head}</tr>{body}</table>"
        )

    def note(self, text: str) -> None:
        """A paragraph of plain text."""
        self.blocks.append(f"<p class='note'>{html.escape(text)}</p>")

    def links(self, title: str, targets: Iterable[tuple[str, str]]) -> None:
        """Links ``(text, href)``: relative file paths or ``#anchors`` in the page."""
        items = "".join(
            f"<li><a href='{html.escape(href, quote=True)}'>{html.escape(text)}</a></li>"
            for text, href in targets
        )
        self.blocks.append(f"<p class='note'>{html.escape(title)}</p><ul>{items}</ul>")

    def cloud(self, name: str, view: CloudView, caption: str) -> None:
        """The interactive 3D view of a packed cloud, with its still image (shown instead
        where WebGL is unavailable). The still is a figure too (``<name>-still``)."""
        ident = self._claim(f"view-{self.key}-{_slug(name)}")
        still = base64.b64encode(still_image(view, caption)).decode("ascii")
        shown = f"{view.n_points:,} of {view.n_total:,} points" if view.n_total > view.n_points \
            else f"{view.n_points:,} points"  # fmt: skip
        self.blocks.append(
            f'<div class="virtus-cloud" id="{ident}" data-figure="{ident}">'
            f'<canvas width="640" height="480"></canvas>'
            f'<img class="virtus-still" alt="{html.escape(caption)} (still)" '
            f'src="data:image/png;base64,{still}">'
            f'<script type="application/json" class="virtus-cloud-data">{view.payload()}</script>'
            f"<p class='note'>{html.escape(caption)}: {shown}; colour: "
            f"{html.escape(view.label)}. Drag to turn, wheel to zoom, double-click to reset."
            "</p></div>"
        )

    def render(self) -> str:
        parts = [f'<section id="{self.key}"><h2>{html.escape(self.title)}</h2>']
        figures_open = False
        for block in self.blocks:
            is_figure = block.startswith("<figure")
            if is_figure and not figures_open:
                parts.append('<div class="figures">')
                figures_open = True
            elif not is_figure and figures_open:
                parts.append("</div>")
                figures_open = False
            parts.append(block)
        if figures_open:
            parts.append("</div>")
        parts.append("</section>")
        return "".join(parts)


@dataclass
class Page:
    """The report page: a title, a subtitle line and sections."""

    title: str
    subtitle: str
    sections: list[Section] = field(default_factory=list)

    def section(self, title: str, key: str | None = None) -> Section:
        """Start a new section (its anchor ``key`` defaults to the title's slug)."""
        section = Section(title, key or _slug(title))
        if any(s.key == section.key for s in self.sections):
            section.key = f"{section.key}-{len(self.sections)}"
        self.sections.append(section)
        return section

    @property
    def figures(self) -> list[str]:
        """The ids of every figure and 3D view, in page order."""
        return [ident for section in self.sections for ident in section.figures]

    def render(self) -> str:
        """The whole HTML document."""
        nav = "".join(f'<a href="#{s.key}">{html.escape(s.title)}</a>' for s in self.sections)
        body = "".join(section.render() for section in self.sections)
        has_cloud = any("virtus-cloud" in b for s in self.sections for b in s.blocks)
        script = f"<script>{VIEWER_JS}</script>" if has_cloud else ""
        return (
            "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            "<meta name='viewport' content='width=device-width, initial-scale=1'>"
            "<meta http-equiv='Content-Security-Policy' content=\"default-src 'none'; "
            "img-src data:; style-src 'unsafe-inline'; script-src 'unsafe-inline'\">"
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<header><h1>{html.escape(self.title)}</h1><div>{html.escape(self.subtitle)}</div>"
            f"</header><nav>{nav}</nav><main>{body}</main>{script}</body></html>\n"
        )
