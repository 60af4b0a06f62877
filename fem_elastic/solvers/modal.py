"""Modal analysis: natural frequencies, the top of the spectrum, stable time steps.

Small vibrations about a configuration x (an equilibrium: the reference
configuration, or a static solution for a prestressed body) obey
``M u'' + K u = 0`` on the free DOFs, with K (N/m) the Hessian of the model's
total potential energy at x and M (kg) its mass matrix. Its modes
``u = phi cos(omega t)`` solve the generalized eigenvalue problem

    K phi = omega^2 M phi,      f = omega / (2 pi)  (Hz),

with ``phi^T M phi = 1``. Fixed (and driven) DOFs are removed; a body with
no support has six rigid-body modes of omega = 0.

An explicit integrator applied to the same system decouples into one
damped modal oscillator per mode,

    q'' + 2 zeta omega q' + omega^2 q = 0,

whose one-step map (the integrator's ``step_matrix(h, omega, zeta)``) must
have spectral radius <= 1 for every mode: the largest such h over the
spectrum is the critical time step. The highest mode limits it, so only
omega_max, the top of the spectrum of the *lumped* mass problem (what
explicit schemes use), is needed. With Rayleigh damping
``C = alpha M + beta K_0`` the mode of frequency omega has the damping ratio
``zeta = alpha / (2 omega) + beta omega / 2``.

Nothing is cached on the model (it is immutable): callers keep what they
need.
"""

from __future__ import annotations

import logging
import math

from typing import TYPE_CHECKING, Literal, overload

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import InvalidParameter, UnderConstrained

if TYPE_CHECKING:  # for annotations only
    from ..physics.multibody import AnyModel
    from .solver_types import SteppingScheme

__all__ = ["natural_frequencies", "max_frequency", "critical_time_step", "modal_critical_time_step"]

log = logging.getLogger(__name__)

# Shift of the free-body eigenproblem, relative to the stiffness scale
# lam_scale = max_i K_ii / m_i (1/s^2): far above the round-off of the zero
# eigenvalues (~eps lam_max) and still a well-conditioned factorisation
# (condition ~ lam_max / |sigma| ~ 1e6, so the solves lose ~6 digits at most
# along the rigid modes only).
_FREE_SHIFT = 1e-6
# Eigenvalues above -_NEGATIVE_TOL * lam_scale are round-off (rigid modes of a
# free body), clipped to 0; below it the tangent is indefinite.
_NEGATIVE_TOL = 1e-8
# Dense eigensolvers below this many free DOFs (ARPACK needs k < n anyway).
_DENSE_MAX = 60
# Stability: a step is stable for a mode when rho(step matrix) <= 1 + _RHO_TOL.
# The tolerance absorbs the round-off of schemes with rho = 1 exactly
# (symplectic Euler), ~1e-16.
_RHO_TOL = 1e-12
# A scheme is *strictly* stable at h when rho <= 1 + _RHO_ROUNDOFF (a few tens
# of ulps); see modal_critical_time_step.
_RHO_ROUNDOFF = 64 * np.finfo(float).eps
# h omega range searched: below 1e-8 no one integrates; above 1e6 the scheme
# is taken as stable for every step.
_HW_MIN, _HW_MAX = 1e-8, 1e6
# Frequencies scanned below omega_max (fractions, log-spaced) by critical_time_step.
_SCAN = np.logspace(-3.0, 0.0, 50)


# -- helpers ------------------------------------------------------------------------------------
def _check_mass(mass: str) -> str:
    if mass not in ("consistent", "lumped"):
        raise InvalidParameter(
            f"mass must be 'consistent' (the Galerkin mass matrix) or 'lumped' (its diagonal "
            f"lumping, what explicit integrators use); got {mass!r}."
        )
    return mass


def _free_system(model, x, mass: str):
    """(K, M, free index, lumped diagonal) on the free DOFs; M is None for lumped mass."""
    _check_mass(mass)
    x = model.X if x is None else np.asarray(x, dtype=float)
    if x.shape != (model.ndofs,):
        raise InvalidParameter(
            f"x must be a flat DOF vector of shape ({model.ndofs},) (m), got shape {x.shape}."
        )
    _, K = model.linearize(x, project=False)
    idx = np.flatnonzero(model.free)
    if idx.size == 0:
        raise InvalidParameter("every DOF of the model is fixed: it has no modes.")
    K = sp.csr_matrix(K)[idx][:, idx]
    m_lumped = np.asarray(model.lumped_mass, dtype=float)[idx]
    M = sp.csr_matrix(model.mass_matrix)[idx][:, idx] if mass == "consistent" else None
    return K, M, idx, m_lumped


