"""The house rules of DESIGN.md section 1, checked on the source: lower layers never import
higher ones, and only ``virtus.render`` imports Mitsuba or Dr.Jit."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "virtus"

#: Layers from the bottom; a module may import its own layer and those below it. Keys are
#: module names relative to ``virtus`` (a package name covers its sub-modules).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("__init__", "errors", "checks", "jsonio", "safeio", "paper"),
    ("transforms", "optics", "isaac", "devices"),
    ("phase", "patterns", "sensor", "projection", "groundtruth", "images", "ply", "objects"),
    ("scene", "usd", "twin", "capture", "reconstruct", "metrology", "calib", "runs"),
    ("render",),
    ("scanner",),
    ("pipeline", "data"),
    ("cli", "__main__"),
)
#: Third-party packages only the renderer may import.
RENDERER_ONLY = ("mitsuba", "drjit")


def _layer(module: str) -> int:
    top = module.split(".")[0]
    for level, names in enumerate(LAYERS):
        if top in names:
            return level
    raise AssertionError(f"virtus.{module} is in no layer: add it to LAYERS")


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" and len(parts) > 1 else parts)
        out.append((name, path))
    return out


def _imports(path: Path) -> list[str]:
    """Every imported module name, at any depth (function-level imports included)."""
    names = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
            if node.module == "virtus":  # from virtus import phase (not __version__)
                names += [
                    f"virtus.{alias.name}"
                    for alias in node.names
                    if (PACKAGE / f"{alias.name}.py").is_file() or (PACKAGE / alias.name).is_dir()
                ]
    return names


@pytest.mark.parametrize(("module", "path"), _modules(), ids=[m for m, _ in _modules()])
def test_lower_layers_never_import_higher_ones(module, path) -> None:
    own = _layer(module)
    offenders = [
        name
        for name in _imports(path)
        if name.startswith("virtus.") and _layer(name.removeprefix("virtus.")) > own
    ]
    assert not offenders, f"virtus.{module} (layer {own}) imports higher layers: {offenders}"


@pytest.mark.parametrize(("module", "path"), _modules(), ids=[m for m, _ in _modules()])
def test_only_the_renderer_imports_mitsuba(module, path) -> None:
    if module == "render" or module.startswith("render."):
        return
    offenders = [n for n in _imports(path) if n.split(".")[0] in RENDERER_ONLY]
    assert not offenders, f"virtus.{module} imports {offenders}: only virtus.render may"


def test_the_rules_can_fail(tmp_path) -> None:
    # The checker itself: a calib module importing the pipeline is caught.
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from virtus.pipeline.scan import scan\n    import drjit\n")
    names = _imports(bad)
    assert "virtus.pipeline.scan" in names and "drjit" in names
    assert _layer("pipeline.scan") > _layer("calib.io")
