"""The layering that README's "Architecture" section describes, checked on the source.

* no import cycles among the package's modules (module-level and function-level imports);
* the layers' arrows run one way: the model reaches neither the analysis, the methods, the
  command line nor the studies, and the analysis reaches neither the methods, the command line
  nor the studies (directly or through other modules);
* the package's own modules are imported at module top, never inside a function;
* only ``npmrf3d/_kernels/`` imports numba;
* only the torch modules of ``npmrf3d/methods/neural/`` import torch, and they are reached only through
  the one documented lazy import, ``npmrf3d/methods/neural/_extra.py`` (torch is an optional
  extra, so the function-level-import rule above cannot hold for them: ``importlib`` does it);
* every library module stays under ~400 lines or says at its top why not;
* no function outside ``npmrf3d/_kernels/`` is longer than 120 lines (a compiled kernel may be:
  numba inlines nothing across modules, and each helper is another compile);
* every registered method and every method module's ``run`` take ``(per_view, config, rng, *,
  progress=None, checkpoint=None, ...)``.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pathlib

import npmrf3d

PACKAGE = pathlib.Path(npmrf3d.__file__).parent


def _modules() -> dict[str, pathlib.Path]:
    out = {}
    for f in PACKAGE.rglob("*.py"):
        parts = list(f.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


def _imports(name: str, path: pathlib.Path, modules) -> list[tuple[str, ast.AST]]:
    """(imported package module, node) for every import of the package's own modules."""
    base = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            mod = node.module or ""
            if node.level:
                b = base
                for _ in range(node.level - 1):
                    b = b.rpartition(".")[0]
                mod = b + ("." + mod if mod else "")
            subs = [f"{mod}.{a.name}" for a in node.names]
            targets = [t for t in subs if t in modules] or [mod]
        else:
            continue
        for t in targets:
            while t and t not in modules:
                t = t.rpartition(".")[0]
            if t and t != name:
                found.append((t, node))
    return found


def _graph():
    modules = _modules()
    return {m: {t for t, _ in _imports(m, p, modules)} for m, p in modules.items()}


def _cycles(graph) -> list[list[str]]:
    index, low, stack, on, out, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles():
    assert _cycles(_graph()) == []


#: Layer -> the layers above it, which it must never reach through its imports.
LAYERS_ABOVE = {
    "npmrf3d.model": ("npmrf3d.analysis", "npmrf3d.methods", "npmrf3d.cli", "npmrf3d.studies"),
    "npmrf3d.analysis": ("npmrf3d.methods", "npmrf3d.cli", "npmrf3d.studies"),
}


def _inside(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_the_model_and_the_analysis_never_import_a_layer_above_them():
    graph = _graph()
    found = []
    for name in graph:
        for layer, above in LAYERS_ABOVE.items():
            if not _inside(name, layer):
                continue
            reached, stack = set(), [name]
            while stack:  # everything the module imports, directly or through other modules
                for target in graph[stack.pop()]:
                    if target not in reached:
                        reached.add(target)
                        stack.append(target)
            found += [f"{name} -> {t}" for t in sorted(reached) if any(_inside(t, a) for a in above)]
    assert found == []


def test_own_modules_are_imported_at_module_top():
    modules = _modules()
    inside = []
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        in_functions = {n.lineno for fn in ast.walk(tree)
                        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
                        for n in ast.walk(fn) if isinstance(n, (ast.Import, ast.ImportFrom))}
        for _, node in _imports(name, path, modules):
            if node.lineno in in_functions:
                inside.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}")
    assert inside == []


def test_only_the_kernels_import_numba():
    users = sorted(str(f.relative_to(PACKAGE)) for f in PACKAGE.rglob("*.py")
                   if "import numba" in f.read_text(encoding="utf-8")
                   or "from numba" in f.read_text(encoding="utf-8"))
    assert users and all(u.startswith("_kernels/") for u in users)