def _lam_scale(K, m_lumped) -> float:
    """max_i |K_ii| / m_i (1/s^2): a lower bound of the top eigenvalue, the problem's scale."""
    return float(np.max(np.abs(K.diagonal()) / m_lumped))


def _is_free_body(model) -> bool:
    """Whether the supports leave a rigid-body motion free (so K is singular)."""
    check = getattr(model, "check_supported", None)
    if check is None:  # pragma: no cover - every Model has it
        return model.free.all()
    try:
        check()
    except UnderConstrained:
        return True
    return False


def _growth(A) -> float:
    """``rho(A) - 1`` for a 2x2 one-step map A, without cancellation.

    Works with ``B = A - I``, whose eigenvalues mu give A's as ``1 + mu``: a
    step map is I + O(h), so B carries the information with full relative
    accuracy where A would round it away (for h omega = 1e-8 the eigenvalues
    of A agree with 1 to eight digits, and the discriminant of A's
    characteristic polynomial is pure round-off, whose square root, ~1e-8,
    would swamp the growth). For a complex pair ``|1 + mu|^2 = 1 + tr B +
    det B`` exactly; real eigenvalues come from the stable quadratic formula.
    Where the two eigenvalues coalesce (symplectic Euler's Jordan block at
    h = 2 / omega, critical damping) the discriminant is round-off and its
    square root errs by ~1e-8 |mu|, as with any eigensolver; that leaves the
    sign of the growth of a damped mode alone, and for symplectic Euler
    misplaces the boundary by ~1e-15 relative only.
    """
    A = np.asarray(A, dtype=float)
    if A.shape != (2, 2):
        raise InvalidParameter(f"step_matrix must return a (2, 2) array, got shape {A.shape}.")
    b00, b11 = A[0, 0] - 1.0, A[1, 1] - 1.0
    tr = b00 + b11
    det = b00 * b11 - A[0, 1] * A[1, 0]
    disc = tr * tr - 4.0 * det
    if not math.isfinite(disc):
        return math.inf
    if disc < 0.0:  # mu = a +- i b: |1 + mu|^2 = 1 + 2 a + a^2 + b^2 = 1 + tr + det
        r2 = 1.0 + tr + det
        return (tr + det) / (1.0 + math.sqrt(max(r2, 0.0)))
    q = -0.5 * (tr + math.copysign(math.sqrt(disc), tr))
    mus = [-q, det / -q] if q != 0.0 else [0.0, 0.0]
    # |1 + mu| - 1 = mu for mu >= -1, else -2 - mu
    return max(mu if mu >= -1.0 else -2.0 - mu for mu in mus)


def _zeta(model, omega: float, beta_body: float = 0.0) -> float:
    """Damping ratio of the mode omega (rad/s): Rayleigh's, plus the body's own dashpots
    modelled as stiffness-proportional with ``beta_body`` (s); 0 without damping."""
    d = getattr(model, "damping", None)
    alpha = float(getattr(d, "alpha", 0.0) or 0.0) if d is not None else 0.0
    beta = float(getattr(d, "beta", 0.0) or 0.0) if d is not None else 0.0
    return alpha / (2.0 * omega) + (beta + beta_body) * omega / 2.0


