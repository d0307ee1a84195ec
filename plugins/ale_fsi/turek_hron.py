"""The Turek-Hron FSI benchmark (Turek & Hron 2006) in fbia units, for verification.

The benchmark is stated in m, kg, s; fbia works in mm, g, s.  Lengths are scaled by 1000,
densities keep their water-like values in g/mm^3 (1000 kg/m^3 = 1e-3 g/mm^3), the dynamic
viscosity mu = rho nu = 1 kg/(m s) becomes 1 g/(mm s), stresses stay in Pa, 2-D forces come out
in g/s^2 (= 1e-3 N/m) and the 2-D inflow rate is U_bar H = 0.2 m/s x 0.41 m = 82 000 mm^2/s.

>>> from fbia.plugins.ale_fsi import turek_hron
>>> path = turek_hron.write_benchmark_mesh("th.msh", mesh_size=25.0)        # doctest: +SKIP
>>> model = turek_hron.model("FSI1", path)                                   # doctest: +SKIP
>>> turek_hron.quantities(model, "FSI1")                                     # doctest: +SKIP
{'ux_A': 2.27e-05, 'uy_A': 0.00082, 'drag': 14.29, 'lift': 0.76, ...}

The mesh is generated with netgen/OCC and written as gmsh 2.2 with named regions and
boundaries; the model then reads it through the user-mesh path (``mesh_file``), exactly as a
user's mesh would be read.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...core.errors import ConfigError

#: Geometry in mm (Turek & Hron 2006, Fig. 1, scaled from m).
CHANNEL = (2500.0, 410.0)
CENTRE = (200.0, 200.0)
RADIUS = 50.0
BAR_END_X = 600.0
BAR_Y = (190.0, 210.0)
POINT_A = (600.0, 200.0)

#: Physical data of the cases in mm, g, s (from turek_hron_2006.json, converted).
CASES: dict[str, dict[str, Any]] = {
    "CSM1": {"E": 1.4e6, "nu": 0.4, "rho_s": 1e-3, "gravity": (0.0, -2000.0), "rate": 0.0},
    "CFD1": {"E": 1e15, "nu": 0.0, "rho_s": 1e-3, "gravity": (0.0, 0.0), "rate": 82000.0},
    "FSI1": {"E": 1.4e6, "nu": 0.4, "rho_s": 1e-3, "gravity": (0.0, 0.0), "rate": 82000.0},
}


def write_benchmark_mesh(
    path: str | Path,
    mesh_size: float = 25.0,
    bar_mesh_size: float | None = None,
    cylinder_mesh_size: float | None = None,
) -> Path:
    """Mesh the Turek-Hron geometry (mm) with netgen/OCC and write it as named gmsh 2.2.

    Parameters
    ----------
    path
        Output file (``.msh``).
    mesh_size
        Maximum element size in the channel (mm).
    bar_mesh_size
        Element size on and in the elastic bar (mm); default ``mesh_size / 4``.
    cylinder_mesh_size
        Element size on the cylinder (mm); default ``mesh_size / 3``.
    """
    import ngsolve
    from netgen.occ import Circle, Glue, OCCGeometry, Rectangle, X, Y

    from ..fem.flow_cell import check_mesh, write_mesh

    h_bar = bar_mesh_size if bar_mesh_size is not None else mesh_size / 4.0
    h_cyl = cylinder_mesh_size if cylinder_mesh_size is not None else mesh_size / 3.0
    if min(mesh_size, h_bar, h_cyl) <= 0:
        raise ConfigError("mesh sizes must be positive", "turek_hron mesh")
    length, height = CHANNEL
    channel = Rectangle(length, height).Face()
    channel.edges.Min(X).name = "inflow"
    channel.edges.Max(X).name = "outflow"
    channel.edges.Min(Y).name = "walls"
    channel.edges.Max(Y).name = "walls"
    cylinder = Circle(CENTRE, RADIUS).Face()
    cylinder.edges.name = "obstacle"
    for e in cylinder.edges:
        e.maxh = h_cyl
    x0 = CENTRE[0]
    bar = Rectangle(BAR_END_X - x0, BAR_Y[1] - BAR_Y[0]).Face().Move((x0, BAR_Y[0], 0.0))
    bar = bar - cylinder
    bar.edges.name = "interface"
    bar.edges.Max(X).name = "interface"
    bar.faces.name = "solid"
    bar.faces.maxh = h_bar
    for e in bar.edges:
        e.maxh = h_bar
    # the bar's left end, shared with the cylinder, is clamped; OCC may split that arc at the
    # circle's seam (angle 0), so name every edge left of the cylinder's rim
    for e in bar.edges:
        if e.center.x < CENTRE[0] + RADIUS + 1.0:
            e.name = "solid_fixed"
    fluid = channel - cylinder - bar
    fluid.faces.name = "fluid"
    shape = Glue([fluid, bar])
    ngmesh = OCCGeometry(shape, dim=2).GenerateMesh(maxh=mesh_size)
    mesh = ngsolve.Mesh(ngmesh)
    check_mesh(mesh, "turek_hron mesh")
    return write_mesh(mesh, path)


def model(case: str, mesh_file: str | Path, **options: Any) -> Any:
    """An :class:`AleFsiForwardModel` set up for a Turek-Hron case on ``mesh_file``."""
    from .model import AleFsiForwardModel

    if case not in CASES:
        raise ConfigError(f"unknown case {case!r}; valid: {', '.join(CASES)}", "turek_hron")
    c = CASES[case]
    opts: dict[str, Any] = {
        "mesh_file": Path(mesh_file),
        "material": "svk",
        "E": c["E"],
        "nu": c["nu"],
        "inflow_rate": c["rate"],
        "fluid_density": 1e-3,
        "fluid_viscosity": 1.0,
        "solid_density": c["rho_s"],
        "gravity": c["gravity"],
        "outflow": "do_nothing",
        "probes": [POINT_A],
        "warm_start": False,
    }
    opts.update(options)
    return AleFsiForwardModel(**opts)


def quantities(model: Any, case: str, workdir: str | Path = ".") -> dict[str, float]:
    """Solve ``case`` and return the benchmark quantities in SI units (m, N/m).

    ``ux_A``, ``uy_A``: displacement of the bar tip A; ``drag``, ``lift``: force of the fluid
    on cylinder and bar; plus ``ndof``, ``newton_iterations`` and ``wall_time``.
    """
    c = CASES[case]
    coord = {"inflow_rate": c["rate"]}
    sol = model.solve({"E": c["E"], "nu": c["nu"]}, [coord], Path(workdir))
    d = sol.diagnostics
    ux, uy = d["probe_displacements"][0][0]
    fx, fy = d["fluid_force"][0]
    return {
        "ux_A": ux * 1e-3,
        "uy_A": uy * 1e-3,
        "drag": fx * 1e-3,
        "lift": fy * 1e-3,
        "ndof": d["ndof"],
        "newton_iterations": d["newton_iterations"],
        "wall_time": d["wall_time"],
    }
