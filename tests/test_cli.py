"""The fem-elastic command, run as a user runs it: in a subprocess."""

import re
import subprocess
import sys


def run(*args):
    return subprocess.run(
        [sys.executable, "-m", "fem_elastic.cli", *args], capture_output=True, text=True, timeout=300
    )


def test_demo_prints_every_material_against_beam_theory():
    r = run("demo", "--cells", "10", "1", "1")
    assert r.returncode == 0, r.stderr
    for name in ("LinearElastic", "StVK", "NeoHookean", "StableNeoHookean", "Corotated"):
        row = re.search(rf"^{name}\s+([\d.]+)\s+([+-][\d.]+)%\s+([+-][\d.]+)%\s+(\d+)\s+([\d.]+)$", r.stdout, re.M)
        assert row, f"no row for {name} in:\n{r.stdout}"
        # P2 on a 10-cell beam: within 5 % of Timoshenko (the 3-D clamp and coarse mesh stiffen it)
        assert abs(float(row.group(3))) < 5.0
    assert "Euler-Bernoulli" in r.stdout and "Timoshenko" in r.stdout


def test_no_command_prints_help_and_fails():
    r = run()
    assert r.returncode == 2 and "demo" in r.stdout


def test_bad_option_is_a_clean_error():
    r = run("demo", "--E", "-5")
    assert r.returncode == 2 and "must be > 0" in r.stderr and "Traceback" not in r.stderr
