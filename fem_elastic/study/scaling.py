"""How the cost of the basic operations grows with the mesh: a power-law fit of time against tets.

:func:`measure_scaling` times, on this machine, three operations on a family of
cantilever beams of growing size (1 x 0.1 x 0.1 m, Neo-Hookean, P1, held at x = 0,
gravity along -z):

- ``"assembly"``: the residual and the PSD-projected tangent, ``model.linearize(x)``,
  in a bent state (half the beam in compression, where the Neo-Hookean tangent is
  indefinite, so the projection has work to do);
- ``"implicit step"``: one ``fe.ImplicitEuler`` step of dt = 1/60 s from rest under
  gravity (Newton on the projected tangent, AMG-CG by default);
- ``"explicit step"``: one ``fe.SymplecticEuler`` step from the bent state.

:class:`ScalingResult` holds the medians and fits ``log t = a + p log n_tets`` by least
squares (:func:`fit_power_law`): p is the scaling exponent, and ``predict`` extrapolates
the time of a larger mesh. Per element the work of assembly and of an explicit step is
constant, so their p is 1 up to cache effects; an implicit step is as near-linear as its
linear solver (AMG-CG: iterations nearly independent of n; a sparse direct solve's fill
grows faster than n).
"""

from __future__ import annotations

import contextlib
import logging
import numbers
import statistics
import time
from dataclasses import dataclass, field

import numpy as np

from ..discretization import fused
from ..dynamics.integrators import ImplicitEuler, SymplecticEuler
from ..dynamics.state import State
from ..errors import InvalidParameter
from ..geometry.mesh import beam_mesh
from ..materials import NeoHookean
from ..physics.elastic_body import ElasticBody
from ..physics.model import Model
from ..solvers.linear_solvers import AMGSolver, DirectSolver, _have_pyamg

__all__ = ["FULL_SIZES", "OPERATIONS", "QUICK_SIZES", "ScalingResult", "beam_cells", "bent_state",
           "fit_power_law", "measure_scaling"]

logger = logging.getLogger(__name__)

#: the operations :func:`measure_scaling` can time
OPERATIONS = ("assembly", "implicit step", "explicit step")
#: target tet counts of the quick run (seconds) and of the full one (a few minutes)
QUICK_SIZES = (1000, 2500, 5000, 10000, 20000)
FULL_SIZES = (5000, 10000, 20000, 40000, 80000, 153600)

#: s, the implicit step (a frame at 60 Hz) and the explicit one (below the critical step of
#: every mesh here: about 3e-5 s at 153,600 tets, larger on coarser meshes)
DT_IMPLICIT = 1.0 / 60.0
DT_EXPLICIT = 1.0e-6
#: s, a fast operation is timed in batches of calls that last at least this long, so that a
#: sample of a 0.1 ms explicit step is not the timer's and the scheduler's noise
_MIN_SAMPLE = 0.02
_MAX_BATCH = 200
_CLOCKS = {"wall": time.perf_counter, "process": time.process_time}


def beam_cells(n_tets: int) -> tuple[int, int, int]:
    """Cells (nx, k, k) of the 1 x 0.1 x 0.1 m beam with about ``n_tets`` tets.

    ``beam_mesh`` splits each cell into 6 tets, so the beam has ``6 nx k^2`` tets; k is
    the integer nearest ``(n_tets / 37.5)^(1/3)`` (which keeps the cells near cubes,
    nx = 6.25 k for a 10:1 beam) and nx the integer nearest ``n_tets / (6 k^2)``.

    Parameters
    ----------
    n_tets : int
        Target number of tets, >= 6.

    Returns
    -------
    tuple of 3 int

    Examples
    --------
    >>> beam_cells(153600), beam_cells(5000)
    ((100, 16, 16), (33, 5, 5))
    """
    if isinstance(n_tets, bool) or not isinstance(n_tets, numbers.Integral) or n_tets < 6:
        raise InvalidParameter(f"n_tets must be an integer >= 6 (one cell), got {n_tets!r}.")
    k = max(1, round((n_tets / 37.5) ** (1.0 / 3.0)))
    nx = max(1, round(n_tets / (6 * k * k)))
    return (int(nx), int(k), int(k))


