"""The scripts in scripts/ keep working: run as a user runs them, on small inputs."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np

import fem_elastic as fe

SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"
MESHES = SCRIPTS.parent / "meshes"


def _run_script(name: str, *args: str) -> subprocess.CompletedProcess:
    """Run ``scripts/<name>`` as a user does; it must exit 0 (its stderr is the message if not)."""
    r = subprocess.run([sys.executable, str(SCRIPTS / name), *args], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    return r


def test_bench_assembly_quick_prints_its_ratios():
    r = _run_script("bench_assembly.py", "--quick", "--no-direct", "--repeats", "1")
    for line in ("scikit-fem forms / ours", "projection overhead", "assembly share"):
        assert line in r.stdout
    # the benchmark checks its own two assemblies against each other; both to round-off
    diff = r.stdout.split("max rel. difference:")[1]
    res, tan = (float(v.split()[-1]) for v in diff.split(","))
    assert res < 1e-10 and tan < 1e-10


def test_shipped_meshes_are_what_make_meshes_builds():
    spec = importlib.util.spec_from_file_location("make_meshes", SCRIPTS / "make_meshes.py")
    make_meshes = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_meshes)
    for name, built in (("blob", make_meshes.blob_mesh()), ("beam", fe.beam_mesh())):
        shipped = fe.load_mesh(MESHES / f"{name}.vtu")
        np.testing.assert_array_equal(shipped.t, built.t)
        # VTU stores float64 points as written: equal up to the ascii/binary round trip
        np.testing.assert_allclose(shipped.p, built.p, rtol=0, atol=1e-15)
        assert set(shipped.boundaries) == set(built.boundaries)


def test_bench_step_quick_prints_its_figures():
    r = _run_script("bench_step.py", "--quick", "--repeats", "1", "--implicit-steps", "1")
    assert "numpy gradient" in r.stdout
    assert "ImplicitEuler, dt = 1/60 s" in r.stdout and "shares of the step time" in r.stdout
    if "fused gradient" in r.stdout:  # numba installed: the fused path agrees with numpy
        diff = r.stdout.split("relative difference: gradient")[1]
        g, e = float(diff.split(",")[0]), float(diff.split("energy")[1].split()[0])
        assert g < 1e-12 and e < 1e-12


def test_bench_static_stability_prints_its_ratio():
    r = _run_script("bench_static_stability.py", "--tets", "2000", "--repeats", "1")
    median = r.stdout.split("median:")[1]
    assert "ratio" in median and "goal <= 0.3" in median
    # the clamped beam under its tip load is a stable equilibrium: the check must say so
    assert "stable=True" in r.stdout


def test_bench_newton_amg_quick_prints_setups_per_step():
    r = _run_script("bench_newton_amg.py", "--quick", "--repeats", "1", "--steps", "1")
    after = r.stdout.split(" after:")[1]
    # one AMG hierarchy per step with reuse (the quick beam needs no rebuild)
    assert "AMG setups 1.00" in after.splitlines()[0]
    assert "ratio after / before" in r.stdout
