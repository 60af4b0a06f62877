"""Symbolic derivatives of an energy and their numpy code: the engine of ``fe.material_from_energy``.

:func:`derive` calls the user's ``psi`` once on sympy symbols (``F`` a 3x3
Matrix of symbols, or the invariants ``I1, I2, J``, and one symbol per
parameter), differentiates the expression it returns once and twice, and
:func:`compile_functions` prints each set of expressions as one straight-line
numpy function: common subexpressions eliminated (``sympy.cse``), integer
powers written as products (``x*x``, ``1.0/x``), every operation on whole
``(N,)`` slabs of the batch. The function is built from that source with
``exec`` once per energy (and cached with it): evaluating it costs what a
hand-written numpy material costs, with no Python work per point.

Why sympy and not an automatic-differentiation library: the derivatives are
needed pointwise at millions of quadrature points, for energies of at most
nine variables. Forward-mode AD over numpy arrays would carry every
intermediate with its 9 first and 45 second derivatives (55 arrays for each
operation of psi), and reverse mode or JAX would bring a compiler and a
heavy dependency for what is, once derived, a few dozen multiplications. A
symbolic derivative is exact, is derived once (~0.1-1 s) and then costs
nothing per call, and its common subexpressions are shared the way a
hand-written material shares ``F^-T`` or ``ln J``; sympy is pure Python
(the optional ``energy`` extra), imported only here, on first use.

The domain of the energy is read off the expression too: every argument of
``log`` must be ``> 0`` (of ``log1p`` ``> -1``), every base of a fractional
power ``>= 0`` (``> 0`` for a negative exponent). Each generated function
returns, besides its outputs, the mask of the points inside that domain
(``None`` when the energy has no such restriction), so that ``psi`` is
``+inf`` and ``P``, ``C`` are NaN outside, as for the hand-written
:class:`~fem_elastic.materials.NeoHookean` at ``J <= 0``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InvalidParameter, MissingDependency

__all__ = ["require_sympy", "Derivation", "derive", "compile_functions", "F_NAMES", "INVARIANTS",
           "PAIRS9"]

_INSTALL = 'pip install "fem_elastic[energy]"'

#: Names of the sympy symbols of F's entries, row-major: ``F[i, j]`` is ``F{i}{j}``.
F_NAMES = [f"F{i}{j}" for i in range(3) for j in range(3)]
#: The invariants of an energy written in invariants, in this order.
INVARIANTS = ("I1", "I2", "J")
#: The 45 index pairs ``(a, b)``, ``a <= b``, of the symmetric 9x9 tangent (a = 3 i + j).
PAIRS9 = [(a, b) for a in range(9) for b in range(a, 9)]


def require_sympy():
    """The sympy module, or :class:`MissingDependency` naming the extra to install.

    Examples
    --------
    >>> require_sympy().__name__
    'sympy'
    """
    try:
        import sympy
    except ModuleNotFoundError as err:
        raise MissingDependency(
            f"fe.material_from_energy derives the energy's derivatives with sympy, which is not "
            f"installed ({err}). Install it with: {_INSTALL} (or pip install sympy).",
            name="sympy",
        ) from err
    return sympy


@dataclass(frozen=True)
class Derivation:
    """An energy traced on symbols, and its derivatives.

    Attributes
    ----------
    form : str
        ``"F"`` or ``"invariants"``.
    variables : list of sympy.Symbol
        The 9 entries of F (row-major), or ``I1, I2, J``.
    params : list of sympy.Symbol
        One per parameter, named as the parameter.
    psi : sympy.Expr
        The energy.
    gradient : list of sympy.Expr
        ``dpsi / d variable`` for each variable.
    hessian : dict
        ``(a, b) -> d2psi / dv_a dv_b`` for ``a <= b``.
    domain : list of (sympy.Expr, str)
        ``(argument, condition)``: ``"> 0"``, ``">= 0"`` or ``"> -1"``, each of
        which must hold for the energy to be defined.
    """

    form: str
    variables: list
    params: list
    psi: object
    gradient: list
    hessian: dict
    domain: list


def _np_help() -> str:
    return (
        "write psi with fe.math (fe.math.log, fe.math.exp, fe.math.sqrt, ...; fe.math.det and "
        "fe.math.trace of F) and the operators + - * / **, not math.* or numpy.* functions"
    )


def derive(psi, form: str, param_names: list[str], describe: str):
    """Call ``psi`` on symbols and differentiate what it returns.

    Parameters
    ----------
    psi : callable
        ``psi(F, *params)`` or ``psi(I1, I2, J, *params)``.
    form : str
        ``"F"`` or ``"invariants"``.
    param_names : list of str
        The parameters' names, in ``psi``'s order.
    describe : str
        ``psi`` in words, for messages.

    Returns
    -------
    Derivation

    Raises
    ------
    MissingDependency
        sympy is not installed.
    InvalidParameter
        ``psi`` cannot be evaluated on symbols, or does not return one scalar.

    Examples
    --------
    >>> d = derive(lambda I1, I2, J, mu: mu / 2 * (I1 - 3), "invariants", ["mu"], "psi")
    >>> d.gradient
    [mu/2, 0, 0]
    """
    sympy = require_sympy()
    if form == "F":
        variables = [sympy.Symbol(n, real=True) for n in F_NAMES]
        args = [sympy.Matrix(3, 3, variables)]
    else:
        variables = [sympy.Symbol(n, real=True) for n in INVARIANTS]
        args = list(variables)
    params = [sympy.Symbol(n, real=True) for n in param_names]
    try:
        value = psi(*args, *params)
    except Exception as err:  # anything: the message names the fix, the original is the cause
        raise InvalidParameter(
            f"{describe} could not be evaluated on symbols to derive its derivatives "
            f"({type(err).__name__}: {err}): {_np_help()}."
        ) from err
    expr = _scalar(sympy, value, describe)
    allowed = set(variables) | set(params)
    extra = expr.free_symbols - allowed
    if extra:
        raise InvalidParameter(
            f"{describe} returned an expression in {sorted(map(str, extra))}, which are neither its "
            f"variables nor its parameters: give every constant as a number or a parameter."
        )
    if expr.has(sympy.I) or expr.has(sympy.zoo) or expr.has(sympy.nan):
        raise InvalidParameter(
            f"{describe} returned {expr}, which is complex or undefined: an energy is a real "
            "number (J/m^3)."
        )
    gradient = [sympy.diff(expr, v) for v in variables]
    hessian = {}
    for a, b in itertools.combinations_with_replacement(range(len(variables)), 2):
        hessian[(a, b)] = sympy.diff(gradient[a], variables[b]) if gradient[a] != 0 else sympy.S.Zero
    # conditions on the parameters alone hold or fail everywhere: the check at rest sees them
    domain = [(arg, c) for arg, c in _domain(sympy, expr) if arg.free_symbols & set(variables)]
    return Derivation(form, variables, params, expr, gradient, hessian, domain)


def _scalar(sympy, value, describe: str):
    """``value`` as one real sympy expression, or InvalidParameter saying what it was."""
    if isinstance(value, (sympy.MatrixBase, np.ndarray, list, tuple, dict, set)):
        shape = getattr(value, "shape", None) or (len(value),)
        raise InvalidParameter(
            f"{describe} must return one scalar energy density (J/m^3), got a "
            f"{type(value).__name__} of shape {tuple(shape)}: sum its terms into one number "
            "(e.g. fe.math.trace(F.T @ F), not F.T @ F)."
        )
    if isinstance(value, bool) or value is None:
        raise InvalidParameter(
            f"{describe} must return one scalar energy density (J/m^3), got {value!r}: "
            "did it forget a return?"
        )
    try:
        expr = sympy.sympify(value, strict=True)
    except (sympy.SympifyError, TypeError) as err:
        raise InvalidParameter(
            f"{describe} must return one scalar energy density (J/m^3), got {value!r} of type "
            f"{type(value).__name__}: {_np_help()}."
        ) from err
    if not isinstance(expr, sympy.Expr) or isinstance(expr, sympy.logic.boolalg.Boolean):
        raise InvalidParameter(
            f"{describe} must return one scalar energy density (J/m^3), got {expr!r} "
            f"({type(expr).__name__})."
        )
    return expr


def _domain(sympy, expr) -> list:
    """The conditions under which ``expr`` is real and finite: ``[(argument, condition), ...]``."""
    from sympy.codegen.cfunctions import log1p

    conditions = []
    for node in sympy.preorder_traversal(expr):
        if isinstance(node, sympy.log):
            conditions.append((node.args[0], "> 0"))
        elif isinstance(node, log1p):
            conditions.append((node.args[0], "> -1"))
        elif isinstance(node, sympy.Pow):
            base, e = node.args
            if base.is_number:
                continue
            if e.is_Integer:
                continue  # defined everywhere (a negative one: +-inf at 0, left to the arithmetic)
            conditions.append((base, "> 0" if (e.is_negative or not e.is_number) else ">= 0"))
    unique = []
    for c in conditions:
        if c not in unique:
            unique.append(c)
    return unique


# -- code generation ---------------------------------------------------------------------------
def _printer(sympy):
    from sympy.printing.numpy import NumPyPrinter

    class Printer(NumPyPrinter):
        """numpy code with integer powers as products: ``x**2`` as ``x*x``, ``x**-1`` as ``1.0/x``."""

        def _print_Pow(self, expr, rational=False):
            base, e = expr.args
            if e.is_Integer and 1 <= abs(int(e)) <= 4:
                b = self.parenthesize(base, sympy.printing.precedence.PRECEDENCE["Mul"] + 1)
                if abs(int(e)) == 1:
                    return b if e > 0 else f"(1.0/{b})"
                product = "*".join([b] * abs(int(e)))  # parenthesized: it may be a denominator
                return f"({product})" if e > 0 else f"(1.0/({product}))"
            return super()._print_Pow(expr, rational=rational)

        def _print_Float(self, expr):
            return repr(float(expr))  # every digit of the double (sympy prints 15)

    return Printer({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})


def compile_functions(sympy, name: str, header: list[str], inputs: list[tuple], params: list,
                      outputs: list[tuple], domain: list) -> object:
    """One numpy function computing ``outputs`` (and the domain mask) from ``inputs``.

    Parameters
    ----------
    sympy : module
    name : str
        The function's name (in tracebacks).
    header : list of str
        The function's arguments before the parameters (``["F", "out"]``).
    inputs : list of (sympy.Symbol, str)
        Each symbol the expressions use and the source that reads it
        (``(F00, "F[0, 0]")``); unused ones are not read.
    params : list of sympy.Symbol
        Passed as the trailing arguments, in order.
    outputs : list of (str, sympy.Expr)
        ``target`` is a source line's left side, ``"out[0, 0] = "``, or
        ``"return"``: such outputs are gathered into one returned tuple (see below).
    domain : list of (sympy.Expr, str)
        The conditions of :func:`derive`.

    Returns
    -------
    callable
        ``f(*header, *params)``; it assigns the ``out[...]`` targets and
        returns ``(values, ok)``: ``values`` the tuple of the ``"return"``
        outputs (empty if none), ``ok`` the boolean mask of the domain (or
        None when there is no condition).
    """
    printer = _printer(sympy)
    internal = {p: sympy.Symbol(f"_p{k}", real=True) for k, p in enumerate(params)}
    names = {s: sympy.Symbol(f"_v_{src_name(s)}", real=True) for s, _ in inputs}
    rename = {**internal, **names}
    exprs = [sympy.sympify(e).xreplace(rename) for _, e in outputs]
    exprs += [arg.xreplace(rename) for arg, _ in domain]
    replacements, reduced = sympy.cse(exprs, symbols=sympy.numbered_symbols("_t"), order="none")
    used = set()
    for _, e in replacements:
        used |= e.free_symbols
    for e in reduced:
        used |= e.free_symbols
    lines = [f"def {name}({', '.join(header + [str(internal[p]) for p in params])}):"]
    for s, source in inputs:
        if names[s] in used:
            lines.append(f"    {names[s]} = {source}")
    for sub, e in replacements:
        lines.append(f"    {sub} = {printer.doprint(e)}")
    returned = []
    n_out = len(outputs)
    for (target, _), e in zip(outputs, reduced[:n_out]):
        code = printer.doprint(e)
        if target == "return":
            returned.append(code)
        else:
            lines.append(f"    {target}{code}")
    conditions = [f"({printer.doprint(e)} {cond.replace('> -1', '> -1.0')})"
                  for e, (_, cond) in zip(reduced[n_out:], domain)]
    ok = " & ".join(conditions) if conditions else "None"
    lines.append(f"    return ({', '.join(returned)}{',' if returned else ''}), {ok}")
    source = "\n".join(lines) + "\n"
    namespace: dict[str, Any] = {"numpy": np}
    exec(compile(source, f"<fem_elastic energy: {name}>", "exec"), namespace)  # noqa: S102
    function = namespace[name]
    function.source = source
    return function


def src_name(symbol) -> str:
    """A symbol's name as a piece of a Python identifier."""
    return "".join(c if c.isalnum() else "_" for c in str(symbol))
