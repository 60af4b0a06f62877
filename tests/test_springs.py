"""Tests of fem_elastic.physics.springs: derivatives by finite differences, the PSD projection, the
spring damper, a two-mass oscillator against its closed form, the calibrations' effective
moduli against their derivation, linearity in E, the shared mass and parameter checks.

Most tests run on a 0.2 x 0.1 x 0.1 m box of 12 tets whose vertices are moved by up to
20 % of the cell size, at a compressed random state (so that many springs are shorter
than at rest and the projection matters).
"""

import logging
from fractions import Fraction
from functools import lru_cache

import numpy as np
import pytest
import skfem

import fem_elastic as fe
from fem_elastic.discretization import Discretization
from fem_elastic.physics.springs import (
    SPRING_POISSON_RATIO,
    MassSpring,
    SpringPotential,
    lloyd_stiffness,
    van_gelder_stiffness,
)

E = 1.0e6  # Pa
CALIBRATIONS = [van_gelder_stiffness, lloyd_stiffness]
H_CELL = 0.1  # cell size of the distorted mesh (m)


def ids(f):
    return f.__name__


def rel_err(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


@lru_cache(maxsize=None)
def distorted_space() -> Discretization:
    mesh = fe.beam_mesh(0.2, 0.1, 0.1, cells=(2, 1, 1))
    rng = np.random.default_rng(1)
    mesh = skfem.MeshTet(mesh.p + rng.uniform(-0.02, 0.02, mesh.p.shape), mesh.t)
    fe.validate_mesh(mesh)
    return Discretization(mesh, 1)


@lru_cache(maxsize=None)
def potential(calibration, k_d=0.0) -> SpringPotential:
    return MassSpring(E=E, calibration=calibration, k_d=k_d).build(distorted_space())


@lru_cache(maxsize=None)
def compressed_state() -> np.ndarray:
    """x = 0.85 X + noise of 10 % of the cell size: most springs shorter than at rest."""
    space = distorted_space()
    rng = np.random.default_rng(2)
    x = 0.85 * space.X + 0.01 * rng.standard_normal(space.ndofs)
    x.setflags(write=False)
    return x


# (a) central finite differences ---------------------------------------------------------------
# Directions d have entries of the cell size times N(0, 1) and h = 1e-6, so lengths change by
# ~1e-7 m on springs of ~0.1 m: the truncation error is O((h |d| / l)^2) ~ 1e-12 relative and
# the cancellation error of the energy differences ~eps |E| / (h |dE|) ~ 1e-9 relative. 1e-6
# is far above both and far below any real error (a wrong term is O(1) relative).
FD_H = 1e-6
FD_TOL = 1e-6


@pytest.mark.parametrize("calibration", CALIBRATIONS, ids=ids)
def test_gradient_and_hessian_by_central_differences(calibration):
    pot = potential(calibration)
    x = compressed_state()
    g, H = pot.linearize(x)
    assert np.array_equal(g, pot.gradient(x))
    assert np.array_equal(H.toarray(), pot.hessian(x).toarray())
    rng = np.random.default_rng(7)
    for _ in range(3):
        d = H_CELL * rng.standard_normal(x.size)
        slope_fd = (pot.energy(x + FD_H * d) - pot.energy(x - FD_H * d)) / (2 * FD_H)
        assert abs(slope_fd - g @ d) <= FD_TOL * np.abs(g).sum() * np.abs(d).max()
        Hd_fd = (pot.gradient(x + FD_H * d) - pot.gradient(x - FD_H * d)) / (2 * FD_H)
        assert rel_err(Hd_fd, H @ d) <= FD_TOL


def test_projected_hessian_is_psd_and_exact_one_is_not():
    pot = potential(van_gelder_stiffness)
    x = compressed_state()
    assert np.mean(pot.lengths(x) < pot.rest_length) > 0.5  # precondition: mostly compressed
    Hp = pot.hessian(x, project=True).toarray()
    H = pot.hessian(x).toarray()
    assert np.array_equal(Hp, Hp.T) and np.array_equal(H, H.T)
    w = np.linalg.eigvalsh(Hp)
    # a sum of PSD 6x6 spring matrices: negative only by round-off of the largest eigenvalue
    assert w.min() >= -1e-10 * w.max()
    w_exact = np.linalg.eigvalsh(H)
    assert w_exact.min() < -1e-3 * w_exact.max()  # the projection had something to do
    # the projection only drops negative transverse terms: Hp - H is PSD
    assert np.linalg.eigvalsh(Hp - H).min() >= -1e-10 * w.max()


def test_projection_is_identity_when_every_spring_is_stretched():
    pot = potential(van_gelder_stiffness)
    x = 1.1 * distorted_space().X  # every spring 10 % longer than at rest
    assert rel_err(pot.hessian(x, project=True).toarray(), pot.hessian(x).toarray()) == 0.0


def test_hessian_at_rest_is_the_sum_of_k_n_nT_blocks():
    """At l = l0 the transverse term vanishes: H v = 0 for rigid motions, 6 zero modes."""
    space = distorted_space()
    pot = potential(van_gelder_stiffness)
    H = pot.hessian(space.X)
    B = space.rigid_body_modes()
    # relative to |H| |B|: round-off of the products, eps ~ 1e-16, times a few terms per row
    assert np.abs(H @ B).max() <= 1e-12 * abs(H).max() * np.abs(B).max()
    w = np.linalg.eigvalsh(H.toarray())
    # a tet mesh is a rigid framework: exactly the six rigid modes cost no energy
    assert np.sum(w < 1e-10 * w.max()) == 6


def test_zero_length_spring_has_a_finite_gradient_and_hessian():
    s = SpringPotential(np.array([0.0, 0, 0, 1, 0, 0]), [[0], [1]], [100.0])
    x = np.zeros(6)  # both nodes at the same point: no direction
    assert s.energy(x) == pytest.approx(50.0)  # 1/2 k l0^2 (J), exact in floating point
    assert np.array_equal(s.gradient(x), np.zeros(6))
    assert np.all(np.isfinite(s.hessian(x).toarray()))
    assert np.linalg.eigvalsh(s.hessian(x, project=True).toarray()).min() >= 0.0


def test_hessian_on_the_tet_pattern_matches_the_springs_own_pattern():
    space = distorted_space()
    pot = potential(lloyd_stiffness, k_d=2.0)
    x = compressed_state()
    own = SpringPotential(space.X, pot.edges, pot.stiffness, k_d=2.0)  # no pattern given
    assert space.pattern.owns(pot.hessian(x)) and space.pattern.owns(pot.damping_matrix(x))
    assert not space.pattern.owns(own.hessian(x))
    # the same terms summed into the same entries, possibly in another order: round-off only
    assert rel_err(pot.hessian(x).toarray(), own.hessian(x).toarray()) <= 1e-14
    assert rel_err(pot.damping_matrix(x).toarray(), own.damping_matrix(x).toarray()) <= 1e-14


# (b) damping along the springs -------------------------------------------------------------
def test_damping_force_matches_damping_matrix_and_dissipates():
    pot = potential(van_gelder_stiffness, k_d=3.0)
    x = compressed_state()
    rng = np.random.default_rng(3)
    v = rng.standard_normal(x.size)
    f = pot.damping_force(x, v)
    D = pot.damping_matrix(x)
    # f = -D v exactly, up to the round-off of a few products per entry
    assert rel_err(-(D @ v), f) <= 1e-13
    # the force is linear in v: a central difference in v is exact up to round-off, and
    # reproduces -D (FD_H relative perturbation; cancellation error ~eps / FD_H ~ 1e-10)
    w = rng.standard_normal(x.size)
    df = (pot.damping_force(x, v + FD_H * w) - pot.damping_force(x, v - FD_H * w)) / (2 * FD_H)
    assert rel_err(df, -(D @ w)) <= FD_TOL
    Dd = D.toarray()
    assert np.array_equal(Dd, Dd.T)
    assert np.linalg.eigvalsh(Dd).min() >= -1e-12 * np.abs(Dd).max()  # PSD up to round-off
    assert v @ f < 0.0  # dissipation: the damping power is negative


def test_damping_does_not_resist_rigid_motion():
    space = distorted_space()
    pot = potential(van_gelder_stiffness, k_d=3.0)
    x = space.X
    v = space.rigid_body_modes() @ np.array([0.3, -0.2, 0.1, 1.0, -2.0, 0.5])
    scale = 3.0 * np.abs(v).max()  # the force scale k_d |v| (N)
    # (v_j - v_i) . n = (omega x d) . n = 0: zero up to round-off of the relative velocity
    assert np.abs(pot.damping_force(x, v)).max() <= 1e-12 * scale


def test_single_spring_damper_force_by_hand():
    X = np.array([0.0, 0, 0, 0, 0, 2])
    s = SpringPotential(X, [[0], [1]], [10.0], k_d=0.5)
    v = np.array([1.0, 2, 3, 0, 0, -1])
    # n = e_z, (v_i - v_j) . n = 3 - (-1) = 4: f_i = -0.5 * 4 e_z, f_j = +0.5 * 4 e_z (N)
    assert np.array_equal(s.damping_force(X, v), [0, 0, -2.0, 0, 0, 2.0])


def test_no_damping_means_zeros_and_no_matrix():
    pot = potential(van_gelder_stiffness)
    x = compressed_state()
    assert np.array_equal(pot.damping_force(x, np.ones(x.size)), np.zeros(x.size))
    assert pot.damping_matrix(x) is None


# (c) a single spring against its closed form --------------------------------------------------
def test_two_masses_on_a_spring_oscillate_at_the_closed_form_frequency():
    """m1, m2 on a spring k, released with stretch A: l - l0 = A cos(omega t),
    omega = sqrt(k (m1 + m2) / (m1 m2)), and the momentum stays zero.

    A spring moving along its own axis has force exactly k (l - l0): the motion is a
    harmonic oscillation for any amplitude below l0, so the closed form is exact.
    """
    k, m1, m2, l0, A = 400.0, 2.0, 0.5, 0.3, 0.05  # N/m, kg, kg, m, m
    u = np.array([1.0, 2.0, -2.0]) / 3.0  # a unit vector along no axis
    X = np.concatenate([[0.1, 0.2, 0.3], [0.1, 0.2, 0.3] + l0 * u])
    spring = SpringPotential(X, [[0], [1]], [k])
    assert spring.rest_length[0] == pytest.approx(l0, rel=1e-15)
    m = np.repeat([m1, m2], 3)
    omega = np.sqrt(k * (m1 + m2) / (m1 * m2))
    period = 2.0 * np.pi / omega
    steps_per_period = 4000
    h = period / steps_per_period
    x = X.copy()
    x[3:] += A * u
    v = np.zeros(6)
    t, stretch, momentum = [], [], []
    for n in range(3 * steps_per_period):  # symplectic Euler: v first, then x with the new v
        v -= h * spring.gradient(x) / m
        x += h * v
        t.append((n + 1) * h)
        stretch.append(spring.lengths(x)[0] - l0)
        momentum.append((m * v).reshape(2, 3).sum(axis=0))
    t, s = np.array(t), np.array(stretch)
    # period from the upward zero crossings, interpolated linearly: near a zero the sine is
    # straight to O(h^3); symplectic Euler's frequency error is (omega h)^2 / 24 ~ 1e-7.
    up = np.where((s[:-1] < 0) & (s[1:] >= 0))[0]
    crossings = t[up] - s[up] * h / (s[up + 1] - s[up])
    assert len(crossings) == 3
    assert np.diff(crossings) == pytest.approx(period, rel=1e-5)
    # amplitude: symplectic Euler's orbit is an ellipse whose largest x is A / sqrt(1 -
    # (omega h)^2 / 4) ~ A (1 + 3e-7), and sampling misses the peak by <= (omega h)^2 / 2
    # ~ 1.2e-6 relative: 1e-5 is above both.
    assert np.abs(s).max() == pytest.approx(A, rel=1e-5)
    # equal and opposite forces: the momentum stays zero up to round-off (kg m/s)
    assert np.abs(momentum).max() <= 1e-12 * m1 * omega * A


# (d) effective moduli of the calibrations ------------------------------------------------------
# Method: a homogeneous strain eps is imposed on every vertex of a block, u = eps X. Springs
# at rest have the Hessian H = sum k [[n n^T, ...]], so the energy is 1/2 u^T H u and probing
# the six unit strains gives the block's 6x6 stiffness C (Voigt order, engineering shears)
# times its volume. Uniaxial stress along x (all other stresses zero, including the shears
# that an anisotropic network couples to) gives E_eff = 1 / S_11, nu_xy = -S_12 / S_11 with
# S = C^-1. On fe.beam_mesh every vertex has the same neighbourhood, so a homogeneous strain
# is the network's own equilibrium away from the free faces: these are its bulk moduli.
VOIGT = [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)]


