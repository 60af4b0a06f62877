"""The small scene the command's safety tests run: a linear beam of a few tets under gravity.

Each test states only what it varies (its name, the integrator, the time table, the mesh),
so what it is about stays readable; the rest is the same clamped beam, rendering nothing.
"""

from __future__ import annotations


def small_scene(name: str, *, integrator: str = "implicit_euler", dt: float = 0.01,
                duration: float = 0.02, cells: tuple[int, int, int] = (2, 1, 1), E: str = "1e5",
                output: str = "", material: str = "linear", integrator_options: str = "") -> str:
    """A scene file's text: a clamped beam (``material``, linear by default) under gravity, ``render = []``.

    ``E`` is Young's modulus as written in the file (a test may edit that text); ``output``
    adds lines to its ``[output]`` table (e.g. ``"checkpoint_every = 2"``),
    ``integrator_options`` to its ``[integrator]`` table, right under ``type``
    (e.g. ``"iterations = 7"``).
    """
    nx, ny, nz = cells
    return f"""\
[scene]
name = "{name}"
[mesh]
kind = "beam"
cells = [{nx}, {ny}, {nz}]
[body]
name = "fem"
material = "{material}"
E = {E}
nu = 0.3
density = 1000.0
[boundary]
fixed = ["left"]
[loads]
gravity = [0.0, 0.0, -9.81]
[integrator]
type = "{integrator}"
""" + (integrator_options + "\n" if integrator_options else "") + f"""\
[time]
dt = {dt!r}
duration = {duration!r}
[output]
render = []
""" + (output + "\n" if output else "")
