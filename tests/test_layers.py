"""One-way layers: config/envs <- runs/agent <- data/learners <- train/bench <- launch <- analysis
<- paper_figures <- app.

Every ``.py`` file of the packages is parsed with ``ast``; every import in it (at module level, inside
functions, under ``if TYPE_CHECKING``, and ``importlib.import_module`` / ``__import__`` with a literal
name) is mapped to the layer of the module it names. A module may import only from its own layer or a
lower one, and the import graph of the project's modules, function-level imports included, has no
cycle (so no function-level import can be dodging one). Offenders are listed as ``file:line``.

The layer of a module is the one of the longest prefix of its dotted name in :data:`LAYER_OF`
(docs/layers.md explains the layers).
"""

from __future__ import annotations

import ast
import functools
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("repro", "repro_data", "analysis", "paper_figures", "repro_app")
SCRIPT_DIRS = ("benchmarks",)  # plain scripts, not a package: app layer
# The layers of docs/layers.md, lowest first: one folder per layer inside repro/.
LAYERS = ("config/envs", "runs/agent", "data/learners", "train/bench", "launch", "analysis", "paper_figures", "app")
CONFIG, RUNS, DATA, TRAIN, LAUNCH, ANALYSIS, FIGURES, APP = range(len(LAYERS))
LAYER_OF = {
    "repro": CONFIG,  # the package itself (__init__: the version only)
    "repro.config": CONFIG,
    "repro.envs": CONFIG,
    "repro.runs": RUNS,
    "repro.agent": RUNS,
    "repro.data": DATA,
    "repro.learners": DATA,
    "repro.train": TRAIN,
    "repro.bench": TRAIN,
    "repro.launch": LAUNCH,
    "repro_data": CONFIG,  # files from outside the project and their paths (imports nothing of the project)
    "repro.__main__": APP,  # `python -m repro`: the entry shim of the app
    "analysis": ANALYSIS,
    "paper_figures": FIGURES,
    "repro_app": APP,
    "benchmarks": APP,
}
# The folders of repro/ (each a package with its own layer); a new top-level module or folder fails
# test_each_folder_has_its_layer until it is given a layer here.
REPRO_FOLDERS = {"config", "envs", "runs", "agent", "data", "learners", "train", "bench", "launch", "conf"}


@dataclass(frozen=True)
class Import:
    source: str  # importing module
    target: str  # imported project module ("" when the name is not a literal)
    file: Path
    line: int
    in_function: bool

    def where(self, root: Path) -> str:
        return f"{self.file.relative_to(root)}:{self.line}"


def layer_of(module: str) -> int:
    parts = module.split(".")
    for n in range(len(parts), 0, -1):
        prefix = ".".join(parts[:n])
        if prefix in LAYER_OF:
            return LAYER_OF[prefix]
    raise KeyError(module)


