"""Constraints, colouring and sweeps of fem_elastic.dynamics.position_based (PBD and XPBD share them)."""

from __future__ import annotations

import numpy as np
import pytest

import fem_elastic as fe
from fem_elastic.discretization import fused
from fem_elastic.dynamics.position_based import (
    EdgeDistance,
    TetNeoHookean,
    TetVolume,
    color_constraints,
    coloring_is_valid,
)
from fem_elastic.dynamics.position_based.constraints import numba_kernels

MESH = fe.beam_mesh(0.4, 0.1, 0.1, cells=(4, 1, 1))
X = MESH.p.T.ravel().copy()


def _sets(mesh=MESH):
    return [EdgeDistance.of_mesh(mesh), TetVolume(mesh), TetNeoHookean(mesh, mu=4e5, lam=6e5)]


def _perturbed(scale=0.01, seed=0):
    return X + scale * np.random.default_rng(seed).standard_normal(X.size)


@pytest.mark.parametrize("mesh", [MESH, fe.beam_mesh(cells=(10, 3, 2)), fe.load_mesh("meshes/blob.vtu")])
def test_coloring_is_valid_and_near_the_degree_bound(mesh):
    """No two constraints of a colour share a vertex; colours within 2x the largest vertex degree."""
    for nodes in (np.asarray(mesh.edges).T, np.asarray(mesh.t).T):
        colors = color_constraints(nodes, mesh.p.shape[1])
        assert coloring_is_valid(nodes, colors)
        degree = np.bincount(nodes.ravel()).max()
        assert degree <= colors.max() + 1 <= 2 * degree
    # the sets store their constraints colour by colour, each colour a valid one
    for s in _sets(mesh):
        assert np.all(np.diff(s.colors) >= 0)
        assert coloring_is_valid(s.nodes, s.colors)
        assert sorted(s.source.tolist()) == list(range(len(s)))


def test_coloring_check_catches_a_shared_vertex():
    nodes = np.asarray(MESH.t).T
    colors = color_constraints(nodes, MESH.p.shape[1])
    bad = colors.copy()
    # give a tet the colour of another tet it shares a vertex with
    a = 0
    b = next(j for j in range(1, len(nodes)) if set(nodes[j]) & set(nodes[a]))
    bad[b] = bad[a]
    assert not coloring_is_valid(nodes, bad)


def test_constraint_gradients_match_finite_differences():
    x = _perturbed()
    for s in _sets():
        idx = np.arange(len(s))
        G = s.values_and_gradients(x, idx)[1]
        Gfd = np.zeros_like(G)
        eps = 1e-7
        for a in range(s.nodes.shape[1]):
            for i in range(3):
                # move one vertex of one constraint at a time (vertices are shared between them)
                Cp = np.array([s.values_and_gradients(_moved(x, s.nodes[j, a], i, eps), [j])[0][0]
                               for j in range(len(s))])
                Cm = np.array([s.values_and_gradients(_moved(x, s.nodes[j, a], i, -eps), [j])[0][0]
                               for j in range(len(s))])
                Gfd[:, :, a, i] = (Cp - Cm) / (2 * eps)
        assert np.abs(G - Gfd).max() < 1e-6 * np.abs(G).max()


def _moved(x, v, i, eps):
    y = x.copy()
    y[3 * v + i] += eps
    return y


