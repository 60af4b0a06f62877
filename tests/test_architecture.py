"""The package's layers: each subpackage imports only those below it (docs/architecture.md).

The check walks the AST of every module (imports inside functions included,
doctest strings not) and maps each import to the layer of its target. A test
plants an upward import in a copy of the package and checks it is caught.
"""

from __future__ import annotations

import ast
import re
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

import fem_elastic

PACKAGE = Path(fem_elastic.__file__).resolve().parent
ROOT = PACKAGE.parent

#: the layers, lowest first: a module may import its own subpackage and any lower rank
RANK = {
    "errors": 0, "_compat": 0,               # foundation: imports nothing of the package
    "files": 0.5, "resources": 0.5,          # foundation too, raising the typed errors of `errors`
    "geometry": 1, "materials": 1,           # side by side: neither imports the other
    "discretization": 2,
    "physics": 3,
    "solvers": 4,
    "dynamics": 5,
    "study": 6,
    "app": 7,
    "__init__": 8, "__main__": 8,            # the package itself: the public surface
}


def _layer(part: str) -> int:
    return RANK[part]


def _module_name(path: Path, package: Path) -> tuple[str, bool]:
    rel = path.relative_to(package).with_suffix("")
    parts = list(rel.parts)
    is_pkg = parts[-1] == "__init__"
    if is_pkg:
        parts = parts[:-1]
    return ".".join(parts), is_pkg


def _imports(path: Path, package: Path):
    """(line, imported module relative to the package: '' for the package itself) of a file."""
    mod, is_pkg = _module_name(path, package)
    here = mod.split(".") if mod else []
    pkg_parts = here if is_pkg else here[:-1]
    name = package.name
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg_parts[:len(pkg_parts) - (node.level - 1)]
                target = base + (node.module.split(".") if node.module else [])
            elif node.module == name or (node.module or "").startswith(name + "."):
                target = node.module.split(".")[1:]
            else:
                continue
            for alias in node.names:  # `from . import x`: x may be a module
                sub = package.joinpath(*target, alias.name)
                if sub.with_suffix(".py").is_file() or (sub / "__init__.py").is_file():
                    yield node.lineno, ".".join(target + [alias.name])
                else:
                    yield node.lineno, ".".join(target)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name == name or alias.name.startswith(name + "."):
                    yield node.lineno, ".".join(alias.name.split(".")[1:])


def layer_violations(package: Path) -> list[str]:
    """Every import in ``package`` that reaches a layer above (or beside) its own."""
    found = []
    for path in sorted(package.rglob("*.py")):
        mod, _ = _module_name(path, package)
        top = mod.split(".")[0] if mod else "__init__"
        for line, target in _imports(path, package):
            ttop = target.split(".")[0] if target else "__init__"
            if ttop == top:
                continue  # within its own subpackage (or module)
            if _layer(ttop) >= _layer(top):
                found.append(f"{path.relative_to(package.parent)}:{line}: {mod or package.name} "
                             f"imports {package.name}{'.' + target if target else ''} "
                             f"(layer {ttop!r} is not below {top!r})")
    return found


def test_every_module_belongs_to_a_layer():
    for path in PACKAGE.rglob("*.py"):
        mod, _ = _module_name(path, PACKAGE)
        _layer(mod.split(".")[0] if mod else "__init__")  # KeyError: a module outside the layers


def test_no_layer_imports_a_layer_above_it():
    assert layer_violations(PACKAGE) == []


@pytest.mark.parametrize("where, planted", [
    ("geometry/mesh.py", "from ..app import cli"),                        # far upward
    ("physics/model.py", "    from ..solvers.newton import newton_minimize"),  # one layer up, lazily
    ("materials/base.py", "from ..geometry import mesh"),                  # beside, not below
    ("solvers/static.py", "import fem_elastic as fe"),                    # the package root
])
def test_a_planted_upward_import_is_caught(tmp_path, where, planted):
    copy = tmp_path / "fem_elastic"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    target = copy / where
    text = target.read_text(encoding="utf-8")
    if planted.startswith("    "):  # inside a function: append one that imports lazily
        text += f"\n\ndef _planted():\n{planted}\n"
    else:
        text += f"\n{planted}\n"
    target.write_text(text, encoding="utf-8")
    found = layer_violations(copy)
    assert len(found) == 1 and found[0].startswith(f"fem_elastic/{where}:"), found


def test_import_fem_elastic_stays_light():
    code = ("import sys, fem_elastic as fe; heavy = [m for m in ('fem_elastic.study', 'meshio', "
            "'pyvista', 'matplotlib', 'numba', 'pyamg', 'tqdm', 'fem_elastic.app.runner', "
            "'fem_elastic.app.render') if m in sys.modules]; print(heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
    code = "import fem_elastic as fe; fe.study.run_accuracy_study; import sys; print('fem_elastic.study' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True"  # imported on first use


def test_no_module_over_800_lines():
    long = {str(p.relative_to(ROOT)): n for p in PACKAGE.rglob("*.py")
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 800}
    assert long == {}


def test_simulate_reads_as_a_loop():
    """simulate's code (its docstring aside) stays short: the work is in the observers."""
    import importlib

    module = importlib.import_module("fem_elastic.dynamics.simulate")
    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    fn = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "simulate")
    code_start = fn.body[1].lineno  # after the docstring
    assert fn.end_lineno - code_start + 1 < 80


def test_architecture_page_lists_every_module():
    """docs/architecture.md names every module of the package, and no module that is gone."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    listed = set(re.findall(r"`(fem_elastic/[\w/]+\.py)`", text))
    actual = {str(p.relative_to(ROOT)) for p in PACKAGE.rglob("*.py")}
    assert listed == actual, (sorted(actual - listed), sorted(listed - actual))


def test_old_module_paths_still_work_with_a_deprecation_warning():
    import importlib

    from fem_elastic import _compat

    for old, new in _compat.MOVED.items():
        sys.modules.pop(f"fem_elastic.{old}", None)
        module = importlib.import_module(f"fem_elastic.{old}")
        target = importlib.import_module(f"fem_elastic.{new[0]}")
        public = [n for n in getattr(target, "__all__", []) if hasattr(target, n)]
        if not public:
            continue
        with pytest.warns(DeprecationWarning, match=f"fem_elastic.{old} is deprecated"):
            assert getattr(module, public[0]) is getattr(target, public[0])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import fem_elastic as fe

        assert fe.mesh.DEGENERATE_TOL == fe.geometry.mesh.DEGENERATE_TOL
        from fem_elastic.io import read_series, write_text_atomic  # a module split in three

        assert read_series is fe.read_series and write_text_atomic is fe.files.write_text_atomic
        from fem_elastic.integrators.base import check_dt

        assert check_dt is fe.dynamics.integrators.base.check_dt
    with pytest.raises(AttributeError, match="has no attribute 'nope'"):
        fe.mesh.nope
    # importing the old module path of simulate leaves the function fe.simulate in place
    assert callable(fe.simulate) and fe.simulate.__module__ == "fem_elastic.dynamics.simulate"
