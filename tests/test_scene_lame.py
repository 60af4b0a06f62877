"""Scene files give a finite-element body as E and nu, or as Lame's mu and lam, and may ask
for the mixed displacement-pressure formulation (issue 15: what the Python API already does)."""

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.app.scene import SceneError, parse_scene

BODY = """\
[mesh]
kind = "beam"
length = 1.0
width = 0.1
height = 0.1
cells = [4, 1, 1]
[body]
material = "neo_hookean"
{elasticity}
density = 1000.0
[boundary]
fixed = ["left"]
[loads]
gravity = [0.0, 0.0, -9.81]
[solve]
kind = "static"
"""

MU, LAM = 1.0e6, 4.99e9  # nu = 0.4999: a near-incompressible rubber-like body


def _scene(elasticity: str):
    return parse_scene(BODY.format(elasticity=elasticity))


def test_lame_pair_and_mixed_formulation_build_the_api_model():
    """The scene's body is the one the Python API builds from (mu, lam), mixed, P2."""
    run = _scene(f"mu = {MU}\nlam = {LAM}\norder = 2\nformulation = \"mixed\"").build()[0]
    assert run.model.body.formulation == "mixed" and run.model.body.order == 2
    material = run.model.body.material
    # Lame's pair passes through untouched (no round trip through E and nu)
    assert material.mu == MU and material.lam == LAM
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(4, 1, 1))
    model = fe.Model(mesh, density=1000.0, fixed="left", gravity=(0.0, 0.0, -9.81),
                     body=fe.ElasticBody(fe.NeoHookean(mu=MU, lam=LAM), order=2, formulation="mixed"))
    u_api = fe.solve_static(model).displacement
    u_scene = fe.solve_static(run.model).displacement
    # the same model, solved by the same Newton: equal to round-off of the solve's tolerance
    np.testing.assert_allclose(u_scene, u_api, rtol=0, atol=1e-12 * np.abs(u_api).max())
    assert run.info["mu"] == MU and run.info["formulation"] == "mixed"
    # the derived nu is reported for reference: exactly the material's, lam / (2 (lam + mu)) =
    # 0.49989982, the 0.4999 that MU and LAM were chosen for to 1.8e-7 (< 1e-6)
    assert run.info["nu"] == material.nu
    assert abs(run.info["nu"] - 0.4999) < 1e-6


def test_e_nu_stays_the_default_pair():
    run = _scene("E = 2e7\nnu = 0.3").build()[0]
    assert run.model.body.material.E == 2e7 and run.model.body.formulation == "displacement"


@pytest.mark.parametrize("elasticity, key, phrase", [
    ("E = 2e7\nnu = 0.3\nmu = 1e6", "mu", "not both"),
    ("mu = 1e6", "lam", "missing required key lam"),
    ("nu = 0.3", "E", "missing required key E"),
    ("density_x = 1", "E", None),  # an unknown key is reported first (its own test elsewhere)
    ("", "E", "give mu and lam"),
    ("mu = 1e6\nlam = -1e6", "lam", "lam"),  # K = lam + 2 mu / 3 < 0: not a solid
])
def test_wrong_pairs_are_named(elasticity, key, phrase):
    with pytest.raises(SceneError) as info:
        _scene(elasticity)
    message = str(info.value)
    if phrase is None:
        assert "density_x" in message
    else:
        assert phrase in message and key in message


def test_mixed_needs_quadratic_tets():
    with pytest.raises(SceneError, match="order"):
        _scene("E = 2e7\nnu = 0.49\nformulation = \"mixed\"").build()


def test_unknown_formulation_lists_the_choices():
    with pytest.raises(SceneError, match="displacement.*mixed"):
        _scene("E = 2e7\nnu = 0.3\nformulation = \"hybrid\"")