def _body_damping_beta(model, x, omega_max) -> float:
    """The body's own damping (a mass-spring body's dashpots) as an equivalent beta (s).

    The dashpots' damping matrix D is not proportional to K, so no single
    mode tells its effect; this takes the largest damping rate
    ``c_max = lambda_max(M^-1 D)`` (1/s) and pairs it with the highest
    frequency, ``zeta(omega_max) = c_max / (2 omega_max)``, i.e.
    ``beta = c_max / omega_max^2``: conservative, since the most damped
    motion is put on the fastest mode. Measured on a spring cantilever the
    step found is stable at 0.9x for k_d up to 100 N s/m (the undamped
    estimate diverged within 20 steps).
    """
    damping_matrix = getattr(model.body_potential, "damping_matrix", None)
    x = model.X if x is None else np.asarray(x, dtype=float)
    D = damping_matrix(x) if damping_matrix is not None else None
    if D is None or omega_max <= 0:
        return 0.0
    idx = np.flatnonzero(model.free)
    m = np.asarray(model.lumped_mass, dtype=float)[idx]
    s = sp.diags(1.0 / np.sqrt(m))
    A = (s @ sp.csr_matrix(D)[idx][:, idx] @ s).tocsr()
    if idx.size <= _DENSE_MAX:
        c_max = float(sla.eigh(A.toarray(), eigvals_only=True)[-1])
    else:
        c_max = float(spla.eigsh(A, k=1, which="LA", tol=1e-8, return_eigenvectors=False,
                                 v0=_start_vector(A.shape[0]))[0])
    return max(c_max, 0.0) / omega_max**2


def _start_vector(n: int) -> np.ndarray:
    """A fixed Lanczos start vector of length n (a seeded normal draw).

    ARPACK otherwise starts from its own random vector, and the same problem
    then gives estimates that differ in the last bits from call to call: a
    sub-stepping integrator's step count, and so a resumed run, would depend
    on it. A random-looking vector (not e.g. all ones) has a component along
    every mode almost surely.
    """
    return np.random.default_rng(20261121).standard_normal(n)