def fit_power_law(n, t) -> tuple[float, float]:
    """Least-squares fit of ``log t = a + p log n`` (natural logarithms).

    Parameters
    ----------
    n, t : array_like
        Sizes and times (any positive units), at least two distinct sizes.

    Returns
    -------
    a, p : float
        ``t ~ exp(a) n^p``; p is the scaling exponent.

    Examples
    --------
    >>> a, p = fit_power_law([1e3, 1e4, 1e5], [2e-3, 2e-2, 2e-1])
    >>> round(p, 12), round(float(np.exp(a)), 12)
    (1.0, 2e-06)
    """
    n = np.asarray(n, dtype=float)
    t = np.asarray(t, dtype=float)
    if n.shape != t.shape or n.ndim != 1:
        raise InvalidParameter(f"n and t must be 1-D of equal length, got {n.shape} and {t.shape}.")
    if not (np.all(np.isfinite(n)) and np.all(np.isfinite(t)) and np.all(n > 0) and np.all(t > 0)):
        raise InvalidParameter("n and t must be positive and finite to fit a power law on their logs.")
    if np.unique(n).size < 2:
        raise InvalidParameter(f"a power law needs at least two distinct sizes, got {n.tolist()}.")
    p, a = np.polyfit(np.log(n), np.log(t), 1)
    return float(a), float(p)


