"""Tests of fem_elastic.solvers.modal: a cantilever's first bending frequency against Euler-Bernoulli,
the rigid modes of a free body, the sqrt(E / rho) scaling, omega_max against a dense
generalized eigensolver, Rayleigh-Ritz monotonicity of the consistent-mass frequencies, and
the critical time step of explicit schemes against closed forms.

The integrators here are small stand-ins that give only what critical_time_step reads:
``explicit`` and ``step_matrix(h, omega, zeta)``, the one-step map of (q, v) on
q'' + 2 zeta omega q' + omega^2 q = 0.
"""

import math
from functools import lru_cache
from types import SimpleNamespace

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse.linalg as spla

import fem_elastic as fe
from fem_elastic.solvers.modal import (
    critical_time_step,
    max_frequency,
    modal_critical_time_step,
    natural_frequencies,
)

RHO = 1000.0  # kg/m^3


def oscillator(w, z):
    return np.array([[0.0, 1.0], [-w * w, -2.0 * z * w]])


class SymplecticEuler:
    explicit = True

    def step_matrix(self, h, w, z):
        # v1 = v + h (-w^2 q - 2 z w v);  q1 = q + h v1
        return np.array([[1 - h * h * w * w, h * (1 - 2 * h * z * w)], [-h * w * w, 1 - 2 * h * z * w]])


class ExplicitEuler:
    explicit = True

    def step_matrix(self, h, w, z):
        return np.eye(2) + h * oscillator(w, z)


class Midpoint:
    explicit = True

    def step_matrix(self, h, w, z):
        hA = h * oscillator(w, z)
        return np.eye(2) + hA + hA @ hA / 2


class RK4:
    explicit = True

    def step_matrix(self, h, w, z):
        hA = h * oscillator(w, z)
        hA2 = hA @ hA
        return np.eye(2) + hA + hA2 / 2 + hA2 @ hA / 6 + hA2 @ hA2 / 24


class ImplicitEuler:
    explicit = False

    def step_matrix(self, h, w, z):
        return np.linalg.inv(np.eye(2) - h * oscillator(w, z))


class Damped:
    """A model seen with Rayleigh damping (alpha 1/s, beta s): all else from the model."""

    def __init__(self, model, alpha=0.0, beta=0.0):
        self._model = model
        self.damping = SimpleNamespace(alpha=alpha, beta=beta)

    def __getattr__(self, name):
        return getattr(self._model, name)


def model_on(mesh, *, E=1.0e6, nu=0.3, order=1, fixed="left", density=RHO):
    return fe.Model(mesh, density=density, body=fe.ElasticBody(fe.LinearElastic(E=E, nu=nu), order=order),
                    fixed=fixed)


@lru_cache(maxsize=None)
def tiny(fixed="left"):
    """60 DOFs (48 free when clamped): at the module's cut-off, solved by dense LAPACK."""
    return model_on(fe.beam_mesh(0.4, 0.1, 0.1, cells=(4, 1, 1)), fixed=fixed)


@lru_cache(maxsize=None)
def small(fixed="left"):
    """189 DOFs: solved by ARPACK, still small enough to check against dense LAPACK."""
    return model_on(fe.beam_mesh(0.6, 0.2, 0.2, cells=(6, 2, 2)), fixed=fixed)


SIZES = {"tiny": tiny, "small": small}


# (1) cantilever against Euler-Bernoulli --------------------------------------------------------
def test_cantilever_first_bending_frequency():
    # L/h = 20, quadratic tets. Euler-Bernoulli leaves out shear and rotary inertia (they
    # lower f by O((h/L)^2) ~ 0.3 % here) and the 3-D clamp; the P2 discretisation raises it
    # (Rayleigh-Ritz: an upper bound). Measured: +0.56 % on this mesh, +0.16 % on (40, 2, 2);
    # 2 % leaves room for both while catching any factor error (2 pi, sqrt, a wrong I).
    L, h, E, nu = 1.0, 0.05, 1.0e9, 0.3
    model = model_on(fe.beam_mesh(L, h, h, cells=(20, 1, 1)), E=E, nu=nu, order=2)
    f = natural_frequencies(model, 3)
    f_eb = fe.RectangularCantilever(L, h, h, E=E, nu=nu).first_bending_frequency(RHO)
    assert f[0] == pytest.approx(f_eb, rel=0.02)
    assert f[1] == pytest.approx(f_eb, rel=0.02)  # square section: bending about y and z
    assert f[2] > 3 * f_eb  # then torsion / second bending, far above