def _rayleigh_quotients(K, M, phi) -> np.ndarray:
    """``phi_k^T K phi_k / phi_k^T M phi_k`` for each column (1/s^2), K phi in extended precision.

    The quotient of an approximate eigenvector errs by the square of the
    vector's error, and it leaves out the round-off that ARPACK's Ritz values
    carry from the factorised ``K - sigma M``. In double precision it would not
    help: the rows of ``K phi`` cancel to ``lambda M phi``, losing about
    ``eps lambda_max / lambda`` relative, which for the first mode of a
    slender body is 1e-13-1e-12 (what ARPACK's values also err by). So K phi
    is summed in ``numpy.longdouble`` (64-bit mantissa on x86-64; on platforms
    where it is plain double the quotient is no worse than before), in blocks of
    rows to bound the extra memory. Measured on a 120-DOF P1 beam: the first
    frequency to 1e-16 of a long-double reference, where ARPACK's erred by
    1.6e-13 or 3e-13 depending on the factorisation it used.
    """
    K = sp.csr_matrix(K)
    phi_l = phi.astype(np.longdouble)
    num = np.zeros(phi.shape[1], dtype=np.longdouble)
    block = max(1, 2_000_000 // max(1, K.nnz // max(1, K.shape[0])))  # ~2M entries of K at once
    for start in range(0, K.shape[0], block):
        rows = K[start:start + block].astype(np.longdouble)
        num += np.einsum("ik,ik->k", phi_l[start:start + block], rows @ phi_l)
    den = np.einsum("ik,ik->k", phi, M @ phi)  # M is well conditioned: no cancellation
    return np.asarray(num / den, dtype=float)


# -- public -------------------------------------------------------------------------------------
@overload
def natural_frequencies(model: AnyModel, n: int = 6, *, x: np.ndarray | None = None,
                        mass: Literal["consistent", "lumped"] = "consistent",
                        return_modes: Literal[False] = False) -> np.ndarray: ...


@overload
def natural_frequencies(model: AnyModel, n: int = 6, *, x: np.ndarray | None = None,
                        mass: Literal["consistent", "lumped"] = "consistent",
                        return_modes: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...


def natural_frequencies(model: AnyModel, n: int = 6, *, x: np.ndarray | None = None,
                        mass: Literal["consistent", "lumped"] = "consistent",
                        return_modes: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """The n lowest natural frequencies (Hz) of small vibrations about x.

    Solves ``K phi = omega^2 M phi`` on the free DOFs with ARPACK in
    shift-invert mode (``scipy.sparse.linalg.eigsh``, ``which="LM"``), which
    finds the eigenvalues nearest the shift sigma:

    - a supported body (its fixed DOFs stop every rigid motion) has K
      positive definite at a stable state: sigma = 0;
    - a body with a free rigid motion has a singular K: sigma is a small
      negative number, ``-1e-6 max_i K_ii / m_i``, so ``K - sigma M`` is
      positive definite. Its six rigid-body modes come back with
      eigenvalues at round-off level (frequencies many orders below the
      first elastic one, not exactly 0), first in the list.

    Each eigenvalue is then refined as the Rayleigh quotient of its mode
    shape with K and M, ``K phi`` summed in extended precision: the first
    frequency of a slender body is then good to ~1e-16 relative, the same
    whichever factorisation ARPACK inverted with (its own values err by
    ~1e-13 there).

    Parameters
    ----------
    model : Model
        The body; its Hessian comes from ``model.linearize(x, project=False)``
        (every energy term: body, loads, contact).
    n : int
        How many frequencies, >= 1 and fewer than the free DOFs.
    x : numpy.ndarray, shape (ndofs,), optional
        Configuration to linearize about (m). Default: the reference
        configuration ``model.X``. For a prestressed body pass an
        equilibrium, e.g. a static solution's positions (the stress
        stiffening, or softening, is then in K).
    mass : {"consistent", "lumped"}
        The consistent mass matrix (default; with it, and exact quadrature,
        each frequency is an upper bound of the continuum one by
        Rayleigh-Ritz) or the lumped diagonal (what explicit integrators
        use).
    return_modes : bool
        Also return the mode shapes.

    Returns
    -------
    f : numpy.ndarray, shape (n,)
        Natural frequencies (Hz), ascending. Eigenvalues that are negative
        only by round-off (``> -1e-8 max_i K_ii / m_i``) give 0.
    modes : numpy.ndarray, shape (ndofs, n)
        Only with ``return_modes``: the mode shapes, ``phi^T M phi = 1``
        (1/sqrt(kg)), zero on fixed DOFs.

    Raises
    ------
    InvalidParameter
        ``n`` or ``mass`` is invalid, or the tangent at x has a clearly
        negative eigenvalue among those computed: x is not a stable
        equilibrium (a buckled or overloaded state), where small vibrations
        grow instead of oscillating and no frequency exists. The check sees
        only the n eigenvalues nearest the shift.

    Examples
    --------
    A steel cantilever 1 m x 5 cm x 5 cm on quadratic tets: the first two
    (bending, about y and z) 0.6 % above Euler-Bernoulli's 40.8 Hz.

    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(1.0, 0.05, 0.05, cells=(20, 1, 1)), density=7850.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=2e11, nu=0.3), order=2),
    ...                  fixed="left")
    >>> f = natural_frequencies(model, 3)
    >>> beam = fe.RectangularCantilever(1.0, 0.05, 0.05, E=2e11, nu=0.3)
    >>> round(beam.first_bending_frequency(7850.0), 1), [round(float(v), 1) for v in f]
    (40.8, [41.0, 41.0, 254.3])
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InvalidParameter(f"n must be a positive integer (how many frequencies), got {n!r}.")
    memory_check = getattr(model, "check_tangent_memory", None)  # shift-invert factorizes K - sigma M
    if memory_check is not None:
        memory_check("direct")
    K, M, idx, m_lumped = _free_system(model, x, mass)
    nfree = idx.size
    if n >= nfree:
        raise InvalidParameter(
            f"n = {n} frequencies asked, but the model has only {nfree} free DOFs; ask for fewer."
        )
    Mf = M if M is not None else sp.diags(m_lumped, format="csr")
    scale = _lam_scale(K, m_lumped)
    if nfree <= _DENSE_MAX:
        lam, phi = sla.eigh(K.toarray(), Mf.toarray(), subset_by_index=[0, n - 1])
    else:
        sigma = -_FREE_SHIFT * scale if _is_free_body(model) else 0.0
        # K - sigma M factorised once, by CHOLMOD where installed (else ARPACK's SuperLU)
        from .cholmod import shift_invert_operator

        OPinv = shift_invert_operator((K - sigma * Mf).tocsr() if sigma else K)
        lam, phi = spla.eigsh(K, k=n, M=Mf, sigma=sigma, which="LM", v0=_start_vector(nfree),
                              OPinv=OPinv)
    lam = _rayleigh_quotients(K, Mf, phi)
    order = np.argsort(lam)
    lam, phi = lam[order], phi[:, order]
    bad = lam < -_NEGATIVE_TOL * scale
    if bad.any():
        raise InvalidParameter(
            f"the stiffness at x has {int(bad.sum())} negative eigenvalue(s) among the {n} lowest "
            f"(omega^2 = {lam[0]:.3e} 1/s^2): x is not a stable equilibrium (buckled, overloaded "
            "or not an equilibrium at all), so small vibrations about it grow instead of "
            "oscillating. Linearize about a stable static solution, or reduce the load."
        )
    f = np.sqrt(np.maximum(lam, 0.0)) / (2.0 * math.pi)
    log.debug("natural frequencies (Hz): %s", f)
    if not return_modes:
        return f
    # M-normalise (ARPACK's vectors are M-orthonormal already; the dense path's too)
    norms = np.sqrt(np.einsum("ik,ik->k", phi, Mf @ phi))
    modes = np.zeros((model.ndofs, n))
    modes[idx] = phi / norms
    return f, modes


def max_frequency(model: AnyModel, *, x: np.ndarray | None = None,
                  mass: Literal["consistent", "lumped"] = "lumped",
                  upper_bound: bool = False) -> float:
    """The highest angular frequency omega_max (rad/s) of the free DOFs.

    omega_max^2 is the largest eigenvalue of ``M^-1 K`` (K the Hessian of
    the model's energy at x, on the free DOFs). It is what limits the step
    of an explicit integrator, which uses the lumped mass: hence the
    default.

    Methods:

    - default: Lanczos (``eigsh(..., k=1, which="LA")``), on
      ``D^-1/2 K D^-1/2`` for the lumped diagonal D, or on
      ``K phi = lam M phi`` for the consistent mass. Converged to a relative
      1e-10; Ritz values approach the top from below, so this is a lower
      bound to that accuracy.
    - ``upper_bound=True`` (lumped mass only): Gershgorin's bound,
      ``max_i sum_j |K_ij| / sqrt(m_i m_j)``: one pass over the nonzeros,
      never below the true value (typically 1.5-3x above it), so a time
      step from it is safe but pessimistic.

    Parameters
    ----------
    model : Model
        The body.
    x : numpy.ndarray, shape (ndofs,), optional
        Configuration (m); default the reference configuration.
    mass : {"lumped", "consistent"}
        Which mass matrix.
    upper_bound : bool
        Return Gershgorin's cheap upper bound instead of the eigenvalue.

    Returns
    -------
    float
        omega_max (rad/s), >= 0 (0 if K has no positive eigenvalue).

    Examples
    --------
    >>> import fem_elastic as fe
    >>> model = fe.Model(fe.beam_mesh(cells=(10, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), fixed="left")
    >>> w = max_frequency(model)
    >>> round(w), max_frequency(model, upper_bound=True) >= w
    (1148, True)
    """
    K, M, idx, m_lumped = _free_system(model, x, mass)
    if upper_bound:
        if mass != "lumped":
            raise InvalidParameter(
                "upper_bound=True is Gershgorin's bound on the lumped-mass problem; "
                "pass mass='lumped' (or upper_bound=False for the consistent mass)."
            )
        s = 1.0 / np.sqrt(m_lumped)
        A = abs(sp.diags(s) @ K @ sp.diags(s))
        return float(math.sqrt(max(float(np.asarray(A.sum(axis=1)).max()), 0.0)))
    if idx.size <= _DENSE_MAX:
        Md = np.diag(m_lumped) if M is None else M.toarray()
        lam = float(sla.eigh(K.toarray(), Md, eigvals_only=True)[-1])
    elif M is None:
        s = sp.diags(1.0 / np.sqrt(m_lumped))
        A = (s @ K @ s).tocsr()
        lam = float(spla.eigsh(A, k=1, which="LA", tol=1e-10, return_eigenvectors=False,
                               v0=_start_vector(A.shape[0]))[0])
    else:
        lam = float(spla.eigsh(K, k=1, M=M, which="LA", tol=1e-10, return_eigenvectors=False,
                               v0=_start_vector(K.shape[0]))[0])
    return math.sqrt(max(lam, 0.0))


def modal_critical_time_step(integrator, omega: float, zeta: float = 0.0) -> float:
    """Largest stable step (s) of an explicit scheme on one modal oscillator.

    The largest h with ``rho(integrator.step_matrix(h, omega, zeta)) <=
    1 + 1e-12`` (the tolerance absorbs the round-off of schemes with
    rho = 1 exactly, such as symplectic Euler), found by doubling h from
    ``1e-8 / omega`` until unstable and bisecting to a relative 1e-12.
    The stable set is assumed to be an interval [0, h_c].

    A scheme whose every step grows the mode (rho > 1 for all h > 0:
    explicit Euler or explicit midpoint without damping) would pass the
    tolerance for tiny steps, where its growth h^2 omega^2 / 2 (or
    (h omega)^4 / 8) falls below 1e-12. Such a "stable" interval is
    recognised because rho still exceeds 1 by more than round-off at
    half the step found, and 0.0 is returned: explicit Euler has no stable
    step for an undamped oscillator.

    Parameters
    ----------
    integrator : object
        Has ``step_matrix(h, omega, zeta) -> (2, 2)`` (the map of (q, v)).
    omega : float
        Angular frequency (rad/s), > 0.
    zeta : float
        Damping ratio (dimensionless), >= 0.

    Returns
    -------
    float
        h_c (s): 0.0 if no step is stable, ``math.inf`` if every step up to
        ``1e6 / omega`` is.

    Examples
    --------
    Symplectic Euler (``v1 = v + h a``, ``q1 = q + h v1``) is stable up to
    h = 2 / omega:

    >>> import numpy as np
    >>> class SymplecticEuler:
    ...     def step_matrix(self, h, w, z):
    ...         return np.array([[1 - h * h * w * w, h * (1 - 2 * h * z * w)],
    ...                          [-h * w * w, 1 - 2 * h * z * w]])
    >>> round(modal_critical_time_step(SymplecticEuler(), omega=100.0), 12)
    0.02
    """
    try:
        omega, zeta = float(omega), float(zeta)
    except (TypeError, ValueError):
        raise InvalidParameter(f"omega and zeta must be numbers, got {omega!r} and {zeta!r}.") from None
    if not (math.isfinite(omega) and omega > 0):
        raise InvalidParameter(f"omega must be finite and > 0 rad/s, got {omega!r}.")
    if not (math.isfinite(zeta) and zeta >= 0):
        raise InvalidParameter(f"zeta must be a finite damping ratio >= 0, got {zeta!r}.")

    def stable(h):
        return _growth(integrator.step_matrix(h, omega, zeta)) <= _RHO_TOL

    lo = _HW_MIN / omega
    if not stable(lo):
        return 0.0
    hi = 2.0 * lo
    while stable(hi):
        lo, hi = hi, 2.0 * hi
        if hi * omega > _HW_MAX:
            return math.inf
    while hi - lo > 1e-12 * lo:
        mid = 0.5 * (lo + hi)
        if stable(mid):
            lo = mid
        else:
            hi = mid
    if _growth(integrator.step_matrix(0.5 * lo, omega, zeta)) > _RHO_ROUNDOFF:
        return 0.0  # stable only within the tolerance: growing at every h
    return lo


def critical_time_step(model: AnyModel, integrator: SteppingScheme, *, x: np.ndarray | None = None,
                       safety: float = 1.0) -> float:
    """Largest stable time step (s) of an integrator on a model.

    Implicit integrators (``integrator.explicit`` False) return
    ``math.inf``. For explicit ones: omega_max from :func:`max_frequency`
    (lumped mass, Lanczos), then the largest h stable for every mode, by
    :func:`modal_critical_time_step` at 50 log-spaced frequencies in
    [omega_max / 1000, omega_max], each with its Rayleigh damping ratio
    ``zeta = alpha / (2 omega) + beta omega / 2`` (from ``model.damping``,
    undamped if it is None or absent; a mass-spring body's own dashpots add
    ``c_max / omega_max^2`` to beta, with c_max the largest eigenvalue of
    ``M^-1 D``: a conservative pairing of the strongest damping with the
    fastest mode), taking the smallest. The low end of
    the scan matters with damping, where the stable step need not fall with
    omega; without it the top mode decides. The step found is checked to be
    stable at every scanned frequency (and reduced by bisection if not).

    Closed forms for an undamped body: symplectic Euler ``2 / omega_max``,
    RK4 ``2 sqrt(2) / omega_max``; explicit Euler and explicit midpoint
    have no stable step (0.0). Explicit Euler with damping ratio zeta < 1 at
    omega_max: ``2 zeta / omega_max`` (the disc ``|1 + h lambda| <= 1``).

    Parameters
    ----------
    model : Model
        The body. Only Rayleigh damping (``model.damping``) is accounted
        for; a body's own dashpots are not.
    integrator : object
        Has ``explicit`` (bool) and ``step_matrix(h, omega, zeta)``.
    x : numpy.ndarray, shape (ndofs,), optional
        Configuration whose tangent gives omega_max (m); default the
        reference configuration. Stiffening materials raise omega_max under
        strain: pass the deformed state to bound a large-deformation run.
    safety : float
        Factor in (0, 1] applied to the step.

    Returns
    -------
    float
        dt (s); ``math.inf`` for implicit schemes; 0.0 when no step is stable.

    Examples
    --------
    >>> import numpy as np
    >>> import fem_elastic as fe
    >>> class SymplecticEuler:
    ...     explicit = True
    ...     def step_matrix(self, h, w, z):
    ...         return np.array([[1 - h * h * w * w, h * (1 - 2 * h * z * w)],
    ...                          [-h * w * w, 1 - 2 * h * z * w]])
    >>> model = fe.Model(fe.beam_mesh(cells=(10, 1, 1)), density=1000.0,
    ...                  body=fe.ElasticBody(fe.LinearElastic(E=1e6, nu=0.3)), fixed="left")
    >>> dt = critical_time_step(model, SymplecticEuler())
    >>> round(dt * max_frequency(model), 9)      # 2 / omega_max
    2.0
    """
    if isinstance(integrator, type):
        raise InvalidParameter(
            f"integrator must be an instance, e.g. {integrator.__name__}(), not the class."
        )
    explicit = getattr(integrator, "explicit", None)
    if explicit is None or not hasattr(integrator, "step_matrix"):
        raise InvalidParameter(
            f"integrator must have 'explicit' and 'step_matrix(h, omega, zeta)', e.g. "
            f"fe.SymplecticEuler(); got {integrator!r}."
        )
    if isinstance(safety, bool) or not isinstance(safety, (int, float, np.number)) or not (0 < safety <= 1):
        raise InvalidParameter(f"safety must be a number in (0, 1], got {safety!r}.")
    if not explicit:
        return math.inf
    w_max = max_frequency(model, x=x, mass="lumped")
    # contact springs not engaged at x still stiffen the system once touched: the
    # contact term adds a PSD matrix, so omega^2 <= omega_body^2 + omega_contact^2 (Weyl)
    g = getattr(model, "gravity_magnitude", 0.0) or None
    w_contact = max((ob.critical_omega(model.lumped_mass[0::3], g) for ob in getattr(model, "obstacles", ())),
                    default=0.0)
    w_max = math.hypot(w_max, w_contact)
    if w_max == 0.0:
        return math.inf  # no stiffness: nothing oscillates
    omegas = w_max * _SCAN
    beta_body = _body_damping_beta(model, x, w_max)
    zetas = [_zeta(model, w, beta_body) for w in omegas]
    h = min(modal_critical_time_step(integrator, w, z) for w, z in zip(omegas, zetas))
    if h == 0.0 or not math.isfinite(h):
        return h

    def all_stable(step):
        return all(_growth(integrator.step_matrix(step, w, z)) <= _RHO_TOL for w, z in zip(omegas, zetas))

    if not all_stable(h):  # a stable set that is not an interval for some mode
        hi, lo = h, 0.5 * h
        while not all_stable(lo):
            hi, lo = lo, 0.5 * lo
            if lo * w_max < _HW_MIN:
                return 0.0
        while hi - lo > 1e-12 * lo:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if all_stable(mid) else (lo, mid)
        h = lo
    log.debug("critical time step %.6g s (omega_max %.6g rad/s)", h, w_max)
    return safety * h