def compliance(pot, X, volume):
    """S = C^-1 (1/Pa, Voigt, engineering shears) from the Hessian under the six homogeneous strains."""
    Xp = X.reshape(-1, 3)
    U = []
    for a, b in VOIGT:
        eps = np.zeros((3, 3))
        eps[a, b] = eps[b, a] = 1.0 if a == b else 0.5
        U.append((Xp @ eps.T).ravel())
    U = np.array(U).T
    return np.linalg.inv(U.T @ (pot.hessian(X) @ U) / volume)


def uniaxial_moduli(pot, X, volume):
    S = compliance(pot, X, volume)
    return 1.0 / S[0, 0], -S[0, 1] / S[0, 0], -S[0, 2] / S[0, 0]


def kuhn_lattice_moduli(weights):
    """Exact (E_x / E, nu_xy) of the beam_mesh spring lattice from its bond weights.

    ``weights`` maps a bond vector d to w = sum over the six tets of a unit cube containing
    that bond direction of k l^2 / E (m^3 per unit cube). C = sum w n n n n.
    """
    C = [[Fraction(0)] * 6 for _ in range(6)]
    for d, w in weights.items():
        l2 = sum(c * c for c in d)
        for i, (a, b) in enumerate(VOIGT):
            for j, (c, e) in enumerate(VOIGT):
                C[i][j] += Fraction(w) * d[a] * d[b] * d[c] * d[e] / l2**2
    n = 6  # invert C exactly by Gauss-Jordan
    M = [row[:] + [Fraction(int(i == j)) for j in range(n)] for i, row in enumerate(C)]
    for c in range(n):
        p = next(r for r in range(c, n) if M[r][c] != 0)
        M[c], M[p] = M[p], M[c]
        M[c] = [x / M[c][c] for x in M[c]]
        for r in range(n):
            if r != c and M[r][c] != 0:
                M[r] = [x - M[r][c] * y for x, y in zip(M[r], M[c])]
    S = [row[n:] for row in M]
    return 1 / S[0][0], -S[0][1] / S[0][0]


