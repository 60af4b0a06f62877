"""Every public callable of ``fe.__all__`` is fully annotated (issue 20, item 7).

Walked: each function of ``fe.__all__`` (the lazily imported ``fe.render_runs`` and
``fe.render_frame`` too), and each class by its ``__init__`` and its public methods,
class and static methods and property getters. Only code of the package is checked:
an ``__init__`` inherited from Python itself (an error's ``Exception.__init__``, a
warning's) has no source of ours to annotate. "Fully" means every parameter
but ``self``/``cls``, ``*args`` and ``**kwargs`` included, and the return.

mypy (``.venv/bin/python -m mypy fem_elastic``, the last step of ``.ci/run``) checks
that the annotations are right; this test checks that they are there: mypy's default
settings skip the bodies of unannotated functions and say nothing about them.
"""

from __future__ import annotations

import inspect

import fem_elastic as fe


def _missing(function) -> list[str]:
    """The parameters (and ``"return"``) of ``function`` without an annotation."""
    signature = inspect.signature(function)
    params = list(signature.parameters.values())
    if params and params[0].name in ("self", "cls"):
        params = params[1:]
    missing = [p.name for p in params if p.annotation is inspect.Parameter.empty]
    if signature.return_annotation is inspect.Signature.empty:
        missing.append("return")
    return missing


def _ours(function) -> bool:
    return (getattr(function, "__module__", None) or "").startswith("fem_elastic")


def _callables(name: str, obj) -> list[tuple[str, object]]:
    """``(qualified name, function)`` of what a user calls on a public name."""
    if not inspect.isclass(obj):
        return [(name, obj)] if callable(obj) else []
    found = []
    for attr in sorted(dir(obj)):
        if attr.startswith("_") and attr != "__init__":
            continue
        raw = inspect.getattr_static(obj, attr)
        if isinstance(raw, property):
            function = raw.fget
        elif isinstance(raw, (staticmethod, classmethod)):
            function = raw.__func__
        elif inspect.isfunction(raw):
            function = raw
        else:  # data, nested classes, builtin slot wrappers (object.__init__, Exception.__init__)
            continue
        if function is not None and _ours(function):
            found.append((f"{name}.{attr}", function))
    return found


def _unannotated(names) -> dict[str, list[str]]:
    bad = {}
    for name in names:
        obj = getattr(fe, name)  # lazy names are imported here
        if inspect.ismodule(obj):  # fe.study, fe.render: modules, not callables
            continue
        for qualname, function in _callables(name, obj):
            missing = _missing(function)
            if missing:
                bad[qualname] = missing
    return bad


def test_every_public_callable_is_fully_annotated():
    bad = _unannotated(fe.__all__)
    assert not bad, "unannotated parameters (or return) of public callables:\n" + "\n".join(
        f"  {qualname}: {', '.join(missing)}" for qualname, missing in sorted(bad.items()))


def test_the_walk_reaches_methods_lazy_names_and_init():
    walked = {q for name in fe.__all__ if not inspect.ismodule(getattr(fe, name))
              for q, _ in _callables(name, getattr(fe, name))}
    # the main result classes' methods, the integrators' step, the lazily imported renderers
    for qualname in ("Trajectory.plot", "Trajectory.save", "StaticResult.reaction_force",
                     "StaticResult.to_pyvista", "Model.__init__", "Model.linearize", "State.rest",
                     "ImplicitEuler.step", "SymplecticEuler.step", "XPBD.step", "simulate",
                     "render_runs", "render_frame", "Ground.signed_distance"):
        assert qualname in walked, qualname
    # an error's __init__ inherited from Exception is Python's, not ours
    assert "InvalidParameter.__init__" not in walked
    assert "Diverged.__init__" in walked  # its own, annotated


def test_the_check_names_what_is_missing(monkeypatch):
    """A planted unannotated function and method are reported, parameter by parameter."""

    def bare(a, b: int, *args, **kwargs):
        return a

    class Planted:
        def __init__(self, x: float) -> None:
            self.x = x

        def method(self, y) -> float:
            return y

        @property
        def value(self):
            return self.x

    for f in (bare, Planted.__init__, Planted.method, Planted.value.fget):
        f.__module__ = "fem_elastic.planted"
    monkeypatch.setattr(fe, "bare", bare, raising=False)
    monkeypatch.setattr(fe, "Planted", Planted, raising=False)
    assert _unannotated(["bare", "Planted"]) == {
        "bare": ["a", "args", "kwargs", "return"],
        "Planted.method": ["y"],
        "Planted.value": ["return"],
    }