def module_files(root: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every package module and script under ``root``."""
    out: dict[str, Path] = {}
    for top in (*PACKAGES, *SCRIPT_DIRS):
        for path in sorted((root / top).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            out[".".join(parts)] = path
    return out


def _is_package(path: Path) -> bool:
    return path.name == "__init__.py"


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The longest project module that ``name`` (a dotted module or module.attribute) names, or None."""
    parts = name.split(".")
    if parts[0] not in (*PACKAGES, *SCRIPT_DIRS):
        return None
    for n in range(len(parts), 0, -1):
        candidate = ".".join(parts[:n])
        if candidate in modules:
            return candidate
    return None


def _literal_import_name(call: ast.Call) -> str | None:
    """``importlib.import_module("a.b")`` / ``__import__("a.b")`` -> ``"a.b"``; the constant prefix of an
    f-string (``f"pkg.{x}"`` -> ``"pkg"``); ``""`` for a name the checker cannot read; None when ``call`` is
    not an import."""
    func = call.func
    is_import = (isinstance(func, ast.Name) and func.id in ("__import__", "import_module")) or (
        isinstance(func, ast.Attribute) and func.attr == "import_module")
    if not is_import or not call.args:
        return None
    arg = call.args[0]
    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
        return arg.value
    if isinstance(arg, ast.JoinedStr) and arg.values and isinstance(arg.values[0], ast.Constant):
        return str(arg.values[0].value).rstrip(".")
    return ""


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> list[Import]:
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if _is_package(path) else module.rpartition(".")[0]
    found: list[Import] = []

    def add(name: str | None, node: ast.AST, in_function: bool) -> None:
        if name is None:
            return
        target = _resolve(name, modules) if name else ""
        if target is not None and target != module:
            found.append(Import(module, target, path, node.lineno, in_function))  # type: ignore[attr-defined]

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            nested = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    add(alias.name, child, in_function)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[: len(base) - (child.level - 1)]
                    prefix = ".".join(base + ([child.module] if child.module else []))
                else:
                    prefix = child.module or ""
                for alias in child.names:
                    add(f"{prefix}.{alias.name}" if alias.name != "*" else prefix, child, in_function)
            elif isinstance(child, ast.Call):
                add(_literal_import_name(child), child, in_function)
            visit(child, nested)

    visit(tree, False)
    return found


@functools.lru_cache(maxsize=4)
def all_imports(root: Path) -> list[Import]:
    modules = module_files(root)
    return [imp for name, path in modules.items() for imp in imports_of(name, path, modules)]


def upward_imports(root: Path) -> list[str]:
    """``file:line: a (layer) imports b (higher layer)`` for every upward or unreadable import."""
    out = []
    for imp in all_imports(root):
        if not imp.target:
            out.append(f"{imp.where(root)}: {imp.source} imports a module named at run time; use a literal name")
            continue
        src, dst = layer_of(imp.source), layer_of(imp.target)
        if dst > src:
            kind = " (inside a function)" if imp.in_function else ""
            out.append(f"{imp.where(root)}: {imp.source} ({LAYERS[src]}) imports {imp.target} "
                       f"({LAYERS[dst]}){kind}")
    return out


def import_cycles(root: Path) -> list[str]:
    """One line per cycle of the project's import graph (function-level imports included)."""
    edges: dict[str, dict[str, Import]] = {}
    for imp in all_imports(root):
        if imp.target:
            edges.setdefault(imp.source, {}).setdefault(imp.target, imp)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def strongconnect(v: str) -> None:  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in edges.get(v, {}):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                components.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            strongconnect(v)
    out = []
    for comp in components:
        members = set(comp)
        links = [imp for src in comp for dst, imp in edges.get(src, {}).items() if dst in members]
        out.append("cycle " + " <-> ".join(comp) + ": " +
                   "; ".join(f"{imp.where(root)} {imp.source} -> {imp.target}"
                             f"{' (inside a function)' if imp.in_function else ''}" for imp in links))
    return out


# ---------------------------------------------------------------------------------------------- tests

def test_no_module_imports_from_a_higher_layer():
    offenders = upward_imports(ROOT)
    assert not offenders, "upward imports:\n" + "\n".join(offenders)


def test_each_folder_has_its_layer():
    """repro/ holds the layer folders and no loose module; each folder has the layer of docs/layers.md (a folder
    mapped to the wrong layer in LAYER_OF would let upward imports pass)."""
    loose = sorted(p.name for p in (ROOT / "repro").iterdir()
                   if (p.suffix == ".py" and p.name not in ("__init__.py", "__main__.py"))
                   or (p.is_dir() and p.name not in REPRO_FOLDERS and p.name != "__pycache__"))
    assert not loose, f"repro/ must hold only the layer folders of docs/layers.md, found {loose}"
    assert layer_of("repro.config.compose") == layer_of("repro.envs.dmc") == CONFIG
    assert layer_of("repro.runs.rundir") == layer_of("repro.agent.agent") == RUNS
    assert layer_of("repro.data.dataset") == layer_of("repro.learners.losses.cql") == DATA
    assert layer_of("repro.train.api") == layer_of("repro.bench.cli") == TRAIN
    assert layer_of("repro.launch.cli") == LAUNCH
    assert layer_of("analysis.load") < layer_of("paper_figures.catalog") < layer_of("repro_app.cli")
    assert set(module_files(ROOT)) and all(isinstance(layer_of(m), int) for m in module_files(ROOT))


def test_no_import_cycle_even_through_function_level_imports():
    cycles = import_cycles(ROOT)
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_the_checker_sees_the_import_forms_used_here():
    """Pins what the scan reads, so a regression in the checker cannot make the tests above pass vacuously."""
    imports = all_imports(ROOT)
    by_source = {(i.source, i.target, i.in_function) for i in imports}
    assert ("repro_app.cli", "repro.launch.cli", False) in by_source  # from repro.launch import cli as launch_cli
    assert ("repro.train.build", "repro.envs", True) in by_source  # function-level import in build_env
    assert ("paper_figures.catalog", "paper_figures.f10_action_dim", False) in by_source  # from pkg import module
    assert ("repro_app.report", "analysis.claims", False) in by_source  # from module import name
    assert len({i.source for i in imports}) > 50


def _write(root: Path, rel: str, text: str) -> None:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_checker_reports_upward_and_cyclic_imports_by_file_and_line(tmp_path):
    for pkg in PACKAGES:
        _write(tmp_path, f"{pkg}/__init__.py", "")
    _write(tmp_path, "repro/config/compose.py", "import os\n\n\ndef compose():\n    from repro_app.report import x\n")
    _write(tmp_path, "repro/config/__init__.py", "")
    _write(tmp_path, "repro_app/report.py", "from repro.config import compose\n")
    _write(tmp_path, "analysis/load.py", "import importlib\nimportlib.import_module('paper_figures.x')\n")
    _write(tmp_path, "paper_figures/x.py", "from ..analysis import load\n")
    _write(tmp_path, "analysis/dyn.py", "name = 'x'\n__import__(name)\n")
    up = upward_imports(tmp_path)
    assert any(line.startswith("repro/config/compose.py:5: repro.config.compose (config/envs) imports repro_app.report")
               and "inside a function" in line for line in up), up
    assert any(line.startswith("analysis/load.py:2: analysis.load (analysis) imports paper_figures.x") for line in up)
    assert any(line.startswith("analysis/dyn.py:2:") and "run time" in line for line in up)
    assert len(up) == 3, up
    cycles = import_cycles(tmp_path)
    assert len(cycles) == 2, cycles
    assert any("repro.config.compose <-> repro_app.report" in c and "repro/config/compose.py:5" in c for c in cycles)
    assert any("analysis.load <-> paper_figures.x" in c and "paper_figures/x.py:1" in c for c in cycles)


# ---------------------------------------------------------------- third-party internals (issue 51 point 4)
DEVIATIONS = ROOT / "docs" / "deviations.md"
INTERNALS_SECTION = "## Third-party internals still used"


def private_imports(root: Path) -> list[tuple[str, str]]:
    """(file, dotted name) of every import of another library's private module or name (a dotted part that starts
    with one underscore) in the packages and benchmarks: ``from x._y import z``, ``import x._y``,
    ``from x import _y``, at any depth of the file."""
    found = []
    for path in module_files(root).values():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [f"{node.module}.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                continue
            for name in names:
                parts = name.split(".")
                if parts[0] in LAYER_OF or parts[0] in PACKAGES:
                    continue
                if any(p.startswith("_") and not p.startswith("__") for p in parts[1:]):
                    found.append((path.relative_to(root).as_posix(), name))
    return found


def listed_internals(text: str) -> str:
    """The table of docs/deviations.md's section on the third-party internals the project still uses."""
    start = text.index(INTERNALS_SECTION)
    end = text.find("\n## ", start + 1)
    return text[start:end if end >= 0 else None]


def test_every_private_import_of_a_library_is_a_listed_pinned_exception():
    table = listed_internals(DEVIATIONS.read_text())
    rows = [line for line in table.splitlines() if line.startswith("| ")]
    unlisted = [f"{file}: {name}" for file, name in private_imports(ROOT)
                if not any(file in row and name.rsplit(".", 1)[-1] in row for row in rows)]
    assert not unlisted, f"list these in docs/deviations.md '{INTERNALS_SECTION[3:]}' with a pin: {unlisted}"


def test_the_private_import_check_sees_each_form(tmp_path):
    _write(tmp_path, "repro/__init__.py", "")
    _write(tmp_path, "repro/config/__init__.py", "")
    _write(tmp_path, "repro/config/x.py", "import numpy\nfrom scipy.stats import _continuous_distns\n"
           "def f():\n    import pandas._libs.parsers\n    from matplotlib._api import check_in_list\n"
           "    from . import _private\n    from repro.config import _own\n")
    assert sorted(name for _, name in private_imports(tmp_path)) == [
        "matplotlib._api.check_in_list", "pandas._libs.parsers", "scipy.stats._continuous_distns"]