def test_van_gelder_lattice_moduli_by_counting_tets():
    """The documented 30/29 and 1/29, derived by hand.

    beam_mesh cuts each unit cube into the six tets 0 -> e_a -> e_a + e_b -> (1, 1, 1) (one
    per ordering a, b, c of the axes), volume 1/6 each. Each tet holds one edge along each
    axis, two face diagonals e_a + e_b, e_b + e_c and the body diagonal. With van Gelder's
    k l^2 = E sum V_t, the weight of a bond direction is (number of tets holding it) / 6:
    axis 6/6, face diagonal (1, 1, 0) 4/6 (the orderings with a, b adjacent), body 6/6.
    """
    w = {(1, 0, 0): 1, (0, 1, 0): 1, (0, 0, 1): 1, (1, 1, 1): 1,
         (1, 1, 0): Fraction(2, 3), (1, 0, 1): Fraction(2, 3), (0, 1, 1): Fraction(2, 3)}
    assert kuhn_lattice_moduli(w) == (Fraction(30, 29), Fraction(1, 29))


# (E_x / E, nu_xy) documented in the springs module docstring. van Gelder: derived above.
# Lloyd: the same lattice sum with each Kuhn tet's six constants from the exact rational
# solution of the fit's normal equations (E_x / E = 1594848683626 / 1239437190795 at nu = 1/4,
# 96579825516950 / 25558363014153 at nu = 0.45); the fit itself is checked independently in
# test_lloyd_fit_is_the_frobenius_least_squares_fit.
DOCUMENTED = [
    (van_gelder_stiffness, 0.25, 30 / 29, 1 / 29),
    (lloyd_stiffness, 0.25, 1594848683626 / 1239437190795, 660240 / 40248001),
    (lloyd_stiffness, 0.45, 96579825516950 / 25558363014153, 2170464 / 143095123),
]