@dataclass(frozen=True)
class ScalingResult:
    """Times of each operation against the mesh size, from :func:`measure_scaling`.

    Attributes
    ----------
    n_tets, n_dofs : numpy.ndarray
        Tets and DOFs of each mesh, ``(n_sizes,)``.
    cells : tuple of tuple of 3 int
        The beam's cells at each size.
    samples : dict of str to list of numpy.ndarray
        Per operation, per size, the seconds of each timed call (a sample of a batch is
        the batch's time divided by its calls).
    fused : bool
        Whether the fused numba kernels ran (numba importable, ``FEM_ELASTIC_NUMBA`` not 0, and
        kernels for the material).
    clock : {"wall", "process"}
        What was timed: wall time, or the process's CPU time (see :func:`measure_scaling`).
    newton_iterations, linear_iterations : numpy.ndarray
        Of the last implicit step timed at each size (``StepStats``): Newton iterations
        and CG iterations summed over them; empty if the implicit step was not timed.
    """

    n_tets: np.ndarray
    n_dofs: np.ndarray
    cells: tuple
    samples: dict
    fused: bool
    clock: str = "wall"
    newton_iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    linear_iterations: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    @property
    def operations(self) -> tuple[str, ...]:
        """The operations timed, in :data:`OPERATIONS`' order."""
        return tuple(op for op in OPERATIONS if op in self.samples)

    @property
    def seconds(self) -> dict[str, np.ndarray]:
        """Median seconds per call, per operation, ``(n_sizes,)`` each."""
        return {op: np.array([statistics.median(s) for s in self.samples[op]])
                for op in self.operations}

    def fit(self, operation: str) -> tuple[float, float]:
        """(a, p) of ``log t = a + p log n_tets`` for ``operation`` (:func:`fit_power_law`)."""
        if operation not in self.samples:
            raise InvalidParameter(f"{operation!r} was not timed; timed: {list(self.operations)}.")
        return fit_power_law(self.n_tets, self.seconds[operation])

    @property
    def exponents(self) -> dict[str, float]:
        """The fitted exponent p of each operation."""
        return {op: self.fit(op)[1] for op in self.operations}

    def predict(self, operation: str, n_tets) -> np.ndarray:
        """Seconds per call at ``n_tets`` tets, from the fitted power law (an extrapolation
        beyond the sizes measured assumes the same regime: same solver, memory not exceeded)."""
        a, p = self.fit(operation)
        return np.exp(a) * np.asarray(n_tets, dtype=float) ** p

    def summary(self) -> str:
        """A text table: median ms per size and operation, the fitted exponents."""
        ops = self.operations
        unit = " CPU ms" if self.clock == "process" else " ms"
        head = f"{'tets':>9} {'DOFs':>9} " + " ".join(f"{op + unit:>22}" for op in ops)
        lines = [head, "-" * len(head)]
        seconds = self.seconds
        for i, (nt, nd) in enumerate(zip(self.n_tets, self.n_dofs)):
            lines.append(f"{nt:9,d} {nd:9,d} "
                         + " ".join(f"{seconds[op][i] * 1e3:22.2f}" for op in ops))
        if len(self.newton_iterations) == len(self.n_tets):
            lines.append("implicit step: Newton iterations "
                         + ", ".join(str(k) for k in self.newton_iterations)
                         + "; CG iterations " + ", ".join(str(k) for k in self.linear_iterations))
        lines.append("fitted exponent p (t ~ n_tets^p): "
                     + ", ".join(f"{op} {p:.2f}" for op, p in self.exponents.items()))
        return "\n".join(lines)

    def plot(self, ax=None):
        """Log-log plot: the medians as markers, each fitted power law as a line, p in the legend.

        Parameters
        ----------
        ax : matplotlib.axes.Axes, optional
            Drawn into a new figure if None (matplotlib is imported here).

        Returns
        -------
        matplotlib.axes.Axes
        """
        if ax is None:
            import matplotlib.pyplot as plt

            _, ax = plt.subplots(figsize=(6.5, 4.5))
        n = np.asarray(self.n_tets, dtype=float)
        line = np.geomspace(n.min(), n.max(), 50)
        for op, marker in zip(self.operations, "osD"):
            a, p = self.fit(op)
            dots = ax.loglog(n, self.seconds[op], marker, label=f"{op}: p = {p:.2f}")
            ax.loglog(line, np.exp(a) * line**p, "--", color=dots[0].get_color(), lw=1)
        ax.set_xlabel("tets")
        ax.set_ylabel(f"{'CPU ' if self.clock == 'process' else ''}seconds per call (median)")
        ax.set_title("cost against mesh size, fitted t ~ n^p")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        return ax


def bent_state(X: np.ndarray, length: float = 1.0, height: float = 0.1) -> np.ndarray:
    """Positions (m) of a cantilever bending shape of the beam at ``X``, tip deflection 10 % of
    the length (m), the beam's height (m) along z from 0.

    Euler-Bernoulli kinematics, plane sections normal to the axis: axial strains up to
    about 1.5 %, all det F > 0, the lower half in compression. The state the assembly and
    the explicit step are timed at here and in the benchmark scripts (``scripts/bench_step.py``).
    """
    zc, w_tip = height / 2.0, 0.1 * length
    Xp = X.reshape(-1, 3)
    s = Xp[:, 0] / length
    w = w_tip * s**2 * (3.0 - s) / 2.0
    slope = w_tip * 3.0 * s * (2.0 - s) / (2.0 * length)
    u = np.zeros_like(Xp)
    u[:, 2] = -w
    u[:, 0] = (Xp[:, 2] - zc) * slope
    return X + u.ravel()