# (2) a free body: six rigid modes, then the first elastic one -----------------------------------
@pytest.mark.parametrize("order", [1, 2])
def test_free_body_has_six_zero_frequencies(order):
    model = model_on(fe.beam_mesh(0.6, 0.2, 0.2, cells=(6, 2, 2)), fixed=None, order=order)
    f, modes = natural_frequencies(model, 8, return_modes=True)
    # Rigid modes come out at round-off level: measured < 1e-6 of the first elastic one.
    assert np.all(f[:6] < 1e-4 * f[6])
    assert f[6] > 0 and f[7] >= f[6]
    # the six are spanned by the rigid-body modes: their M-projection onto them is complete
    B = model.space.rigid_body_modes()
    M = model.mass_matrix
    P = B @ np.linalg.solve(B.T @ M @ B, B.T @ M @ modes[:, :6])
    assert np.abs(P - modes[:, :6]).max() < 1e-6 * np.abs(modes[:, :6]).max()
    # M-normalised and M-orthogonal
    assert np.allclose(modes.T @ M @ modes, np.eye(8), atol=1e-8)


def test_free_body_matches_dense_solver():
    # The elastic frequencies of the shifted solve agree with a dense generalized
    # eigensolver (no shift) to 1e-9: the shift costs no accuracy above the rigid modes.
    model = small(fixed=None)
    f = natural_frequencies(model, 10)
    _, K = model.linearize(model.X, project=False)
    lam = sla.eigh(K.toarray(), model.mass_matrix.toarray(), eigvals_only=True)
    f_dense = np.sqrt(np.maximum(lam[:10], 0)) / (2 * np.pi)
    assert f[6:] == pytest.approx(f_dense[6:], rel=1e-9)


@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_frequencies_do_not_depend_on_the_shift_invert_factor(monkeypatch, mass):
    # Each frequency is the Rayleigh quotient of its mode shape with K and M (K phi summed in
    # long double), so the factor ARPACK inverts with leaves only its second-order trace. A
    # slender beam (omega_max / omega_1 ~ 190): without the quotient the first frequency differed
    # by 5e-14 relative between SuperLU and the dense LU below (2.7e-13 between SuperLU and
    # CHOLMOD); the quotients agree to 4e-16.
    # Bound: a few ulps, plus the long-double sum's eps_ld (omega_max / omega_1)^2 ~ 2e-15.
    import fem_elastic.solvers.cholmod as cholmod

    model = fe.Model(fe.beam_mesh(1.0, 0.1, 0.1, cells=(10, 1, 1)), 1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(1e6, 0.3), order=1), fixed="left")
    monkeypatch.setattr(cholmod, "shift_invert_operator", lambda A: None)  # ARPACK's SuperLU
    f_lu = natural_frequencies(model, 3, mass=mass)

    def dense_inverse(A):  # a different factorisation, with different round-off
        lu = sla.lu_factor(A.toarray())
        return spla.LinearOperator(A.shape, matvec=lambda b: sla.lu_solve(lu, b), dtype=float)

    monkeypatch.setattr(cholmod, "shift_invert_operator", dense_inverse)
    f_dense = natural_frequencies(model, 3, mass=mass)
    assert np.abs(f_dense / f_lu - 1.0).max() < 4e-15