@pytest.mark.parametrize("calibration, nu, E_ratio, nu_eff", DOCUMENTED,
                         ids=["van_gelder", "lloyd-0.25", "lloyd-0.45"])
def test_effective_moduli_of_a_block_under_uniaxial_stress(calibration, nu, E_ratio, nu_eff):
    L, W, Hh = 2.0, 1.0, 1.0  # m; cubes of 0.5 m
    space = Discretization(fe.beam_mesh(L, W, Hh, cells=(4, 2, 2)), 1)
    pot = MassSpring(E=E, nu=nu, calibration=calibration).build(space)
    E_eff, nu_y, nu_z = uniaxial_moduli(pot, space.X, L * W * Hh)
    # Every spring constant is a sum of per-tet terms, so the block's affine energy is the
    # exact sum of its tets' energies (free faces included): only round-off (~1e-14) separates
    # the measurement from the derivation. 1e-9 leaves room for it and catches any real error.
    assert E_eff / E == pytest.approx(E_ratio, rel=1e-9)
    assert nu_y == pytest.approx(nu_eff, abs=1e-9)
    assert nu_z == pytest.approx(nu_eff, abs=1e-9)
    # far from 1/4, the value of an isotropic network: this mesh makes the network anisotropic
    assert nu_y < SPRING_POISSON_RATIO / 5


