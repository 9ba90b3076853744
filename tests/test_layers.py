"""The package's layer order (README.md, Layout): each module imports only from its own layer
and the layers below it, and the modules' imports form no cycle."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from pathlib import Path

import ntncontact

SOURCE = Path(ntncontact.__file__).parent

#: bottom to top, as README.md's Layout lists them: a module's first name after
#: ``ntncontact.`` gives its layer ("" is the package itself, which re-exports the public API)
LAYERS = (
    ("package", "jit", "threads"),  # the version and kernel cache, the Numba decorator, threads
    ("mesh",),
    ("materials",),  # before fem: the element kernel evaluates the materials
    ("fem",),
    ("contact",),
    ("ale",),
    ("dynamics",),
    ("solvers",),
    ("engine",),
    ("io",),
    ("report",),
    ("api",),
    ("studies",),  # each case of a sweep is a run through the public API
    ("cli", "warmup"),
    ("",),
)
LAYER_OF = {name: level for level, names in enumerate(LAYERS) for name in names}


def module_name(path: Path) -> str:
    """``ntncontact.fem.assembly`` of ``.../ntncontact/fem/assembly.py``; a package is named by
    its folder."""
    parts = path.relative_to(SOURCE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path for path in sorted(SOURCE.rglob("*.py"))}


def layer(module: str) -> int:
    name = module.split(".")[1] if "." in module else ""
    assert name in LAYER_OF, f"{module}: its layer is not in LAYERS (add it to README too)"
    return LAYER_OF[name]


def imported_modules(module: str, node: ast.AST) -> Iterator[str]:
    """The package's modules an import statement loads: ``from .x import y`` loads the module
    ``x.y`` if there is one, else ``x``."""
    if isinstance(node, ast.Import):
        yield from (alias.name for alias in node.names if alias.name in MODULES)
        return
    assert isinstance(node, ast.ImportFrom)
    if node.level:
        package = module if MODULES[module].name == "__init__.py" else module.rsplit(".", 1)[0]
        base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1])
        source = ".".join(filter(None, (base, node.module)))
    else:
        source = node.module or ""
    if source not in MODULES:
        return
    for alias in node.names:
        yield f"{source}.{alias.name}" if f"{source}.{alias.name}" in MODULES else source


def imports(module: str, *, at_import_only: bool) -> set[str]:
    """The package's modules ``module`` imports; ``at_import_only``: those imported when it is
    (not inside functions, not under ``if TYPE_CHECKING``)."""
    found: set[str] = set()

    def visit(node: ast.AST) -> None:
        skipped = isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda) or (
            isinstance(node, ast.If) and ast.unparse(node.test).endswith("TYPE_CHECKING"))
        if at_import_only and skipped:
            return
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.update(imported_modules(module, node))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(MODULES[module].read_text(encoding="utf-8")))
    return found - {module}


def test_no_module_imports_from_a_layer_above_its_own():
    upward = sorted(f"{module} ({LAYERS[layer(module)][0]}) imports {target} "
                    f"({LAYERS[layer(target)][0]})"
                    for module in MODULES for target in imports(module, at_import_only=False)
                    if layer(target) > layer(module))
    assert not upward, "\n".join(upward)


def cycle_through(start: str, graph: dict[str, set[str]]) -> list[str] | None:
    """A path of imports from ``start`` back to it, or None."""
    stack, seen = [(start, [start])], set()
    while stack:
        module, path = stack.pop()
        for target in sorted(graph[module]):
            if target == start:
                return path + [start]
            if target not in seen:
                seen.add(target)
                stack.append((target, path + [target]))
    return None


def test_the_modules_import_each_other_in_no_cycle():
    graph = {module: imports(module, at_import_only=True) for module in MODULES}
    cycles: list[list[str]] = []
    for module in MODULES:  # one cycle through each module not in one found already
        if not any(module in cycle for cycle in cycles):
            if (cycle := cycle_through(module, graph)) is not None:
                cycles.append(cycle)
    assert not cycles, "\n".join(" -> ".join(cycle) for cycle in cycles)


def test_the_scan_sees_the_imports_it_checks():
    """The scan resolves relative imports of modules and of names (a check that finds nothing
    because it resolves nothing would pass)."""
    assert {"ntncontact.api", "ntncontact.studies.sweep"} <= imports("ntncontact",
                                                                    at_import_only=True)
    assert "ntncontact.materials.models" in imports("ntncontact.fem.assembly",
                                                    at_import_only=True)
    assert "ntncontact.contact" in imports("ntncontact.engine.builder", at_import_only=True)
    assert "ntncontact.mesh.gmsh_io" not in imports("ntncontact.engine.builder",
                                                    at_import_only=True)
    assert "ntncontact.mesh.gmsh_io" in imports("ntncontact.engine.builder",
                                                at_import_only=False)
