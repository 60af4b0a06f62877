"""The notebooks run: each is executed in quick mode from a temporary copy.

``notebooks/*.ipynb`` are committed with the outputs of a full run. Here each
is executed again with ``FEM_ELASTIC_QUICK=1`` (small meshes, few steps; the
kernel inherits the test process's environment) from a copy in a temporary
directory, so the committed files are never touched. A notebook checks its own
conclusions with asserts, so "it ran" already means "its claims held"; the
test also looks for the generated conclusions and the plots.

Each notebook prints a digest of the library's source (``fem_elastic source: ...``)
in its first code cell; the committed full run must show the digest of the
current source, so a library change that was not followed by a re-execution of
the notebooks (see notebooks/README.md) fails here.
"""

import hashlib
import re
import shutil
import sys
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat", reason="the notebooks need the [test] extra (nbformat)")
nbclient = pytest.importorskip("nbclient", reason="the notebooks need the [test] extra (nbclient)")
pytest.importorskip("ipykernel", reason="the notebooks need the [test] extra (ipykernel)")
pytest.importorskip("matplotlib", reason="the notebooks need the [test] extra (matplotlib)")

NOTEBOOKS = Path(__file__).resolve().parent.parent / "notebooks"

# notebook -> phrases its generated conclusions must contain, and how many plots it draws at least
EXPECTED = {
    "springs_vs_fem.ipynb": (
        ["A spring network is not the material", "Refinement", "Orientation", "Large deflection",
         "Dynamics", "Run time"],
        7,
    ),
    "integrators.ipynb": (
        ["Stability, predicted against observed", "With Rayleigh damping", "Energy", "Accuracy", "Cost"],
        4,
    ),
    "error_vs_runtime.ipynb": (
        ["Error budgets", "P1 locking", "Springs", "Large deflection", "Time integration",
         "Linearized implicit Euler"],
        3,
    ),
    "position_based_vs_fem.ipynb": (
        ["PBD's stiffness is not a material constant", "XPBD converges to implicit Euler on the same energy",
         "Shape matching", "its shape is not the material's", "Projective dynamics",
         "converges linearly to the implicit-Euler step"],
        4,
    ),
}


def _outputs(nb):
    """(stream text, markdown texts, number of PNG images, error outputs) of an executed notebook."""
    text, markdown, images, errors = [], [], 0, []
    for cell in nb.cells:
        if cell.cell_type != "code":
            continue
        for out in cell.get("outputs", []):
            if out.output_type == "stream":
                text.append(out.text)
            elif out.output_type in ("display_data", "execute_result"):
                markdown.append(out.data.get("text/markdown", ""))
                images += "image/png" in out.data
            elif out.output_type == "error":
                errors.append(f"{out.ename}: {out.evalue}")
    return "".join(text), markdown, images, errors


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def source_digest(package_dir):
    """sha256 over the library's source: every *.py under the package, sorted by path relative to it,
    hashing each relative path and the file's bytes. The notebooks' first code cell has the same function."""
    package_dir = Path(package_dir)
    h = hashlib.sha256()
    for rel in sorted(p.relative_to(package_dir).as_posix() for p in package_dir.rglob("*.py")):
        h.update(rel.encode() + b"\0")
        h.update((package_dir / rel).read_bytes() + b"\0")
    return h.hexdigest()


def _library_digest():
    """The first 16 hex digits of the source digest of the fem_elastic that the tests (and kernels) import."""
    import fem_elastic

    return source_digest(Path(fem_elastic.__file__).parent)[:16]


def _printed_digest(text):
    found = re.findall(r"fem_elastic source: ([0-9a-f]{16})", text)
    return found[0] if len(found) == 1 else None


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_notebook_runs_in_quick_mode(name, tmp_path, monkeypatch):
    committed = NOTEBOOKS / name
    before = _digest(committed)
    copy = tmp_path / name
    shutil.copyfile(committed, copy)
    monkeypatch.setenv("FEM_ELASTIC_QUICK", "1")
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")

    nb = nbformat.read(copy, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}
    )
    client.execute()  # raises CellExecutionError (with the traceback) if a cell fails
    nbformat.write(nb, copy)  # kept in tmp_path for inspection

    text, markdown, images, errors = _outputs(nb)
    assert not errors, errors
    # the kernel saw the quick switch, and ran the Python the tests run
    assert "QUICK = True" in text
    assert f"python: {sys.executable}" in text, text.splitlines()[0]
    # the notebook's digest of the library source is the test's (the two functions agree)
    assert _printed_digest(text) == _library_digest(), text.splitlines()[0]
    # the notebook's own asserts on its conclusions passed, and the conclusions were generated
    assert "all conclusions checked" in text
    phrases, n_plots = EXPECTED[name]
    conclusions = next((m for m in markdown if "1. **" in m), "")
    for phrase in phrases:
        assert phrase in conclusions, f"{name}: no {phrase!r} in the generated conclusions"
    assert images >= n_plots
    assert _digest(committed) == before, "the committed notebook must not be modified"


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_committed_notebook_carries_a_full_run(name):
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.get("execution_count") for c in code), "re-execute the notebook (see notebooks/README.md)"
    text, markdown, images, errors = _outputs(nb)
    assert not errors, errors
    assert "QUICK = False" in text and "all conclusions checked" in text
    printed, current = _printed_digest(text), _library_digest()
    assert printed == current, (
        f"{name}: the committed outputs were computed with fem_elastic source {printed or '(none printed)'}, but the "
        f"source is now {current}: re-execute the notebooks in full and commit them (command in notebooks/README.md)"
    )
    assert images >= EXPECTED[name][1]
    assert (NOTEBOOKS / name).stat().st_size < 1_000_000