def test_the_measuring_method_gives_E_and_nu_for_fem():
    """The same probe on linear P1 FEM returns the material's E and nu (the patch test)."""
    space = Discretization(fe.beam_mesh(2.0, 1.0, 1.0, cells=(4, 2, 2)), 1)
    pot = fe.ElasticBody(fe.LinearElastic(E=E, nu=0.3)).build(space)
    E_eff, nu_y, nu_z = uniaxial_moduli(pot, space.X, 2.0)
    assert E_eff / E == pytest.approx(1.0, rel=1e-9)  # round-off only, as above
    assert nu_y == pytest.approx(0.3, abs=1e-9) and nu_z == pytest.approx(0.3, abs=1e-9)


def test_lloyd_fit_is_the_frobenius_least_squares_fit():
    """lloyd_stiffness's normal equations against a plain lstsq on explicit 12x12 matrices."""
    p = np.array([[0.0, 0, 0], [1.0, 0.1, 0], [0.2, 0.9, 0.1], [0.3, 0.2, 0.8]])
    mesh = fe.mesh_from_arrays(p, [[0, 1, 2, 3]])
    space = Discretization(mesh, 1)
    nu = 0.3
    K_t = fe.ElasticBody(fe.LinearElastic(E=E, nu=nu)).build(space).hessian(space.X).toarray()
    node = space.vertex_dofs[:, 0] // 3
    edges = node[np.asarray(mesh.edges)]
    S = [SpringPotential(space.X, edges[:, [e]], 1.0).hessian(space.X).toarray()
         for e in range(6)]
    A = np.stack([s.ravel() for s in S], axis=1)
    k_ref = np.linalg.lstsq(A, K_t.ravel(), rcond=None)[0]
    k = lloyd_stiffness(mesh, E, nu)
    assert (k > 0).all()  # a well-shaped tet: nothing clamped
    # two solutions of the same well-conditioned 6x6 problem: round-off only
    assert k == pytest.approx(k_ref, rel=1e-10)


def test_lloyd_clamps_negative_constants_and_says_so(caplog):
    p = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 0.9, 0], [0.5, 0.3, 0.3]])  # a sliver
    mesh = fe.mesh_from_arrays(p, [[0, 1, 2, 3]])
    with caplog.at_level(logging.WARNING, logger="fem_elastic.physics.springs"):
        k = lloyd_stiffness(mesh, E)
    assert (k >= 0).all() and np.sum(k == 0) == 2
    assert "2 of 6 fitted spring constants were negative" in caplog.text