# (3) f scales as sqrt(E / rho) ------------------------------------------------------------------
def test_frequencies_scale_as_sqrt_E_over_rho():
    # K is exactly proportional to E and M to rho (linear material): the eigenvalues scale
    # exactly, to the eigensolver's precision (ARPACK to machine precision, ~1e-13 here).
    mesh = fe.beam_mesh(0.6, 0.2, 0.2, cells=(6, 2, 2))
    f1 = natural_frequencies(model_on(mesh, E=1.0e6), 4)
    f4 = natural_frequencies(model_on(mesh, E=4.0e6), 4)
    f9 = natural_frequencies(model_on(mesh, E=1.0e6, density=RHO / 9), 4)
    assert f4 == pytest.approx(2 * f1, rel=1e-8)
    assert f9 == pytest.approx(3 * f1, rel=1e-8)


@pytest.mark.parametrize("size", SIZES)
def test_lumped_mass_frequencies_and_modes(size):
    model = SIZES[size]()
    f, modes = natural_frequencies(model, 4, mass="lumped", return_modes=True)
    _, K = model.linearize(model.X, project=False)
    free = model.free
    Kf = K.toarray()[np.ix_(free, free)]
    lam = sla.eigh(Kf, np.diag(model.lumped_mass[free]), eigvals_only=True)[:4]
    assert f == pytest.approx(np.sqrt(lam) / (2 * np.pi), rel=1e-9)
    assert np.all(modes[~free] == 0.0)
    assert np.allclose((modes.T * model.lumped_mass) @ modes, np.eye(4), atol=1e-8)


# (4) omega_max against the dense generalized eigenvalue problem ----------------------------------
@pytest.mark.parametrize("size", SIZES)
@pytest.mark.parametrize("fixed", ["left", None])
@pytest.mark.parametrize("mass", ["lumped", "consistent"])
def test_max_frequency_matches_dense(size, fixed, mass):
    model = SIZES[size](fixed=fixed)
    _, K = model.linearize(model.X, project=False)
    free = model.free
    Kf = K.toarray()[np.ix_(free, free)]
    M = np.diag(model.lumped_mass) if mass == "lumped" else model.mass_matrix.toarray()
    Mf = M[np.ix_(free, free)]
    w_dense = math.sqrt(sla.eigh(Kf, Mf, eigvals_only=True)[-1])
    # Lanczos to a relative 1e-10 on the eigenvalue: 1e-8 on omega leaves margin.
    assert max_frequency(model, mass=mass) == pytest.approx(w_dense, rel=1e-8)
    if mass == "lumped":
        bound = max_frequency(model, upper_bound=True)
        assert w_dense <= bound < 4 * w_dense  # Gershgorin: above, and not absurdly so


def test_max_frequency_of_lumped_is_below_consistent():
    # For P1 row-sum lumping the lumped omega_max is the lower one (1-D bar: 2c/h vs 2 sqrt(3) c/h),
    # which is why explicit codes lump.
    assert max_frequency(tiny(), mass="lumped") < max_frequency(tiny(), mass="consistent")


# (5) critical time step: closed forms -----------------------------------------------------------
@lru_cache(maxsize=None)
def w_max():
    return max_frequency(tiny(), mass="lumped")


def test_symplectic_euler_undamped():
    # |eigenvalues| = 1 up to h omega = 2; the bisection stops at a relative 1e-12.
    assert critical_time_step(tiny(), SymplecticEuler()) == pytest.approx(2 / w_max(), rel=1e-9)


def test_rk4_undamped():
    # |R(i y)|^2 = 1 - y^6/72 + y^8/576 <= 1 for y^2 <= 8.
    assert critical_time_step(tiny(), RK4()) == pytest.approx(2 * math.sqrt(2) / w_max(), rel=1e-9)


@pytest.mark.parametrize("integrator", [ExplicitEuler(), Midpoint()], ids=["euler", "midpoint"])
def test_schemes_growing_at_every_step_have_no_stable_step(integrator):
    # Undamped: |1 + i y| > 1 and |1 + i y - y^2/2| > 1 for every y = h omega > 0.
    assert critical_time_step(tiny(), integrator) == 0.0


