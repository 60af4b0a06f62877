"""The module paths of fem_elastic before it was grouped into subpackages, kept as aliases.

Until version 0.2 the modules sat side by side (``fem_elastic.mesh``,
``fem_elastic.simulate``, ...). Each old path still imports, as a module that
forwards every attribute to where the name lives now and warns once with
:class:`DeprecationWarning` naming the new path. ``fem_elastic.<old name>``
as an attribute works the same way. Names in ``fem_elastic.__all__`` never
moved: ``fe.simulate``, ``fe.Model``, ... are unchanged.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

#: old module (under fem_elastic) -> the modules its names live in now, searched in order
MOVED: dict[str, tuple[str, ...]] = {
    "_fused_kernels": ("discretization._fused_kernels",),
    "analytic": ("physics.analytic",),
    "checkpoint": ("dynamics.checkpoint",),
    "cli": ("app.cli",),
    "contact": ("physics.contact", "physics.obstacles"),
    "damping": ("physics.damping",),
    "driven": ("physics.driven",),
    "elastic_body": ("physics.elastic_body",),
    "fields": ("physics.fields",),
    "fused": ("discretization.fused",),
    "integrators": ("dynamics.integrators",),
    "integrators.base": ("dynamics.integrators.base",),
    "integrators.explicit": ("dynamics.integrators.explicit",),
    "integrators.implicit": ("dynamics.integrators.implicit",),
    "integrators.incremental": ("dynamics.integrators.incremental",),
    "integrators.newmark": ("dynamics.integrators.newmark",),
    "io": ("geometry.mesh_io", "app.vtu", "files"),
    "linear_solvers": ("solvers.linear_solvers",),
    "loads": ("physics.loads",),
    "mass": ("discretization.mass",),
    "mesh": ("geometry.mesh",),
    "modal": ("solvers.modal",),
    "model": ("physics.model", "geometry.mesh"),
    "newton": ("solvers.newton",),
    "output": ("app.output",),
    "potential": ("physics.potential",),
    "render": ("app.render", "app.render_scene"),
    "runner": ("app.runner",),
    "scene": ("app.scene",),
    "scene_schema": ("app.scene_schema",),
    "simulate": ("dynamics.simulate", "dynamics.checkpoint"),
    "skfem_forms": ("discretization.skfem_forms",),
    "springs": ("physics.springs",),
    "state": ("dynamics.state",),
    "static": ("solvers.static",),
    "stiffness_warping": ("physics.stiffness_warping",),
    "trajectory": ("dynamics.trajectory",),
}

_PACKAGE = __name__.rsplit(".", 1)[0]


class _MovedModule(types.ModuleType):
    """An old module path: attributes are looked up in the new modules, with one warning."""

    def __init__(self, old: str, new: tuple[str, ...]):
        super().__init__(f"{_PACKAGE}.{old}", f"Moved to {', '.join(_PACKAGE + '.' + n for n in new)}.")
        self._new = tuple(f"{_PACKAGE}.{n}" for n in new)
        self._warned = False

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        for target in self._new:
            module = importlib.import_module(target)
            if hasattr(module, name):
                if not self._warned:
                    self._warned = True
                    public = name in getattr(sys.modules.get(_PACKAGE), "__all__", ())
                    warnings.warn(
                        f"{self.__name__} is deprecated: import {name} from {target}"
                        + (f" (or use fem_elastic.{name})" if public else "")
                        + "; the old path goes in 0.3.",
                        DeprecationWarning, stacklevel=2,
                    )
                return getattr(module, name)
        raise AttributeError(f"module {self.__name__!r} (moved to {', '.join(self._new)}) has no "
                             f"attribute {name!r}")

    def __dir__(self):
        names = set()
        for target in self._new:
            names.update(dir(importlib.import_module(target)))
        return sorted(names)


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds ``fem_elastic.<old module>`` and loads it as a :class:`_MovedModule`."""

    def find_spec(self, fullname, path=None, target=None):
        if not fullname.startswith(_PACKAGE + "."):
            return None
        old = fullname[len(_PACKAGE) + 1:]
        if old not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, self, is_package=old == "integrators")

    def create_module(self, spec):
        return moved_module(spec.name[len(_PACKAGE) + 1:])

    def exec_module(self, module):
        pass


def moved_module(old: str) -> _MovedModule:
    """The alias module of an old path (one per path, registered in ``sys.modules``)."""
    name = f"{_PACKAGE}.{old}"
    module = sys.modules.get(name)
    if not isinstance(module, _MovedModule):
        module = _MovedModule(old, MOVED[old])
        module.__path__ = []  # lets ``fem_elastic.integrators.base`` be found below it
        sys.modules[name] = module
    return module


class _Package(types.ModuleType):
    """The package module, keeping its public names when an old module path of the same name loads.

    Importing a submodule sets it as an attribute of its parent: ``import
    fem_elastic.simulate`` (the old path) would replace the function
    ``fem_elastic.simulate`` by the alias module. An alias never replaces a
    name the package already has.
    """

    def __setattr__(self, name, value):
        # an old module path must not shadow a public name, also one resolved lazily
        # by the package's __getattr__ (``fe.render``, public since issue 20)
        if isinstance(value, _MovedModule) and (name in self.__dict__
                                                or name in self.__dict__.get("__all__", ())):
            return
        super().__setattr__(name, value)


def install() -> None:
    """Put the finder of old module paths on ``sys.meta_path`` (once), and guard the package's names."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
    sys.modules[_PACKAGE].__class__ = _Package