def test_van_gelder_formula_on_one_tet():
    p = np.array([[0.0, 0, 0], [2.0, 0, 0], [0, 1.0, 0], [0, 0, 3.0]])
    mesh = fe.mesh_from_arrays(p, [[0, 1, 2, 3]])
    k = van_gelder_stiffness(mesh, E)
    e = np.asarray(mesh.edges)
    l2 = ((p[e[1]] - p[e[0]]) ** 2).sum(axis=1)
    assert k == pytest.approx(E * 1.0 / l2, rel=1e-14)  # V = 2 * 1 * 3 / 6 = 1 m^3


# (e) the body in a Model ----------------------------------------------------------------------
@pytest.mark.parametrize("calibration", CALIBRATIONS, ids=ids)
def test_doubling_E_halves_the_cantilever_deflection(calibration):
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(10, 1, 1))
    tips = []
    for E_ in (E, 2 * E):
        model = fe.Model(mesh, 1000.0, body=MassSpring(E=E_, calibration=calibration),
                         fixed="left", traction={"right": (0.0, 0.0, -0.01)})
        tips.append(-fe.solve_static(model).displacement[:, 2].min())
    slope = tips[0] / 1.0  # tip deflection over the length
    assert 0.0 < slope < 1e-5  # precondition: a small load
    # Every k is proportional to E, so the linear response is exactly 1/E; what is left is
    # the geometric nonlinearity, of relative size O(deflection / length) (the mesh is not
    # mirror-symmetric, so the quadratic term does not vanish), and Newton's rtol 1e-8.
    assert tips[0] / tips[1] == pytest.approx(2.0, rel=10 * slope + 1e-7)


def test_springs_and_fem_share_the_mass():
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(4, 1, 1))
    springs = fe.Model(mesh, 1200.0, body=MassSpring(E=E), fixed="left")
    fem = fe.Model(mesh, 1200.0, body=fe.ElasticBody(fe.LinearElastic(E=E, nu=0.25)),
                   fixed="left")
    assert np.array_equal(springs.lumped_mass, fem.lumped_mass)
    assert (springs.mass_matrix != fem.mass_matrix).nnz == 0
    assert springs.lumped_mass.sum() / 3 == pytest.approx(1200.0 * 0.01, rel=1e-12)  # rho V


def test_model_uses_the_body_potential_and_its_pattern():
    mesh = fe.beam_mesh(1.0, 0.1, 0.1, cells=(4, 1, 1))
    model = fe.Model(mesh, 1000.0, body=MassSpring(E=E, k_d=0.5), fixed="left")
    pot = model.body_potential
    assert isinstance(pot, SpringPotential) and isinstance(pot, fe.Potential)
    assert pot.edges.shape == (2, mesh.edges.shape[1]) == (2, pot.stiffness.size)
    assert pot.rest_length.min() > 0 and (pot.k_d == 0.5).all()
    g, H = model.linearize(model.X)
    assert np.array_equal(g, np.zeros(model.ndofs)) and model.space.pattern.owns(H)
    assert model.energy(model.X) == 0.0


def test_roundoff_floors_are_on_the_scale_of_the_fem_ones():
    """Both estimate eps x stiffness x length scale: their ratio is an O(1) number."""
    space = Discretization(fe.beam_mesh(1.0, 0.1, 0.1, cells=(4, 1, 1)), 1)
    springs = MassSpring(E=E).build(space)
    fem = fe.ElasticBody(fe.LinearElastic(E=E, nu=0.25)).build(space)
    for a, b in ((springs.energy_roundoff(), fem.energy_roundoff()),
                 (springs.gradient_roundoff(), fem.gradient_roundoff())):
        assert 0.1 < a / b < 10.0


def test_a_nu_springs_cannot_represent_is_reported(caplog):
    mesh = fe.beam_mesh(cells=(2, 1, 1))
    with caplog.at_level(logging.WARNING, logger="fem_elastic.physics.springs"):
        fe.Model(mesh, 1000.0, body=MassSpring(E=E))  # nu = 1/4: nothing to say
    assert caplog.text == ""
    for calibration, says in ((van_gelder_stiffness, "ignores nu"),
                              (lloyd_stiffness, "target of its least-squares fit")):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="fem_elastic.physics.springs"):
            fe.Model(mesh, 1000.0, body=MassSpring(E=E, nu=0.45, calibration=calibration))
        assert "cannot represent nu = 0.45" in caplog.text and says in caplog.text
    assert "ignored" in MassSpring(E=E, nu=0.45).note
    assert MassSpring.effective_poisson_ratio == 0.25


