"""The house rules of DESIGN.md section 1, checked on the source.

* Lower floors never import higher ones (:data:`LAYERS`, drawn in the README).
* No import cycle between modules, even within one floor.
* ``pipeline`` and ``data`` never import each other; a job imports another job only where
  :data:`COMPOSES` says so.
* Nothing under ``capture``, ``patterns``, ``reconstruct`` or ``calib`` imports
  ``virtus.render``, at the top or inside a function; only ``virtus.render`` imports Mitsuba
  or Dr.Jit.
* ``cli`` imports only names a package lists in its ``__all__``.
* No module over 800 lines, function over 100 or class over 400 (docstrings aside), except
  the entries of :data:`ALLOWED`, each with its reason (the list may only shrink).

Each rule is a function of the parsed tree, so the tests of the tests below plant a violation
in a copy and see it caught.
"""

from __future__ import annotations

import ast
import shutil
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "virtus"

#: Floors from the bottom; a module may import its own floor and those below it. Keys are
#: names relative to ``virtus`` (a package name covers its sub-modules).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("__init__", "errors", "checks", "paper", "allocator"),
    ("io",),
    ("geometry",),
    ("patterns", "sensor", "scene"),
    ("capture", "reconstruct", "metrology", "calib", "twin", "uncertainty"),
    ("render",),
    ("scanner",),
    ("pipeline", "data"),
    # Job-level packages built on the jobs and the datasets: the acceptance test and design
    # sweeps, robots, learning, and the report that shows any run.
    ("design", "robot", "learn", "report"),
    ("cli", "__main__"),
)
#: Floor packages that may not import each other although they share a floor.
SEPARATE = (("pipeline", "data"),)
#: Jobs that run other jobs: job -> the jobs it may import.
COMPOSES: dict[str, tuple[str, ...]] = {
    "pipeline.demo": ("pipeline.calibrate", "pipeline.scan"),
    "pipeline.scan": ("pipeline.capture",),
    "pipeline.turntable": ("pipeline.scan",),
    "pipeline.twin": ("pipeline.calibrate",),
}
#: Modules of ``pipeline`` that are not jobs (shared by the jobs).
PIPELINE_SHARED = ("pipeline", "pipeline.inputs")
#: Packages that must never reach the renderer, not even inside a function.
RENDER_FREE = ("capture", "patterns", "reconstruct", "calib", "uncertainty")
#: Third-party packages only the renderer may import.
RENDERER_ONLY = ("mitsuba", "drjit")
MAX_MODULE_LINES, MAX_FUNCTION_LINES, MAX_CLASS_LINES = 800, 100, 400
#: Oversized modules, functions and classes that stay so, with the reason. Only shrinks.
ALLOWED: dict[str, str] = {
    "module scene.model": "every scene object's validated model and its YAML",
    "class data.store.DatasetStore": "the store's layout, writing, reading and checking",
    "function data.config.DatasetConfig.from_dict": "one validation per section of the "
    "dataset file, in the file's order: split, the schema would be read in pieces",
    "function pipeline.demo._run": "the paper's experiment step by step (calibrate, capture, "
    "reconstruct, fit, compare, write), each step a library call",
}


def _layer(module: str) -> int:
    top = module.split(".")[0]
    for level, names in enumerate(LAYERS):
        if top in names:
            return level
    raise AssertionError(f"virtus.{module} is in no layer: add it to LAYERS")


def _modules(package: Path = PACKAGE) -> list[tuple[str, Path]]:
    out = []
    for path in sorted(package.rglob("*.py")):
        parts = path.relative_to(package).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" and len(parts) > 1 else parts)
        out.append((name, path))
    return out


@dataclass(frozen=True)
class Imported:
    module: str  #: the imported module, ``virtus.``-relative when it is ours
    names: tuple[str, ...]  #: names taken from it (``from m import a, b``)
    nested: bool  #: inside a function


def _resolve(name: str, package: Path) -> str:
    """The module a dotted ``virtus.`` name refers to (an attribute's module for ``a.b.c``)."""
    parts = name.split(".")
    while parts:
        base = package.joinpath(*parts)
        if base.with_suffix(".py").is_file() or (base / "__init__.py").is_file():
            return ".".join(parts)
        parts.pop()
    return name