def test_explicit_euler_mass_proportional_damping():
    # |1 + h lambda|^2 = 1 - 2 h zeta omega + h^2 omega^2 <= 1  <=>  h <= 2 zeta / omega
    # (underdamped). alpha-damping: zeta = alpha / (2 omega), so h_c = alpha / omega^2,
    # smallest at omega_max (zeta = 0.01 there). At low omega zeta > 1, where
    # h_c = 2 / (omega (zeta + sqrt(zeta^2 - 1))) ~ 2 / alpha, far larger.
    alpha = 0.02 * w_max()
    dt = critical_time_step(Damped(tiny(), alpha=alpha), ExplicitEuler())
    assert dt == pytest.approx(alpha / w_max() ** 2, rel=1e-9)


def test_explicit_euler_overdamped_top_mode():
    # beta-damping: zeta = beta omega / 2; underdamped modes allow h <= 2 zeta / omega = beta,
    # overdamped ones h <= 2 / (omega (zeta + sqrt(zeta^2 - 1))) (the most negative real
    # eigenvalue inside the disc |1 + h lambda| <= 1), smaller: with zeta = 2 at omega_max
    # that is the limit.
    beta = 4.0 / w_max()
    dt = critical_time_step(Damped(tiny(), beta=beta), ExplicitEuler())
    assert dt == pytest.approx(2 / (w_max() * (2 + math.sqrt(3))), rel=1e-9)


def test_symplectic_euler_stiffness_proportional_damping():
    # det = 1 - 2 zeta y and tr = 2 - y^2 - 2 zeta y (y = h omega): the complex pair has
    # modulus sqrt(det) < 1, and an eigenvalue leaves through -1 where 1 + tr + det = 0,
    # y^2 + 4 zeta y - 4 = 0, y = 2 (sqrt(1 + zeta^2) - zeta), decreasing in omega for
    # zeta = beta omega / 2: the top mode decides (zeta = 0.1 there).
    beta = 0.2 / w_max()
    zeta = beta * w_max() / 2
    dt = critical_time_step(Damped(tiny(), beta=beta), SymplecticEuler())
    assert dt == pytest.approx(2 * (math.sqrt(1 + zeta**2) - zeta) / w_max(), rel=1e-9)


def test_implicit_is_unconditionally_stable_and_safety_scales():
    assert critical_time_step(tiny(), ImplicitEuler()) == math.inf
    full = critical_time_step(tiny(), SymplecticEuler())
    assert critical_time_step(tiny(), SymplecticEuler(), safety=0.5) == 0.5 * full


def test_modal_critical_time_step_closed_forms():
    assert modal_critical_time_step(SymplecticEuler(), 50.0) == pytest.approx(2 / 50.0, rel=1e-10)
    assert modal_critical_time_step(ExplicitEuler(), 50.0, zeta=0.1) == pytest.approx(0.2 * 2 / 50.0 / 2, rel=1e-9)
    assert modal_critical_time_step(ExplicitEuler(), 50.0) == 0.0


@pytest.mark.parametrize("name, factor", [("SymplecticEuler", 2.0), ("RK4", 2 * math.sqrt(2)),
                                          ("ExplicitEuler", 0.0), ("ImplicitEuler", math.inf)])
def test_package_integrators(name, factor):
    # The package's own integrators, where present, give the same closed forms.
    cls = getattr(fe, name, None)
    if cls is None:
        pytest.skip(f"fe.{name} not available")
    assert critical_time_step(tiny(), cls()) == pytest.approx(factor / w_max(), rel=1e-9)