# (f) parameters -------------------------------------------------------------------------------
@pytest.mark.parametrize("kwargs, says", [
    (dict(E=0.0), "Young's modulus E must be > 0"),
    (dict(E=-1.0), "Young's modulus E must be > 0"),
    (dict(E=float("nan")), "E must be finite"),
    (dict(E="1e6"), "E must be a real number"),
    (dict(E=E, nu=0.5), "nu must be < 0.5"),
    (dict(E=E, nu=-1.0), "nu must be > -1"),
    (dict(E=E, k_d=-1.0), "k_d (spring damping, N s/m) must be a finite number >= 0"),
    (dict(E=E, k_d=float("inf")), "k_d (spring damping, N s/m) must be a finite number >= 0"),
    (dict(E=E, k_d=True), "k_d (spring damping, N s/m) must be a finite number >= 0"),
    (dict(E=E, order=2), "fe.ElasticBody(material, order=2)"),
    (dict(E=E, calibration="van_gelder"), "calibration must be a function"),
])
def test_bad_parameters_raise_invalid_parameter(kwargs, says):
    with pytest.raises(fe.InvalidParameter) as err:
        MassSpring(**kwargs)
    assert says in str(err.value)


def test_a_bad_calibration_result_is_caught():
    bad = MassSpring(E=E, calibration=lambda mesh, E, nu: np.ones(3))
    with pytest.raises(fe.InvalidParameter, match="one per mesh edge"):
        fe.Model(fe.beam_mesh(cells=(2, 1, 1)), 1000.0, body=bad)


def test_build_on_quadratic_tets_is_refused():
    space = Discretization(fe.beam_mesh(cells=(1, 1, 1)), 2)
    with pytest.raises(fe.InvalidParameter, match="order 1"):
        MassSpring(E=E).build(space)


@pytest.mark.parametrize("edges, k, says", [
    ([[0], [0]], [1.0], "two different nodes"),
    ([[0], [2]], [1.0], "must lie in"),
    ([0, 1], [1.0], "(2, n_springs)"),
    ([[0], [1]], [-1.0], "stiffness must be finite and >= 0"),
    ([[0], [1]], [1.0, 2.0], "one per spring"),
])
def test_spring_potential_checks_its_arrays(edges, k, says):
    with pytest.raises(fe.InvalidParameter) as err:
        SpringPotential(np.array([0.0, 0, 0, 1, 0, 0]), edges, k)
    assert says in str(err.value)


def test_van_gelder_network_is_anisotropic_as_documented():
    """Young's modulus along a direction n, 1 / (s . S s) with s the Voigt form of n n (stress
    n n, engineering strains), from the 6x6 stiffness of the network under homogeneous strains.

    With van Gelder's constants the block's energy is a sum over tets (k l^2 = E sum V_t), so
    free surfaces do not enter and the values are the lattice's exact fractions (documented in
    fem_elastic.physics.springs): 30/29 along x, 10/7 along the shared diagonal (1, 1, 1), 5/6 along
    the face diagonal (1, 1, 0), 3/8 along (1, -1, 0). Tolerance: round-off of a 6x6 inverse.
    """
    space = Discretization(fe.beam_mesh(2.0, 1.0, 1.0, cells=(4, 2, 2)), 1)
    S = compliance(MassSpring(E=1.0).build(space), space.X, 2.0)  # block volume 2 m^3

    def modulus(n):
        n = np.asarray(n, float) / np.linalg.norm(n)
        s = np.array([n[a] * n[b] for a, b in VOIGT])
        return 1.0 / (s @ S @ s)

    for n, expected in (((1, 0, 0), 30 / 29), ((1, 1, 1), 10 / 7), ((1, 1, 0), 5 / 6), ((1, -1, 0), 3 / 8)):
        assert abs(modulus(n) - expected) < 1e-12, (n, modulus(n), expected)
