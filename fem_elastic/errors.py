"""Typed errors raised by fem_elastic.

Every error is a subclass of :class:`FemElasticError`, so a caller can catch
everything the library raises on purpose with one ``except`` clause, and
anything else (a ``TypeError`` from a wrong call, say) still surfaces as a bug.
Messages say what was wrong and what to do about it.
"""

from __future__ import annotations

from os import PathLike
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = [
    "FemElasticError",
    "InvalidMesh",
    "InvalidParameter",
    "UnderConstrained",
    "NotConverged",
    "Diverged",
    "MissingDependency",
    "StepFailed",
    "OutputInUse",
    "WriteFailed",
    "ResourceLimit",
]


class FemElasticError(Exception):
    """Base class of every error fem_elastic raises deliberately."""


class InvalidMesh(FemElasticError, ValueError):
    """The mesh cannot be used: degenerate, inverted, non-tetrahedral or malformed.

    Attributes
    ----------
    elements : numpy.ndarray or None
        Indices of the offending elements (or vertices, see the message), when
        the problem is local to some of them.
    """

    def __init__(self, message: str, elements: ArrayLike | None = None) -> None:
        super().__init__(message)
        self.elements = elements


class InvalidParameter(FemElasticError, ValueError):
    """A physical or numerical parameter is out of its admissible range."""


class MissingDependency(FemElasticError, ModuleNotFoundError):
    """An optional package a feature needs is not installed; the message says what to install.

    It is a :class:`ModuleNotFoundError` (so ``except ImportError`` catches it)
    and a :class:`FemElasticError` (so the command line reports it without a
    traceback). Raised by rendering (pyvista, imageio) and by
    ``fe.material_from_energy`` (sympy).
    """


class UnderConstrained(InvalidParameter):
    """A static problem leaves rigid-body motion free, so it has no unique solution."""


class NotConverged(FemElasticError, RuntimeError):
    """An iterative solver stopped before meeting its tolerance.

    Attributes
    ----------
    result : object
        The solver's result object at the point it gave up (last iterate,
        residual history), so nothing computed is lost.
    """

    def __init__(self, message: str, result: Any = None) -> None:
        super().__init__(message)
        self.result = result


class Diverged(FemElasticError, RuntimeError):
    """A simulation blew up.

    Attributes
    ----------
    step : int
        Index of the step that failed.
    time : float
        Simulation time (s) at the start of the failed step.
    reason : str
        What was detected (non-finite state, energy growth, ...).
    last_good_state : object
        The last state that passed every check.
    trajectory : object
        What ``simulate`` recorded up to the last good state (None when the
        error comes from a single ``step`` call).
    """

    def __init__(self, message: str, step: int | None = None, time: float | None = None,
                 reason: str | None = None, last_good_state: Any = None,
                 trajectory: Any = None) -> None:
        super().__init__(message)
        self.step = step
        self.time = time
        self.reason = reason
        self.last_good_state = last_good_state
        self.trajectory = trajectory


class StepFailed(Diverged):
    """A step of a simulation raised an error: the run ends as honestly as a divergence.

    Whatever goes wrong inside a step (a user motion that raises, a linear
    solver that gives up, a contact routine's error, a ``numpy.linalg.LinAlgError``)
    ends :func:`fe.simulate` with this error instead: like :class:`Diverged`
    (of which it is a subclass, so ``except fe.Diverged`` catches it too) it
    carries the step, the time, the reason, the last good state and the frames
    recorded so far; the original exception is its ``__cause__`` (and
    ``original``).

    Attributes
    ----------
    original : BaseException
        The exception the step raised.
    """

    def __init__(self, message: str, step: int | None = None, time: float | None = None,
                 reason: str | None = None, last_good_state: Any = None,
                 trajectory: Any = None, original: BaseException | None = None) -> None:
        super().__init__(message, step=step, time=time, reason=reason,
                         last_good_state=last_good_state, trajectory=trajectory)
        self.original = original


class OutputInUse(InvalidParameter):
    """Another process writes into the output directory (it holds the directory's lock).

    Attributes
    ----------
    pid : int or None
        The process id of the holder, as it wrote it in the lock file.
    """

    def __init__(self, message: str, pid: int | None = None) -> None:
        super().__init__(message)
        self.pid = pid


class WriteFailed(FemElasticError, OSError):
    """An output file could not be written whole (a full disk, a file size limit, a closed pipe).

    Nothing truncated is left under the final name: the file is written to a
    temporary name and renamed only once it is whole. An :class:`OSError`
    too, so ``except OSError`` still catches it.

    Attributes
    ----------
    path : str
        The file that was being written.
    """

    def __init__(self, message: str, path: str | PathLike[str] | None = None) -> None:
        FemElasticError.__init__(self, message)
        self.path = None if path is None else str(path)
        self.filename = self.path

    def __str__(self) -> str:
        return self.args[0] if self.args else ""


class ResourceLimit(InvalidParameter):
    """A model (or its output) would need more memory or disk than the machine has free.

    Raised before the work starts, with the estimate and what is free.

    Attributes
    ----------
    needed, available : float
        The estimate and what is free (bytes).
    """

    def __init__(self, message: str, needed: float | None = None,
                 available: float | None = None) -> None:
        super().__init__(message)
        self.needed = needed
        self.available = available
