"""The documentation's examples run and say what they claim.

Each ``examples/plot_*.py`` (the docs gallery) runs here in quick mode
(``FEM_ELASTIC_QUICK=1``: coarse meshes, short runs) in a subprocess, off-screen, and must exit
0: every example asserts its own physical checks (beam theory, reactions, energy behaviour,
convergence), and this test checks the key lines it prints. The Sphinx build itself is too
slow for the default run on 2 cores; ``.ci/docs`` builds the site with warnings as errors.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = sorted((ROOT / "examples").glob("plot_*.py"))

# what each example must print (a regex on its stdout), beyond exiting 0 after its asserts; the
# reason for each number's range is written beside it (the quick-mode values in brackets)
EXPECTED = {
    # P2 converges from below (0.955, 0.979, 0.988 on 4, 8, 16 cells): a conforming displacement
    # FEM is stiffer than the solid; about 1 % is left at 16 cells, 0.5 % of it the 3-D clamp
    "plot_cantilever_beam_theory.py": r"P2,\s+16 cells along: tip .* 0\.98\d x Timoshenko",
    # a homogeneous stretch is exact on any mesh: E strain A = 1e6 Pa * 0.01 * 0.01 m^2 = 100 N,
    # and only x is prescribed on that face, so its y and z reactions vanish (printed to 1e-6 N)
    "plot_rollers_reactions.py": r"reaction on the pulled face: \[100\.\s+0\.\s+0\.\] N",
    # implicit Euler free fall from 50 mm: g dt^2 n (n + 1) / 2 passes 49 mm (within the 1 mm
    # the example calls contact) at step n = 10 of dt = 0.01 s, not at n = 9 (44 mm)
    "plot_neohookean_drop.py": r"first contact at t = 0\.10 s",
    # 40 steps a period: the first mode's energy alone falls by (1 + (2 pi / 40)^2)^-40 = 0.38
    # (-62 %), higher modes faster [-67 %]: two digits, a loss between 10 and 99 %
    "plot_integrators_compared.py": r"implicit Euler .* energy\s+-\d\d\.\d\d %",
    # XPBD within 10 % of implicit Euler at 200 iterations (one digit) [1.8 %; the example
    # asserts < 5 %]
    "plot_pbd_xpbd_vs_fem.py": r"200 iterations: XPBD tip .* field\s+\d\.\d %",
    # Euler-Bernoulli gives 4.0 cm; the P2 solid on the quick mesh is stiffer, by under 2.5 %
    # (3.900-3.999 cm) [3.945 cm, 0.986 x]
    "plot_scene_from_python.py": r"fem_p2 .* static\s+3\.9\d\d cm",
    # Euler-Bernoulli's first frequency is 40.76 Hz; the consistent-mass P2 model lies above
    # the solid's (Rayleigh-Ritz) by its discretization, under 2 % on the quick mesh [1.012 x]
    "plot_modal_analysis.py": r"mode 1:\s+4\d\.\d\d Hz\s+1\.0[01]\d x Euler-Bernoulli",
    # the same energy, the same Newton iterates: the two displacements agree to round-off
    # [1.1e-15]; printed as 1e-19 to 1e-10 relative (or exactly 0), the example's own bound
    # (< 1e-9), which also covers one more Newton iteration in one of them (it moves u by
    # under 1e-13 relative: Newton is quadratic, see the example)
    "plot_user_energy.py": r"generated vs hand-written Neo-Hookean: (\d\.\de-1\d|0\.0e\+00)",
    # the work per element is constant, so each cost grows about linearly with the tets: the
    # fitted exponents printed with two decimals, each within [0.5, 1.6] (the example asserts
    # it; 0.75-1.00 seen on the quick 1k-20k tets of a loaded 2-core machine)
    "plot_scaling.py": r"fitted exponent p \(t ~ n_tets\^p\): assembly [01]\.\d\d, "
                       r"implicit step [01]\.\d\d, explicit step [01]\.\d\d",
}


def test_every_example_has_an_expectation():
    names = {p.name for p in EXAMPLES}
    assert len(names) >= 6, "the gallery needs 6-10 examples"
    assert names == set(EXPECTED), f"examples and EXPECTED differ: {names ^ set(EXPECTED)}"


def test_gallery_header_and_titles():
    assert (ROOT / "examples" / "README.rst").is_file()  # sphinx-gallery's index needs it
    for path in EXAMPLES:
        text = path.read_text()
        # sphinx-gallery takes the title from the module docstring's first underlined line
        head = re.match(r'"""\n(.+)\n(=+)\n', text)
        assert head and len(head.group(2)) >= len(head.group(1)), f"{path.name}: no title"
        assert "FEM_ELASTIC_QUICK" in text, f"{path.name} has no quick mode"


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.stem)
def test_example_runs_in_quick_mode(path, tmp_path):
    env = dict(os.environ, FEM_ELASTIC_QUICK="1", MPLBACKEND="Agg", PYVISTA_OFF_SCREEN="true",
               OMP_NUM_THREADS="1")
    proc = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, f"{path.name} failed:\n{proc.stdout}\n{proc.stderr[-3000:]}"
    assert re.search(EXPECTED[path.name], proc.stdout), (
        f"{path.name} did not print {EXPECTED[path.name]!r}:\n{proc.stdout}")
    assert not list(tmp_path.iterdir()), "an example wrote files into its working directory"


PAGES = sorted((ROOT / "docs").rglob("*.md"))
PAGES = [p for p in PAGES if "_build" not in p.parts and re.search(r"```python\n", p.read_text())]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT / "docs")))
def test_python_blocks_of_the_guide_run(page, monkeypatch):
    # the site's pages say their commands run from the repository root: run them there
    monkeypatch.chdir(ROOT)
    namespace: dict = {}
    for block in re.findall(r"```python\n(.*?)```", page.read_text(), re.S):
        exec(compile(block, str(page), "exec"), namespace)


def test_guide_pages_have_python_to_run():
    names = {p.name for p in PAGES}
    assert {"getting_started.md", "materials.md", "scenes.md"} <= names
