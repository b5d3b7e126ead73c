"""Page assembly: text escaped, figures inlined, ids unique, nothing fetched from anywhere."""

from __future__ import annotations

import re

import numpy as np
import pytest

from virtus.report.html import Page, flatten, format_value
from virtus.report.viewer import pack_cloud

_PNG = (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x01\x00\x00\x00\x01\x08\x06\x00"
        b"\x00\x00\x1f\x15\xc4\x89\x00\x00\x00\rIDATx\x9cc\xf8\x0f\x00\x00\x01\x01\x00\x05\x18"
        b"\xd8N\x00\x00\x00\x00IEND\xaeB`\x82")  # fmt: skip


def test_a_page_is_self_contained_and_escaped() -> None:
    page = Page("run <b>", "sub & title")
    section = page.section("Decode: <maps>")
    section.figure("phase", _PNG, "phase <in> rad")
    with pytest.raises(ValueError, match="added twice"):
        section.figure("phase", _PNG, "again")  # one id per figure
    section.table("t", {"a": {"b": 1.23456789}, "c": "<script>"})
    section.links("files", [("points", "points.ply"), ("part", "#decode-maps")])
    text = page.render()
    assert "<b>" not in text.split("<body>")[1].split("<main>")[0]
    assert "&lt;script&gt;" in text and "<script>" not in text  # no viewer: no script at all
    assert re.findall(r'src="([^"]+)"', text) and all(
        s.startswith("data:image/png;base64,") for s in re.findall(r'src="([^"]+)"', text)
    )
    assert "http:" not in text and "https:" not in text
    assert not re.search(r"""(src|href)=["']?//""", text)  # no protocol-relative address
    assert 'id="decode-maps"' in text and "fig-decode-maps-phase" in text
    assert page.figures == ["fig-decode-maps-phase"]
    assert "Content-Security-Policy" in text and "default-src 'none'" in text


def test_a_cloud_brings_the_viewer_and_its_still() -> None:
    page = Page("p", "s")
    view = pack_cloud(np.array([[0.0, 0.0, 1.0], [0.1, 0.1, 1.2]]), None, "depth")
    page.section("3D view").cloud("cloud", view, "points")
    text = page.render()
    assert text.count("<script>") == 1 and 'class="virtus-still"' in text
    assert 'id="view-3d-view-cloud"' in text and page.figures == ["view-3d-view-cloud"]


def test_section_keys_are_unique() -> None:
    page = Page("p", "s")
    a, b = page.section("Decode"), page.section("Decode")
    assert a.key != b.key


def test_values_read_well() -> None:
    assert flatten({"a": {"b": {"c": 1}}, "d": 2}) == [("a.b.c", 1), ("d", 2)]
    assert format_value(0.1234567891) == "0.123457"
    assert format_value(None) == "-" and format_value(True) == "yes"
    assert format_value(list(range(20))).endswith("(20 items)]")
