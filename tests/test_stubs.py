"""The compiled module ships type stubs that match it.

python/pelletdem/_core.pyi was generated with pybind11-stubgen and edited by hand (names and
units, numpy dtypes), so it cannot be regenerated blindly: when the bindings gain or lose an
attribute this test names it, and the stub is updated by hand (run
`pybind11-stubgen pelletdem._core -o /tmp/stubs` to see the generated signature).
"""
from __future__ import annotations

import ast
import importlib.util
import inspect
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pelletdem import _core

ROOT = Path(__file__).resolve().parents[1]
STUB = ROOT / "python" / "pelletdem" / "_core.pyi"


def _public(names):
    return {n for n in names if not n.startswith("_")}


def _stub_tree() -> ast.Module:
    return ast.parse(STUB.read_text(), filename=str(STUB))


def _stub_members(tree: ast.Module) -> dict[str, set[str] | None]:
    """Module-level public names -> public member names (None for functions)."""
    out: dict[str, set[str] | None] = {}
    for node in tree.body:
        if isinstance(node, ast.ClassDef):
            members = set()
            for item in node.body:
                if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    members.add(item.name)
                elif isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                    members.add(item.target.id)
                elif isinstance(item, ast.Assign):
                    members.update(t.id for t in item.targets if isinstance(t, ast.Name))
            out[node.name] = _public(members)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            out[node.name] = None
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            out[node.target.id] = None
    return {k: v for k, v in out.items() if not k.startswith("_")}


def test_stub_and_marker_are_in_the_package():
    assert STUB.is_file()
    assert (STUB.parent / "py.typed").is_file()


def test_installed_package_ships_the_stub():
    """scikit-build-core's wheel.packages copies python/pelletdem whole, stub and marker too."""
    installed = Path(importlib.util.find_spec("pelletdem").origin).parent
    if installed == STUB.parent:
        pytest.skip("running against the source tree, not an installed wheel")
    assert (installed / "_core.pyi").is_file(), "reinstall: the installed package has no _core.pyi"
    assert (installed / "py.typed").is_file()


def test_stub_parses():
    _stub_tree()


def test_stub_names_every_public_attribute_of_the_module():
    stub = _stub_members(_stub_tree())
    runtime = _public(dir(_core))
    assert sorted(runtime - set(stub)) == [], "in _core but not in _core.pyi"
    assert sorted(set(stub) - runtime) == [], "in _core.pyi but not in _core"


# The laws' parameter structs have one attribute per row of their tables, which the stub does
# not list (a new effect's rows would otherwise need it edited): their rows are checked here.
LAW_PARAMS = ("ContactLawParams", "BondParams")


@pytest.mark.parametrize("name", sorted(n for n in _public(dir(_core)) if inspect.isclass(getattr(_core, n))))
def test_stub_names_every_public_member_of_each_class(name):
    stub = _stub_members(_stub_tree())
    assert name in stub
    cls = getattr(_core, name)
    runtime = _public(vars(cls))
    if name in LAW_PARAMS:
        rows = {r.name for r in cls.rows()}
        assert rows <= runtime, f"{name}: rows without an attribute: {sorted(rows - runtime)}"
        runtime -= rows
    assert sorted(runtime - stub[name]) == [], f"{name}: in _core but not in _core.pyi"
    assert sorted(stub[name] - runtime) == [], f"{name}: in _core.pyi but not in _core"


@pytest.mark.parametrize("name", LAW_PARAMS)
def test_law_params_attributes_are_the_rows_with_their_types_and_defaults(name):
    cls = getattr(_core, name)
    p = cls()
    for r in cls.rows():
        value = getattr(p, r.name)
        assert type(value) is (bool if r.type == "bool" else float), r.name
        assert value == r.default, r.name


def test_stub_signatures_match_the_module_under_stubtest(tmp_path):
    """mypy's stubtest compares every signature with the runtime's (argument names, defaults,
    positional-only markers). The classes' metaclass (pybind11_type) is the one accepted
    difference."""
    if shutil.which("mypy") is None and importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed")
    installed = Path(importlib.util.find_spec("pelletdem").origin).parent
    if not (installed / "_core.pyi").is_file() or (installed / "_core.pyi").read_text() != STUB.read_text():
        pytest.skip("the installed stub differs from the source tree's: reinstall to check it")
    cfg = tmp_path / "mypy.ini"
    cfg.write_text("[mypy]\ncache_dir = /dev/null\n")
    # The laws' attributes are their tables' rows, not listed in the stub (see LAW_PARAMS).
    allow = tmp_path / "allowlist.txt"
    allow.write_text("".join(f"pelletdem._core.{c}.{m}\n" for c in LAW_PARAMS
                             for m in ["__getattr__", "__setattr__"] + [r.name for r in getattr(_core, c).rows()]))
    out = subprocess.run([sys.executable, "-m", "mypy.stubtest", "--mypy-config-file", str(cfg),
                          "--allowlist", str(allow), "pelletdem._core"],
                         capture_output=True, text=True, cwd=tmp_path, timeout=300)
    errors = [line for line in out.stdout.splitlines()
              if line.startswith("error:") and "metaclass differs" not in line]
    assert errors == [], out.stdout


def test_mypy_accepts_the_stub():
    if importlib.util.find_spec("mypy") is None:
        pytest.skip("mypy is not installed")
    out = subprocess.run([sys.executable, "-m", "mypy", "--strict", "--follow-imports=silent",
                          "--cache-dir", "/dev/null", str(STUB)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout + out.stderr