def _imports(path: Path, package: Path = PACKAGE) -> list[Imported]:
    """Every import of a module, at any depth (function-level imports included); ``virtus``
    modules are given relative to the package."""
    tree = ast.parse(path.read_text(), str(path))
    nested = {
        id(node)
        for fn in ast.walk(tree)
        if isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef)
        for node in ast.walk(fn)
    }
    out = []
    for node in ast.walk(tree):
        inner = id(node) in nested
        if isinstance(node, ast.Import):
            for alias in node.names:
                name = alias.name
                if name.startswith("virtus."):
                    name = _resolve(name.removeprefix("virtus."), package)
                out.append(Imported(name, (), inner))
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = tuple(alias.name for alias in node.names)
            if node.module == "virtus":
                for alias in names:  # from virtus import paper (a module) or __version__
                    sub = package / alias
                    if sub.with_suffix(".py").is_file() or (sub / "__init__.py").is_file():
                        out.append(Imported(alias, (), inner))
                    else:
                        out.append(Imported("__init__", (alias,), inner))
            elif node.module.startswith("virtus."):
                module = _resolve(node.module.removeprefix("virtus."), package)
                for alias in names:  # from virtus.patterns import phase (a module)
                    sub = package.joinpath(*module.split("."), alias)
                    if sub.with_suffix(".py").is_file() or (sub / "__init__.py").is_file():
                        out.append(Imported(f"{module}.{alias}", (), inner))
                out.append(Imported(module, names, inner))
            else:
                out.append(Imported(node.module, names, inner))
    return out


def _ours(imported: list[Imported]) -> list[Imported]:
    return [i for i in imported if i.module.split(".")[0] not in RENDERER_ONLY + ("virtus",)
            and _is_ours(i.module)]  # fmt: skip


def _is_ours(module: str) -> bool:
    return any(module.split(".")[0] in names for names in LAYERS)


def upward_imports(module: str, imported: list[Imported]) -> list[str]:
    own = _layer(module)
    return [i.module for i in _ours(imported) if _layer(i.module) > own]


def separated_imports(module: str, imported: list[Imported]) -> list[str]:
    top = module.split(".")[0]
    bad = []
    for pair in SEPARATE:
        if top in pair:
            others = [p for p in pair if p != top]
            bad += [i.module for i in _ours(imported) if i.module.split(".")[0] in others]
    return bad


def job_imports(module: str, imported: list[Imported]) -> list[str]:
    """Jobs this job imports that :data:`COMPOSES` does not allow."""
    if not module.startswith("pipeline.") or module in PIPELINE_SHARED:
        return []
    allowed = COMPOSES.get(module, ())
    return [
        i.module
        for i in _ours(imported)
        if i.module.startswith("pipeline.")
        and i.module not in PIPELINE_SHARED
        and i.module != module
        and i.module not in allowed
    ]


def render_imports(module: str, imported: list[Imported]) -> list[str]:
    if module.split(".")[0] not in RENDER_FREE:
        return []
    return [i.module for i in imported if i.module == "render" or i.module.startswith("render.")]


def _package_all(module: str, package: Path) -> set[str] | None:
    """The ``__all__`` of a ``virtus`` module or package, or None if it has none."""
    base = package.joinpath(*module.split("."))
    path = base / "__init__.py" if (base / "__init__.py").is_file() else base.with_suffix(".py")
    if not path.is_file():
        return None
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return set(ast.literal_eval(node.value))
    return None


def cli_private_imports(module: str, imported: list[Imported], package: Path) -> list[str]:
    """Names ``cli`` takes from our modules that those modules do not list in ``__all__``."""
    if module.split(".")[0] != "cli":
        return []
    bad = []
    for i in _ours(imported):
        if i.module.split(".")[0] == "cli" or not i.names:
            continue
        public = _package_all(i.module, package)
        base = package.joinpath(*i.module.split("."))
        bad += [
            f"{i.module}.{n}"
            for n in i.names
            if (public is None or n not in public)
            and not (base / f"{n}.py").is_file()  # a module: from virtus.capture import scandir
        ]
    return bad


def _docstring_lines(node: ast.AST) -> int:
    body = getattr(node, "body", [])
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        if isinstance(body[0].value.value, str):
            return body[0].end_lineno - body[0].lineno + 1
    return 0


def oversized(module: str, path: Path) -> list[str]:
    """``module NAME``, ``function NAME`` and ``class NAME`` entries over the limits (a
    module's lines; a function's or class's lines less its own docstring)."""
    text = path.read_text()
    found = []
    if len(text.splitlines()) > MAX_MODULE_LINES:
        found.append(f"module {module}")

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                name = f"{prefix}.{child.name}"
                lines = child.end_lineno - child.lineno + 1 - _docstring_lines(child)
                is_class = isinstance(child, ast.ClassDef)
                if lines > (MAX_CLASS_LINES if is_class else MAX_FUNCTION_LINES):
                    found.append(f"{'class' if is_class else 'function'} {name}")
                visit(child, name)

    visit(ast.parse(text), module)
    return found