def _check_count(value, name: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < low:
        raise InvalidParameter(f"{name} must be an integer >= {low}, got {value!r}.")
    return int(value)


def _operations(model, operations, linear_solver):
    """({operation: callable} on ``model``, the ImplicitEuler or None); each call does the
    whole operation once."""
    x_bent = bent_state(model.X)
    ops = {}
    implicit = None
    if "assembly" in operations:
        ops["assembly"] = lambda: model.linearize(x_bent, project=True)
    if "implicit step" in operations:
        implicit = ImplicitEuler(linear_solver=linear_solver)
        rest = State.rest(model)
        ops["implicit step"] = lambda: implicit.step(model, rest, DT_IMPLICIT)
    if "explicit step" in operations:
        explicit = SymplecticEuler()
        bent = State(x_bent, np.zeros(model.ndofs), 0.0)
        ops["explicit step"] = lambda: explicit.step(model, bent, DT_EXPLICIT)
    return ops, implicit


def _time_interleaved(calls: dict, counts: dict, clock) -> dict:
    """{operation: seconds per call of each sample}, the operations called in turn.

    Each operation is called once untimed first (numba's compile or cache load, the
    sparsity pattern, buffers). Its first timed call decides the batch: a call of 20 ms
    or more is a sample by itself; a faster one is discarded and the samples become
    batches of calls lasting about 20 ms, timed together and divided by their count.
    """
    for fn in calls.values():
        fn()
    batch: dict = dict.fromkeys(calls)
    times: dict = {op: [] for op in calls}
    for r in range(max(counts[op] for op in calls)):
        for op, fn in calls.items():
            if r >= counts[op]:
                continue
            if batch[op] is None:
                t0 = clock()
                fn()
                once = clock() - t0
                if once >= _MIN_SAMPLE:
                    batch[op] = 1
                    times[op].append(once)
                    continue
                batch[op] = int(min(_MAX_BATCH, np.ceil(_MIN_SAMPLE / max(once, 1e-9))))
            t0 = clock()
            for _ in range(batch[op]):
                fn()
            times[op].append((clock() - t0) / batch[op])
    return times


@contextlib.contextmanager
def _blas_threads(n):
    """BLAS and OpenMP pools limited to ``n`` threads (threadpoolctl, if installed) inside."""
    if n is None:
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # the [fast] extra is optional: then the pools stay as they are
        logger.info("threadpoolctl is not installed: BLAS threads not limited")
        yield
        return
    with threadpool_limits(limits=n):
        yield


def measure_scaling(n_tets=FULL_SIZES, operations=OPERATIONS, repeats: int = 5,
                    implicit_repeats: int | None = None, material=None,
                    linear_solver=None, blas_threads: int | None = 1,
                    clock: str = "wall") -> ScalingResult:
    """Time assembly, an implicit and an explicit step on beams of growing size.

    For each size, a 1 x 0.1 x 0.1 m beam of about ``n`` P1 tets (:func:`beam_cells`) of
    ``material`` (density 1000 kg/m^3, held at x = 0, gravity 9.81 m/s^2 along -z) is
    built; each operation is called once untimed (numba's compile or cache load, pattern
    and buffer set-up), then ``repeats`` times, the operations in turn so that a change of
    load on a shared machine falls on all of them alike. An operation faster than 20 ms
    is timed in batches of calls lasting about 20 ms each, a sample being the batch's
    mean. Logs each size at INFO level.

    Parameters
    ----------
    n_tets : sequence of int
        Target tet counts, at least two distinct meshes (default :data:`FULL_SIZES`,
        5k-154k tets, a few minutes on 2 cores; :data:`QUICK_SIZES`, 1k-20k, seconds).
    operations : sequence of str
        A subset of :data:`OPERATIONS`.
    repeats : int
        Timed samples of each operation per size, >= 1 (the medians: >= 5).
    implicit_repeats : int, optional
        Samples of the implicit step, if fewer (it takes seconds at the largest sizes).
    material : Material, optional
        Default ``fe.NeoHookean(E=1e7, nu=0.45)``.
    linear_solver : object, optional
        The implicit step's linear solver. Default ``fe.AMGSolver()`` (AMG-CG with the
        rigid-body modes) at every size, so that the fit measures one regime: the
        integrators' default ``fe.AutoSolver()`` switches from a direct solve to AMG-CG
        at 20k DOFs, and a fit across the switch mixes two power laws. Without pyamg
        (the ``[fast]`` extra), ``fe.DirectSolver()``.
    blas_threads : int or None
        BLAS and OpenMP threads during the timings (threadpoolctl, the ``[fast]`` extra;
        without it, left as they are), default 1: the project's figures are
        single-threaded BLAS, and on a loaded machine extra BLAS threads compete with
        the other processes (a 2-4x slower AMG step seen on 2 cores). None leaves them.
        numba's threads (``NUMBA_NUM_THREADS``) are not changed.
    clock : {"wall", "process"}
        ``"wall"`` (``time.perf_counter``) times what a user waits for. ``"process"``
        (``time.process_time``) counts the CPU time of this process's threads: on a shared
        machine it leaves out the time the scheduler gave to other processes, so the fit
        is steadier there; with one thread (numba's and BLAS's) it equals the wall time
        of an idle machine, with several it is their sum.

    Returns
    -------
    ScalingResult

    Raises
    ------
    InvalidParameter
        Fewer than two distinct meshes, an unknown operation or clock, or a count below 1.

    Examples
    --------
    >>> r = measure_scaling((200, 1600), operations=("explicit step",), repeats=1)
    >>> r.n_tets.tolist(), r.operations
    ([192, 1620], ('explicit step',))
    """
    sizes: list = [n_tets] if isinstance(n_tets, numbers.Integral) else list(n_tets)
    cells = sorted({beam_cells(n) for n in sizes}, key=lambda c: c[0] * c[1] * c[2])
    if len(cells) < 2:
        raise InvalidParameter(f"n_tets must give at least two distinct meshes, got {sizes}.")
    ops = tuple(operations)
    unknown = [op for op in ops if op not in OPERATIONS]
    if unknown or not ops:
        raise InvalidParameter(f"operations must be some of {list(OPERATIONS)}, got {list(ops)}.")
    repeats = _check_count(repeats, "repeats", 1)
    implicit_repeats = repeats if implicit_repeats is None else _check_count(
        implicit_repeats, "implicit_repeats", 1)
    material = NeoHookean(E=1.0e7, nu=0.45) if material is None else material
    if linear_solver is None:
        linear_solver = AMGSolver() if _have_pyamg() else DirectSolver()
    if blas_threads is not None:
        blas_threads = _check_count(blas_threads, "blas_threads", 1)
    if clock not in _CLOCKS:
        raise InvalidParameter(f"clock must be one of {list(_CLOCKS)}, got {clock!r}.")
    timer = _CLOCKS[clock]
    counts = {op: implicit_repeats if op == "implicit step" else repeats for op in ops}

    samples: dict[str, list[np.ndarray]] = {op: [] for op in OPERATIONS if op in ops}
    n_el, n_dofs, newton, linear = [], [], [], []
    with _blas_threads(blas_threads):
        for c in cells:
            model = Model(beam_mesh(1.0, 0.1, 0.1, c), density=1000.0,
                          body=ElasticBody(material, order=1), fixed="left",
                          gravity=(0.0, 0.0, -9.81))
            calls, implicit = _operations(model, ops, linear_solver)
            times = _time_interleaved(calls, counts, timer)
            if implicit is not None:
                newton.append(implicit.last_stats.newton_iterations)
                linear.append(implicit.last_stats.linear_iterations)
            for op, per_size in samples.items():
                per_size.append(np.array(times[op]))
            n_el.append(model.mesh.t.shape[1])
            n_dofs.append(model.ndofs)
            logger.info("scaling: %d tets, %d DOFs: %s", n_el[-1], n_dofs[-1],
                        ", ".join(f"{op} {statistics.median(times[op]) * 1e3:.2f} ms"
                                  for op in times))
    # whether the fused kernels ran: for this material on these spaces, not merely numba's presence
    ran_fused = fused.kernels_for(material, model.space) is not None
    return ScalingResult(np.array(n_el), np.array(n_dofs), tuple(cells), samples, ran_fused,
                         clock, np.array(newton, dtype=int), np.array(linear, dtype=int))
