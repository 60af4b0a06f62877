"""The README stays true: its Python runs, and CI runs its test command."""

import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def test_python_tour_runs_and_converges(monkeypatch, tmp_path):
    blocks = re.findall(r"```python\n(.*?)```", README, re.S)
    assert blocks, "the README has no Python example"
    # run where a user runs it, a checkout (relative paths), but write its files elsewhere
    for name in ("fem_elastic", "meshes", "scenes"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), namespace)
    assert namespace["ck"].step == 100 and namespace["ck"].complete
    assert np.array_equal(namespace["again"].displacement, namespace["run"].displacement)
    res = namespace["res"]
    # the tour's soft beam droops far (a large-deflection problem): Newton must get there
    assert res.converged
    assert np.all(np.isfinite(res.displacement))
    assert res.displacement[:, 2].min() < -0.1  # m: it visibly sags under gravity and load


def test_ci_runs_the_readme_commands():
    commands = re.findall(r"```bash\n(.*?)```", README, re.S)
    setup_demo, setup_test = (c.strip().splitlines()[-1] for c in commands[:2])
    assert "fem-elastic demo" in setup_demo
    ci = (ROOT / ".ci" / "run").read_text()
    # .ci/run spells the README's one-liner out step by step: each step must be there
    for step in setup_test.split(" && "):
        assert step in ci, f"README step {step!r} is not what .ci/run runs"


def _bash_commands():
    """Every command of the README's ```bash blocks (comments dropped, && chains split)."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", README, re.S):
        for line in block.splitlines():
            line = line.split("#", 1)[0].strip()
            commands += [c.strip() for c in line.split("&&") if c.strip()]
    return commands


def test_readme_commands_run_from_the_venv_without_activating_it():
    # the set-up commands create .venv and never activate it, so a command after them must
    # name .venv/bin/...: a bare `python`, `pip` or `fem-elastic` is another interpreter or
    # not on PATH at all
    commands = _bash_commands()
    assert len(commands) >= 8
    for command in commands:
        # apt-get: the system packages the cholmod extra builds against, before the venv
        # bash scripts/install_mpi.sh: the [mpi] extra's compiled route, into .venv
        assert command.startswith((".venv/bin/", "python3 -m venv .venv", "apt-get ",
                                   "bash scripts/install_mpi.sh .venv")), command
    # inline commands in the prose; the bad-inputs table quotes error messages, not commands
    prose = re.sub(r"<!-- bad-inputs:start -->.*<!-- bad-inputs:end -->", "", README, flags=re.S)
    spans = re.findall(r"`([^`\n]+)`", prose)
    for span in spans:
        assert not re.match(r"(python|pip)3? ", span) or span.startswith("python3 -m venv"), (
            f"README names `{span}`: write .venv/bin/python or .venv/bin/pip")


def test_ci_docs_builds_what_the_readme_says():
    docs = [c for c in _bash_commands() if "sphinx-build" in c or '".[docs]"' in c]
    assert len(docs) == 2, docs
    script = (ROOT / ".ci" / "docs").read_text()
    for step in docs:
        assert step in script, f"README step {step!r} is not what .ci/docs runs"
    assert " -W " in docs[-1], "the docs build must turn warnings into errors"
    pyproject = (ROOT / "pyproject.toml").read_text()
    assert re.search(r"^docs = \[.*sphinx", pyproject, re.M), "pyproject.toml has no docs extra"


def test_readme_scene_is_a_valid_scene():
    import fem_elastic as fe

    (toml,) = re.findall(r"```toml\n(.*?)```", README, re.S)
    scene = fe.parse_scene(toml, source="README.md", base_dir=ROOT / "scenes")
    built = scene.build()
    assert [b.name for b in built] == scene.variants and len(built) == 2  # the body + [[compare]]
    assert built[0].steps == 180  # 3 s at dt = 1/60 s


def test_readme_meshes_and_scripts_exist():
    # every file the README names for the user to open or run is in the repository
    named = r"(?<![\w/.])((?:meshes|scenes|scripts|notebooks|examples|docs)/[\w./-]+\.\w+)"
    for path in set(re.findall(named, README)):
        if path.startswith("docs/_build/"):  # what the README's docs build command writes
            continue
        assert (ROOT / path).exists(), f"README names {path}, which is not in the repository"
    import fem_elastic as fe

    blob = fe.load_mesh(ROOT / "meshes" / "blob.vtu")
    assert set(blob.boundaries) == {"bottom"}  # what the README says of it