# (6) Rayleigh-Ritz: consistent-mass frequencies fall as the space grows ----------------------------
def test_consistent_mass_frequencies_decrease_as_space_grows():
    # With the consistent mass and exact quadrature (both hold here), the k-th eigenvalue is a
    # min-max over the trial space; a larger space (nested: uniform refinement of the same
    # tets, or P2 on the same mesh) can only lower it. Not true of lumped mass, so not tested.
    # skfem's refinement keeps every coarse tet as a union of fine ones (but drops the named
    # boundaries and some orientations): clamp the x = 0 vertices by a mask instead.
    mesh = fe.beam_mesh(0.4, 0.1, 0.1, cells=(4, 1, 1))
    fine = fe.reorient(mesh.refined())

    def clamped(m, order=1):
        return model_on(m, order=order, fixed=m.p[0] == 0.0)

    coarse = natural_frequencies(clamped(mesh), 6)
    refined = natural_frequencies(clamped(fine), 6)
    quadratic = natural_frequencies(clamped(mesh, order=2), 6)
    tol = 1e-9 * coarse  # eigensolver round-off
    assert np.all(refined <= coarse + tol)
    assert np.all(quadratic <= coarse + tol)
    assert np.all(refined < 0.99 * coarse)  # and the refinement is not a no-op


# errors and prestress ---------------------------------------------------------------------------
def test_invalid_arguments():
    with pytest.raises(fe.InvalidParameter):
        natural_frequencies(tiny(), 0)
    with pytest.raises(fe.InvalidParameter):
        natural_frequencies(tiny(), 3, mass="diagonal")
    with pytest.raises(fe.InvalidParameter):
        natural_frequencies(tiny(), tiny().free.sum())
    with pytest.raises(fe.InvalidParameter):
        max_frequency(tiny(), mass="consistent", upper_bound=True)
    with pytest.raises(fe.InvalidParameter):
        critical_time_step(tiny(), object())
    with pytest.raises(fe.InvalidParameter):
        critical_time_step(tiny(), SymplecticEuler(), safety=1.5)


def test_unstable_state_raises():
    # A Neo-Hookean bar squeezed to 40 % of its length along x, then linearized there: the
    # compressed material's tangent has negative eigenvalues (bending of a column far past its
    # Euler load), so there are no real frequencies.
    mesh = fe.beam_mesh(0.4, 0.1, 0.1, cells=(4, 1, 1))
    model = fe.Model(mesh, density=RHO, body=fe.ElasticBody(fe.NeoHookean(E=1e6, nu=0.3)), fixed="left")
    x = model.X.reshape(-1, 3).copy()
    x[:, 0] *= 0.4
    with pytest.raises(fe.InvalidParameter, match="not a stable equilibrium"):
        natural_frequencies(model, 6, x=x.ravel())


def test_critical_step_counts_the_dashpots_of_a_spring_body():
    """A mass-spring body with k_d: the step critical_time_step returns stays stable (the
    undamped estimate blew up within 20 steps at k_d = 30 N s/m)."""
    mesh = fe.beam_mesh(length=1.0, width=0.1, height=0.1, cells=(10, 1, 1))
    for k_d in (30.0, 100.0):
        model = fe.Model(mesh, density=1000.0, body=fe.MassSpring(E=1e6, k_d=k_d), fixed="left",
                         gravity=(0, 0, -9.81))
        dt = fe.critical_time_step(model, fe.SymplecticEuler())
        fe.simulate(model, fe.SymplecticEuler(), 0.9 * dt, steps=400)  # raises Diverged if unstable
        with pytest.raises(fe.Diverged):
            fe.simulate(model, fe.SymplecticEuler(), 1.3 * dt, steps=400, check_stability=False)


def test_critical_step_refuses_a_class_and_bad_damping_ratios():
    from fem_elastic.solvers.modal import modal_critical_time_step

    model = fe.Model(fe.beam_mesh(cells=(2, 1, 1)), density=1000.0,
                     body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), fixed="left")
    with pytest.raises(fe.InvalidParameter, match="instance"):
        fe.critical_time_step(model, fe.SymplecticEuler)
    with pytest.raises(fe.InvalidParameter, match="zeta"):
        modal_critical_time_step(fe.SymplecticEuler(), 1.0, zeta=-0.1)
    with pytest.raises(fe.InvalidParameter, match="numbers"):
        modal_critical_time_step(fe.SymplecticEuler(), 1.0, zeta="a")
