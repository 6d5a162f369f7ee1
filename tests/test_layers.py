"""The package's layers (docs/architecture.md "Layers") hold in the import graph.

The layer order is read from the table in docs/architecture.md, so the document and
the code cannot drift apart: every module under src/dynslam2d must belong to a row,
and no module imports a module of a higher row at module level. Imports inside a
function (run on use, so they cannot form an import loop) may go upward only where
listed in :data:`ALLOWED_LOCAL_UPWARD`, the same list as the document's
"Known upward imports".
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "dynslam2d"
DOC = ROOT / "docs" / "architecture.md"

#: Upward imports inside a function body: (importing module, imported module).
ALLOWED_LOCAL_UPWARD = {
    # open_source's old home keeps it reachable for existing code (PEP 562 module __getattr__).
    ("dynslam2d.io.sources", "dynslam2d.inputs"),
    # the offline clean-up measures distances to walls with the map metrics' distance transform.
    ("dynslam2d.slam.cleanup", "dynslam2d.eval.maps"),
    # the paper experiment runs its settings through the batch process pool.
    ("dynslam2d.experiments", "dynslam2d.batch.engine"),
}


def doc_rows(text: str) -> list[str]:
    """The rows of the layers table in docs/architecture.md, bottom first."""
    section = text.split("## Layers", 1)[1].split("\n## ", 1)[0]
    return [line for line in section.splitlines() if line.startswith("|")][2:]  # header, rule


def doc_layers(text: str) -> dict[str, int]:
    """Top-level module / package name -> row index (0 = bottom), from the layers table."""
    rows = doc_rows(text)
    layers: dict[str, int] = {"__init__": 0}  # the package root re-exports value types
    for i, row in enumerate(rows):
        modules_cell = row.split("|")[2]
        for name in re.findall(r"`([A-Za-z_][\w]*)(?:\.py|/)`", modules_cell):
            assert name not in layers or name == "__init__", f"{name} is in two rows of the layers table"
            layers[name] = i
    return layers


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(source: str, module: str, is_package: bool = False) -> list[tuple[str, bool]]:
    """``(imported dynslam2d module, inside a function or class body)`` for every import in ``source``.

    Module level includes ``if``/``try`` blocks (``TYPE_CHECKING`` too) at the top of the file.
    """
    out: list[tuple[str, bool]] = []

    def targets(node: ast.Import | ast.ImportFrom) -> list[str]:
        if isinstance(node, ast.Import):
            return [a.name for a in node.names]
        base = node.module or ""
        if node.level:
            pkg = module.split(".") if is_package else module.split(".")[:-1]
            pkg = pkg[: len(pkg) - (node.level - 1)]
            base = ".".join(pkg + ([node.module] if node.module else []))
        # ``from dynslam2d.io import sources`` imports the submodule, ``from x import f`` the module x
        return [f"{base}.{a.name}" if _is_module(f"{base}.{a.name}") else base for a in node.names]

    def walk(body: list[ast.stmt], local: bool) -> None:
        for stmt in body:
            if isinstance(stmt, (ast.Import, ast.ImportFrom)):
                out.extend((t, local) for t in targets(stmt))
            elif isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.Lambda)):
                for node in ast.walk(stmt):
                    if isinstance(node, (ast.Import, ast.ImportFrom)):
                        out.extend((t, True) for t in targets(node))
            else:
                for field in ("body", "orelse", "finalbody"):
                    walk(getattr(stmt, field, None) or [], local)
                for handler in getattr(stmt, "handlers", None) or []:
                    walk(handler.body, local)

    walk(ast.parse(source).body, False)
    return [(t, local) for t, local in out if t == "dynslam2d" or t.startswith("dynslam2d.")]


def _is_module(dotted: str) -> bool:
    rel = Path(*dotted.split(".")[1:]) if "." in dotted else Path()
    return (SRC / rel).with_suffix(".py").is_file() or (SRC / rel / "__init__.py").is_file()


def layer_of(module: str, layers: dict[str, int]) -> int:
    parts = module.split(".")
    head = parts[1] if len(parts) > 1 else "__init__"
    if head not in layers:
        raise KeyError(head)
    return layers[head]


def upward(layers: dict[str, int]) -> tuple[list[str], set[tuple[str, str]]]:
    """(module-level upward imports as messages, local upward imports as pairs) over src/dynslam2d."""
    names = [row.split("|")[1].strip() for row in doc_rows(DOC.read_text(encoding="utf-8"))]
    module_level: list[str] = []
    local: set[tuple[str, str]] = set()
    for path in sorted(SRC.rglob("*.py")):
        mod = module_name(path)
        own = layer_of(mod, layers)
        for target, is_local in imports(path.read_text(encoding="utf-8"), mod, path.name == "__init__.py"):
            if layer_of(target, layers) <= own:
                continue
            if is_local:
                local.add((mod, target))
            else:
                module_level.append(f"{mod} (layer of {names[own]}) imports {target} (layer of "
                                    f"{names[layer_of(target, layers)]})")
    return module_level, local


@pytest.fixture(scope="module")
def layers() -> dict[str, int]:
    return doc_layers(DOC.read_text(encoding="utf-8"))


def test_layers_table_lists_every_module(layers):
    missing = sorted({
        module_name(p).split(".")[1] for p in SRC.rglob("*.py") if p.parent != SRC or p.stem != "__init__"
    } - set(layers))
    assert not missing, f"add {missing} to a row of the layers table in docs/architecture.md"
    # the order the document states (bottom to top), in its main steps
    assert layers["types"] < layers["detect"] < layers["filter"] < layers["slam"] < layers["config"]
    assert layers["config"] < layers["pipeline"] < layers["io"] < layers["sim"] < layers["inputs"]
    assert layers["inputs"] < layers["eval"] < layers["viz"] < layers["results"] < layers["cli"]
    assert layers["trajectory"] == layers["types"] and layers["yamlfile"] == layers["config"]


def test_no_module_level_import_goes_up_a_layer(layers):
    module_level, _ = upward(layers)
    assert not module_level, "upward imports at module level:\n" + "\n".join(module_level)


def test_local_upward_imports_are_the_listed_ones(layers):
    _, local = upward(layers)
    assert local - ALLOWED_LOCAL_UPWARD == set(), "new upward import inside a function; list it here and in " \
        "docs/architecture.md 'Known upward imports', or move the code down"
    assert ALLOWED_LOCAL_UPWARD - local == set(), "an allowed upward import is gone: drop it from the list and the doc"
    doc = DOC.read_text(encoding="utf-8").split("Known upward imports", 1)[1].split("\n## ", 1)[0]
    for importer, _imported in ALLOWED_LOCAL_UPWARD:
        path = importer.removeprefix("dynslam2d.").replace(".", "/") + ".py"
        assert f"`{path}`" in doc, f"docs/architecture.md 'Known upward imports' does not name {path}"


def test_the_check_sees_an_upward_import(layers):
    # the same walk over made-up modules: a detector importing the simulator is caught at
    # module level, in a TYPE_CHECKING block, and (as local) inside a function; a relative
    # import is resolved against the importing module's package
    src = (
        "from typing import TYPE_CHECKING\n"
        "import numpy as np\n"
        "from dynslam2d.sim import SimSource\n"
        "if TYPE_CHECKING:\n    from dynslam2d.pipeline import Pipeline\n"
        "from ..io import sources\n"
        "from . import kernels\n"
        "def f():\n    from dynslam2d.viz.figures import write_figures\n"
    )
    found = imports(src, "dynslam2d.detect.shapes")
    assert found == [("dynslam2d.sim", False), ("dynslam2d.pipeline", False), ("dynslam2d.io.sources", False),
                     ("dynslam2d.detect.kernels", False), ("dynslam2d.viz.figures", True)]
    own = layer_of("dynslam2d.detect.shapes", layers)
    assert [layer_of(t, layers) > own for t, _ in found] == [True, True, True, False, True]


def test_io_sources_open_source_still_opens_both_kinds():
    # the old import path is the same function as the new one, and the recording reader alone
    # refuses a simulated scenario with a message that names the fix
    from dynslam2d.errors import DynSlamError
    from dynslam2d.inputs import open_source
    from dynslam2d.io import sources

    assert sources.open_source is open_source
    assert open_source("sim:paper", duration=0.5).meta.format == "sim"
    with pytest.raises(DynSlamError, match="dynslam2d.inputs.open_source"):
        sources.open_recording("sim:paper")