def import_cycles(package: Path = PACKAGE) -> list[list[str]]:
    """Cycles of module-level imports between ``virtus`` modules (function-level imports
    break cycles at run time and are left out; a package's ``__init__`` counts as itself)."""
    graph: dict[str, set[str]] = {}
    for module, path in _modules(package):
        graph[module] = {
            i.module
            for i in _imports(path, package)
            if not i.nested and _is_ours(i.module) and i.module != module
            and not module.startswith(i.module + ".")  # a module importing its own package face
        }  # fmt: skip
    cycles, state = [], {}

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                cycles.append([*stack[stack.index(nxt) :], nxt])
            elif nxt not in state:
                visit(nxt, [*stack, nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    return cycles


_MODULES = _modules()


@pytest.mark.parametrize(("module", "path"), _MODULES, ids=[m for m, _ in _MODULES])
def test_the_house_rules_hold(module, path) -> None:
    imported = _imports(path)
    assert not upward_imports(module, imported), f"virtus.{module} imports a higher floor"
    assert not separated_imports(module, imported), f"virtus.{module}: pipeline <-> data"
    assert not job_imports(module, imported), f"virtus.{module} imports a job: see COMPOSES"
    assert not render_imports(module, imported), f"virtus.{module} imports virtus.render"
    assert not cli_private_imports(module, imported, PACKAGE), f"virtus.{module}: not __all__"
    if module != "render" and not module.startswith("render."):
        foreign = [i.module for i in imported if i.module.split(".")[0] in RENDERER_ONLY]
        assert not foreign, f"virtus.{module} imports {foreign}: only virtus.render may"
    over = [entry for entry in oversized(module, path) if entry not in ALLOWED]
    assert not over, f"over the size limits (add a reason to ALLOWED or split): {over}"


def test_no_import_cycles() -> None:
    assert import_cycles() == []


#: How many entries :data:`ALLOWED` had when it was written; lower it as entries go.
ALLOWED_AT_MOST = 4


def test_the_size_allow_list_only_names_what_is_oversized() -> None:
    assert len(ALLOWED) <= ALLOWED_AT_MOST, "the allow-list may only shrink"
    found = {entry for module, path in _MODULES for entry in oversized(module, path)}
    assert not set(ALLOWED) - found, f"ALLOWED entries no longer needed: {set(ALLOWED) - found}"


# -- tests of the tests: each rule, planted in a copy of the tree, is caught ------------------


@pytest.fixture(scope="module")
def tree_copy(tmp_path_factory) -> Path:
    copy = tmp_path_factory.mktemp("house") / "virtus"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    return copy


def _plant(tree: Path, relative: str, text: str, rule) -> list[str]:
    """What ``rule(module, imports)`` finds in ``relative`` of ``tree`` once ``text`` is
    appended to it, less what it found before (the tree's own state does not matter)."""
    path = tree / relative
    module = ".".join(Path(relative).with_suffix("").parts)
    before = set(rule(module, _imports(path, tree)))
    path.write_text(path.read_text() + "\n" + text)
    return sorted(set(rule(module, _imports(path, tree))) - before)


def test_a_scene_usd_cycle_is_caught(tree_copy, tmp_path) -> None:
    # The cycle the re-plan removed: scene.model reading USD, twin.usd reading scenes.
    tree = tmp_path / "virtus"
    shutil.copytree(tree_copy, tree)
    for relative, text in (
        ("scene/model.py", "from virtus.twin.usd import load_usd_scene\n"),
        ("twin/usd.py", "from virtus.scene.model import Scene\n"),
    ):
        (tree / relative).write_text((tree / relative).read_text() + "\n" + text)
    assert any("scene.model" in c and "twin.usd" in c for c in import_cycles(tree))


def test_a_planted_upward_import_is_caught(tree_copy) -> None:
    text = "def f():\n    from virtus.scanner import X\n"
    assert _plant(tree_copy, "geometry/optics.py", text, upward_imports) == ["scanner"]


def test_a_planted_data_to_pipeline_import_is_caught(tree_copy) -> None:
    text = "from virtus.pipeline.scan import scan\n"
    assert _plant(tree_copy, "data/config.py", text, separated_imports) == ["pipeline.scan"]


def test_a_planted_job_to_job_import_is_caught(tree_copy) -> None:
    text = "from virtus.pipeline.twin import X\n"
    assert _plant(tree_copy, "pipeline/ablation.py", text, job_imports) == ["pipeline.twin"]


def test_a_planted_render_import_below_the_renderer_is_caught(tree_copy) -> None:
    text = "def f():\n    import virtus.render.tracing\n"
    assert _plant(tree_copy, "calib/io.py", text, render_imports) == ["render.tracing"]


def test_a_planted_private_cli_import_is_caught(tree_copy) -> None:
    text = "from virtus.pipeline.calibrate import _solve\n"

    def rule(module: str, imported: list[Imported]) -> list[str]:
        return cli_private_imports(module, imported, tree_copy)

    assert _plant(tree_copy, "cli/rig_cmd.py", text, rule) == ["pipeline.calibrate._solve"]


def test_a_planted_900_line_module_is_caught(tree_copy) -> None:
    path = tree_copy / "io" / "big.py"
    path.write_text("x = 1\n" * 900)
    assert oversized("io.big", path) == ["module io.big"]
    path.write_text("def f():\n" + "    x = 1\n" * 120)
    assert oversized("io.big", path) == ["function io.big.f"]