def test_every_projection_keeps_linear_and_angular_momentum():
    """sum m dx = 0 and sum m x x dx = 0 for each constraint's correction, to round-off."""
    x = _perturbed(0.02)
    w = 1.0 / np.random.default_rng(1).uniform(0.5, 2.0, X.size // 3).repeat(3)
    m = 1.0 / w
    for s in _sets():
        idx = np.arange(len(s))
        at = np.full((len(s), s.m), 1e-3)
        dx = s.corrections(x, w, idx, np.zeros((len(s), s.m)), at)[1]
        mv = m.reshape(-1, 3)[s.nodes] * dx  # (n, k, 3)
        P = x.reshape(-1, 3)[s.nodes]
        scale = np.abs(mv).sum(axis=(1, 2)) * np.abs(P).max()
        assert np.abs(mv.sum(axis=1)).max() < 1e-13 * np.abs(mv).max()
        assert np.abs(np.cross(P, mv).sum(axis=1)).max() < 1e-13 * scale.max()


def test_a_distance_constraint_set_is_satisfied_after_enough_iterations():
    """Hard edge constraints (k = 1, PBD): every edge back at its rest length, to 1e-10."""
    s = EdgeDistance.of_mesh(MESH)
    x = _perturbed(0.01)
    w = np.ones(X.size)
    zeros = np.zeros((len(s), 1))
    errors = []
    for _ in range(400):
        s.sweep(x, w, zeros.copy(), zeros, np.ones(len(s)))
        errors.append(np.abs(s.values(x)).max())
    assert errors[-1] < 1e-10 * s.rest.min()
    assert errors[9] < 0.1 * errors[0]


@pytest.mark.parametrize("kind", ["edges", "volumes", "neohookean"])
def test_jacobi_and_gauss_seidel_both_converge(kind):
    """XPBD sweeps on a compliant set: both reach C + at lam = 0 (Jacobi in more sweeps).

    Their end points differ slightly (by 1-2 % of the motion here): the fixed point of XPBD
    depends on the path of the iterates (the g = 0 approximation, see xpbd.py).
    """
    mesh = fe.beam_mesh(0.2, 0.1, 0.1, cells=(2, 1, 1))
    X0 = mesh.p.T.ravel()
    s = {"edges": EdgeDistance.of_mesh(mesh, compliance=np.full(mesh.edges.shape[1], 1e-4)),
         "volumes": TetVolume(mesh, compliance=np.full(mesh.t.shape[1], 1e-2)),
         "neohookean": TetNeoHookean(mesh, mu=1e3, lam=2e3)}[kind]
    at = s.compliance / 1e-4
    x0 = X0 + 0.005 * np.random.default_rng(2).standard_normal(X0.size)
    w = np.ones(X0.size)
    w[:12] = 0.0  # four vertices held
    needed = {}
    for method in ("gauss_seidel", "jacobi"):
        x, lam = x0.copy(), np.zeros((len(s), s.m))
        residual = []
        for _ in range(4000):
            s.sweep(x, w, lam, at, np.ones(len(s)), method)
            residual.append(np.abs(s.values(x) + at * lam).max())
            if residual[-1] < 1e-10:
                break
        assert residual[-1] < 1e-10, (method, residual[-1])
        assert np.array_equal(x[:12], x0[:12])  # held vertices never move
        needed[method] = len(residual)
        motion = np.abs(x - x0).max()
        assert 0.0 < motion < 0.05
    assert needed["gauss_seidel"] < needed["jacobi"]


@pytest.mark.skipif(numba_kernels() is None, reason="numba not installed (or FEM_ELASTIC_NUMBA=0)")
@pytest.mark.parametrize("method", ["gauss_seidel", "jacobi"])
def test_numba_and_numpy_sweeps_agree(method, monkeypatch):
    x0 = _perturbed(0.01)
    w = 1.0 / np.random.default_rng(3).uniform(0.5, 2.0, X.size)
    for s in _sets():
        at = np.random.default_rng(4).uniform(0.0, 1e-2, (len(s), s.m))
        scale = np.full(len(s), 0.7)
        results = []
        for env in ("1", "0"):
            monkeypatch.setenv(fused.ENV, env)
            x, lam = x0.copy(), np.zeros((len(s), s.m))
            for _ in range(3):
                s.sweep(x, w, lam, at, scale, method, relaxation=1.5)
            results.append((x, lam))
        (xa, la), (xb, lb) = results
        assert np.abs(xa - xb).max() < 1e-11 * np.abs(xa).max()
        assert np.abs(la - lb).max() < 1e-10 * max(np.abs(la).max(), 1e-30)


def test_volume_constraint_values():
    s = TetVolume(MESH)
    assert np.allclose(s.values(1.1 * X), 1.1**3 - 1.0)
    rng = np.random.default_rng(5)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    rotated = (X.reshape(-1, 3) @ Q.T).ravel()
    assert np.abs(s.values(rotated)).max() < 1e-12


def test_bad_compliance_is_refused():
    with pytest.raises(fe.InvalidParameter, match="compliance"):
        EdgeDistance.of_mesh(MESH, compliance=-np.ones(MESH.edges.shape[1]))
    with pytest.raises(fe.InvalidParameter, match="mu and lam"):
        TetNeoHookean(MESH, mu=0.0, lam=1.0)