#: The modules of ``npmrf3d/methods/neural/`` that import torch (everything else there must not).
TORCH_MODULES = {f"methods/neural/{m}.py" for m in ("checkpoint", "descriptor", "engine", "generator", "noise",
                                                   "zarr_volume")}


def test_only_the_neural_torch_modules_import_torch_and_only_lazily():
    users, imported_by = set(), {}
    modules = _modules()
    for name, path in modules.items():
        rel = str(path.relative_to(PACKAGE))
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "torch" for a in node.names):
                users.add(rel)
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "torch" and not node.level:
                users.add(rel)
        for target, _ in _imports(name, path, modules):
            imported_by.setdefault(target, set()).add(rel)
    assert users == TORCH_MODULES
    for rel in TORCH_MODULES:  # a torch module is imported by torch modules only
        name = "npmrf3d." + rel[:-3].replace("/", ".")
        assert imported_by.get(name, set()) <= TORCH_MODULES, (name, imported_by.get(name))
    lazy = [str(f.relative_to(PACKAGE)) for f in PACKAGE.rglob("*.py")
            if 'import_module("npmrf3d.methods.neural.' in f.read_text(encoding="utf-8")]
    assert lazy == ["methods/neural/_extra.py"]


def test_long_modules_say_why():
    long = []
    for f in PACKAGE.rglob("*.py"):
        text = f.read_text(encoding="utf-8")
        if text.count("\n") > 420:
            head = text[:1500].lower()
            if "why" not in head and "over 400" not in head and "400 lines" not in head:
                long.append(str(f.relative_to(PACKAGE)))
    assert long == []


def test_the_registry_is_what_the_studies_and_the_cli_offer():
    from npmrf3d.cli.info import run  # noqa: F401 (the info command lists METHODS)
    from npmrf3d.methods import METHODS
    from npmrf3d.studies.grid import ALGORITHMS, STUDY_ONLY

    assert ALGORITHMS == (*METHODS, *STUDY_ONLY)


#: The most lines a function outside the compiled kernels may span (decorators and docstring included).
MAX_FUNCTION_LINES = 120


def _long_functions(path: pathlib.Path, most: int) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return [f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1} lines)"
            for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > most]


def test_no_function_outside_the_kernels_is_over_120_lines():
    kernels = PACKAGE / "_kernels"
    long = [found for f in sorted(PACKAGE.rglob("*.py")) if kernels not in f.parents
            for found in _long_functions(f, MAX_FUNCTION_LINES)]
    assert long == []


def test_the_line_count_sees_a_long_function(tmp_path):
    source = tmp_path / "npmrf3d" / "long.py"
    source.parent.mkdir()
    source.write_text("def f():\n" + "    x = 1\n" * 125, encoding="utf-8")
    global PACKAGE
    saved, PACKAGE = PACKAGE, tmp_path / "npmrf3d"
    try:
        assert _long_functions(source, MAX_FUNCTION_LINES) == ["npmrf3d/long.py:1 f (126 lines)"]
        assert _long_functions(source, 126) == []
    finally:
        PACKAGE = saved


def _has_the_method_shape(function) -> bool:
    params = list(inspect.signature(function).parameters.values())
    leading = [p.name for p in params[:3]]
    keywords = {p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY}
    positional = [p for p in params if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD]
    return leading == ["per_view", "config", "rng"] and len(positional) == 3 and {"progress", "checkpoint"} <= keywords


def test_every_method_runs_with_one_signature():
    from npmrf3d.methods import METHODS

    wrong = [name for name, method in METHODS.items() if not _has_the_method_shape(method.run)]
    for f in sorted((PACKAGE / "methods").glob("*.py")):
        module = importlib.import_module(f"npmrf3d.methods.{f.stem}")
        if callable(getattr(module, "run", None)) and not _has_the_method_shape(module.run):
            wrong.append(f"npmrf3d.methods.{f.stem}.run")
    assert wrong == []
    assert not _has_the_method_shape(lambda config, per_view, rng, *, progress=None, checkpoint=None: None)
