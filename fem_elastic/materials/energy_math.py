"""``fe.math``: the functions an energy for :func:`fe.material_from_energy` is written with.

:func:`~fem_elastic.materials.from_energy.material_from_energy` calls the
user's ``psi`` once, on sympy symbols, to derive its first and second
derivatives; ``math.log`` cannot take a symbol and ``numpy.log`` makes an
object array of it. The functions here take either: on a sympy expression
they return the sympy function of it (which sympy differentiates and
:mod:`.codegen` turns into numpy), on numbers and numpy arrays they are
numpy's own, so the same ``psi`` can also be evaluated on plain numbers::

    >>> import fem_elastic as fe
    >>> psi = lambda I1, I2, J, mu, lam: mu/2*(I1 - 3) - mu*fe.math.log(J) + lam/2*fe.math.log(J)**2
    >>> float(psi(3.0, 3.0, 1.0, mu=1e6, lam=2e6))              # numbers: numpy
    0.0

Elementwise: :func:`log`, :func:`log1p`, :func:`exp`, :func:`expm1`,
:func:`sqrt`, :func:`sin`, :func:`cos`, :func:`tan`, :func:`sinh`,
:func:`cosh`, :func:`tanh`, :func:`atan`; ``**`` for powers (``J**(-2/3)``).
Of a 3x3 matrix (the ``F`` of an energy written in F, a sympy Matrix, or a
numpy array of shape ``(3, 3, ...)``): :func:`det`, :func:`trace`,
:func:`transpose`; ``F.T @ F`` works on the sympy Matrix as written.

Why the module is called ``energy_math`` and reached as ``fe.math``: a file
named ``math.py`` in a package does not shadow the standard library for
absolute imports, but it does as soon as its folder is the first entry of
``sys.path`` (a file of that folder run as a script, some IDE runners), and
it would make ``import math`` in the package's own modules (``base.py`` uses
the standard library's) read as if it meant this one. The public name is the
attribute ``fe.math`` only; it is left out of ``fe.__all__`` so that
``from fem_elastic import *`` never rebinds a user's ``math``.

sympy is not imported here (it is an optional dependency, imported by
:func:`fe.material_from_energy`): an argument is symbolic only if sympy is
already loaded and the argument is one of its objects.
"""

from __future__ import annotations

import sys

import numpy as np

from .base import _det

__all__ = [
    "log", "log1p", "exp", "expm1", "sqrt", "sin", "cos", "tan", "sinh", "cosh", "tanh", "atan",
    "det", "trace", "transpose", "is_symbolic",
]


def is_symbolic(x) -> bool:
    """Whether ``x`` is a sympy object (an expression, a symbol, a matrix).

    Examples
    --------
    >>> is_symbolic(1.0)
    False
    """
    sympy = sys.modules.get("sympy")
    return sympy is not None and isinstance(x, (sympy.Basic, sympy.MatrixBase))


def _elementwise(name: str, numpy_function, sympy_name: str, doc: str):
    def function(x):
        if is_symbolic(x):
            return _sympy_function(sympy_name)(x)
        return numpy_function(x)

    function.__name__ = function.__qualname__ = name
    function.__doc__ = doc
    return function


def _sympy_function(name: str):
    sympy = sys.modules["sympy"]
    if name in ("log1p", "expm1"):  # sympy's codegen functions: differentiable, printed as numpy's
        from sympy.codegen import cfunctions

        return getattr(cfunctions, name)
    return getattr(sympy, name)


log = _elementwise("log", np.log, "log", """Natural logarithm: ``numpy.log`` or ``sympy.log``.

The energy is ``+inf`` where an argument of ``log`` is ``<= 0`` (e.g. ``log(J)`` of
an inverted element): :func:`fe.material_from_energy` makes it the energy's domain.

Examples
--------
>>> float(log(1.0))
0.0
""")
log1p = _elementwise("log1p", np.log1p, "log1p", """``log(1 + x)``, accurate for small x: ``numpy.log1p``.

Examples
--------
>>> float(log1p(0.0))
0.0
""")
exp = _elementwise("exp", np.exp, "exp", """Exponential: ``numpy.exp`` or ``sympy.exp``.

Examples
--------
>>> float(exp(0.0))
1.0
""")
expm1 = _elementwise("expm1", np.expm1, "expm1", """``exp(x) - 1``, accurate for small x: ``numpy.expm1``.

Examples
--------
>>> float(expm1(0.0))
0.0
""")
sqrt = _elementwise("sqrt", np.sqrt, "sqrt", """Square root: ``numpy.sqrt`` or ``sympy.sqrt``.

Its argument must be ``>= 0`` (the energy is ``+inf`` elsewhere).

Examples
--------
>>> float(sqrt(4.0))
2.0
""")
sin = _elementwise("sin", np.sin, "sin", """Sine (radians).

Examples
--------
>>> float(sin(0.0))
0.0
""")
cos = _elementwise("cos", np.cos, "cos", """Cosine (radians).

Examples
--------
>>> float(cos(0.0))
1.0
""")
tan = _elementwise("tan", np.tan, "tan", """Tangent (radians).

Examples
--------
>>> float(tan(0.0))
0.0
""")
sinh = _elementwise("sinh", np.sinh, "sinh", """Hyperbolic sine.

Examples
--------
>>> float(sinh(0.0))
0.0
""")
cosh = _elementwise("cosh", np.cosh, "cosh", """Hyperbolic cosine.

Examples
--------
>>> float(cosh(0.0))
1.0
""")
tanh = _elementwise("tanh", np.tanh, "tanh", """Hyperbolic tangent.

Examples
--------
>>> float(tanh(0.0))
0.0
""")
atan = _elementwise("atan", np.arctan, "atan", """Inverse tangent (radians): numpy.arctan or sympy.atan.

Examples
--------
>>> float(atan(0.0))
0.0
""")


def det(A):
    """Determinant of a 3x3 matrix, by the rule of Sarrus.

    Parameters
    ----------
    A : sympy.Matrix (3, 3) or numpy.ndarray, shape (3, 3, ...)
        A matrix, or a batch in scikit-fem's layout (tensor indices first).

    Returns
    -------
    sympy expression or numpy.ndarray of shape ``A.shape[2:]``

    Examples
    --------
    >>> import numpy as np
    >>> float(det(np.diag([1.0, 2.0, 3.0])))
    6.0
    """
    return _det(A)  # the materials' own expansion: indexing alone, so it takes a sympy Matrix too


def trace(A):
    """Trace of a 3x3 matrix (sympy Matrix, or numpy ``(3, 3, ...)``).

    Examples
    --------
    >>> import numpy as np
    >>> float(trace(np.eye(3)))
    3.0
    """
    return A[0, 0] + A[1, 1] + A[2, 2]


def transpose(A):
    """Transpose of a 3x3 matrix: ``A.T`` of a sympy Matrix, axes 0 and 1 swapped of numpy ``(3, 3, ...)``.

    Examples
    --------
    >>> import numpy as np
    >>> transpose(np.arange(9.0).reshape(3, 3))[0, 1]
    np.float64(3.0)
    """
    if is_symbolic(A):
        return A.T
    return np.swapaxes(np.asarray(A), 0, 1)
