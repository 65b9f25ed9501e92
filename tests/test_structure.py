"""The shape of the code: modules import each other without cycles and only by public names,
and no source file grows past about 600 lines (a file that does is doing more than one job)."""
from __future__ import annotations

import ast
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "pelletdem"
MAX_LINES = 650
# Made by a tool, or records rather than code.
NOT_CODE = {"README.md", "CHANGELOG.md"}


def _modules() -> dict[str, Path]:
    mods = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        name = ".".join(("pelletdem",) + parts)
        mods[name.removesuffix(".__init__")] = path
    return mods


MODULES = _modules()


def _imports(name: str, path: Path):
    """(module imported, names taken from it) for every relative import of pelletdem modules in
    `name`, at any depth (inside functions too)."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
            mod = ".".join(base + ([node.module] if node.module else []))
            for alias in node.names:
                sub = f"{mod}.{alias.name}"
                if sub in MODULES:
                    yield sub, None
                elif mod in MODULES and node.module:
                    yield mod, alias.name


def test_no_import_cycles():
    graph = {m: {d for d, _ in _imports(m, p)} - {m} for m, p in MODULES.items()}
    state: dict[str, int] = {}

    def visit(m, path):
        state[m] = 1
        for d in sorted(graph[m]):
            if state.get(d) == 1:
                raise AssertionError("import cycle: " + " -> ".join(path[path.index(d):] + [d]))
            if d not in state:
                visit(d, path + [d])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])


def test_modules_take_only_public_names_from_each_other():
    private = [f"{m} takes {name} from {d}" for m, p in MODULES.items() for d, name in _imports(m, p)
               if name and name.startswith("_") and not name.startswith("__") and d != m]
    assert private == []


def test_no_source_file_is_over_the_line_limit():
    files = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True).stdout.split()
    if not files:
        pytest.skip("not a git checkout")
    long = []
    for f in files:
        path = ROOT / f
        if path.suffix not in {".py", ".cpp", ".hpp", ".md", ".sh", ".in"} or f in NOT_CODE or not path.is_file():
            continue
        if f.startswith("benchmarks/results/"):  # dated records
            continue
        n = len(path.read_text(errors="replace").splitlines())
        if n > MAX_LINES:
            long.append(f"{f}: {n} lines")
    assert long == []
