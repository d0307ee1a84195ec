"""Options of the ``ale_fsi`` forward model, and their mapping onto the solver's settings.

:class:`AleFsiOptions` is the typed contract of the plugin (units in every description);
:func:`solver_settings` is the one place the options become the solver's
:class:`~fbia.plugins.ale_fsi.forms.SolverSettings` (``growth`` inherits both).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from types import MappingProxyType
from typing import Any, Literal

from pydantic import Field, field_validator, model_validator

from ...core.options import PluginOptions, settings_from
from ..fem.outlines import (
    DEFAULT_INTERFACE_MESH_SIZE,
    NAMED_OUTLINES,
    OutlineName,
    outline_mesh_size,
)

Point = tuple[float, float]
Probe = tuple[float, float] | tuple[float, float, float]  # one coordinate per mesh dimension


class AleFsiOptions(PluginOptions):
    """Options of :class:`AleFsiForwardModel` (units in every description)."""

    mode: Literal["quasi_static", "transient"] = Field(
        "quasi_static",
        description="quasi_static: steady FSI with continuation in the inflow rate "
        "(coordinates {'inflow_rate': mm^2/s}); transient: one-step-theta from rest "
        "(coordinates {'time': s}) [-]",
    )
    material: Literal["svk", "neo_hooke"] = Field(
        "svk", description="solid material: Saint Venant-Kirchhoff or neo-Hooke [-]"
    )
    E: float = Field(400.0, gt=0, description="Young's modulus of the biofilm [Pa]")
    nu: float = Field(0.3, gt=-1.0, lt=0.5, description="Poisson's ratio of the biofilm [-]")
    inflow_rate: float = Field(
        100.0, description="volume inflow rate of the parabolic inflow profile [mm^2/s]"
    )
    channel_length: float = Field(2.0, gt=0, description="flow-cell length L [mm]")
    channel_height: float = Field(1.0, gt=0, description="flow-cell height H [mm]")
    geometry: Literal["flow_cell", "dome_3d", "ridge_3d", "colony_3d"] = Field(
        "flow_cell",
        description="flow_cell: the 2-D cell; dome_3d: a 3-D duct with a spherical-cap "
        "biofilm (inflow_rate in mm^3/s; for its displacement to 1 %: order 3, mesh_size "
        "0.2, interface_mesh_size 0.15, curved, threads 2, mesh_motion_layer 0.15, "
        "mesh_motion_order 1 -- see benchmarks/bench_ale_fsi_3d.py); ridge_3d: the 2-D cell "
        "extruded over channel_width between symmetry walls (plane strain); colony_3d: the "
        "dome_3d duct "
        "with the colony of colony_surface [-]",
    )
    channel_width: float = Field(1.0, gt=0, description="3-D duct width / ridge depth W [mm]")
    dome_radius: float = Field(0.4, gt=0, description="base radius of the dome_3d cap [mm]")
    dome_height: float = Field(0.4, gt=0, description="height of the dome_3d cap [mm]")
    dome_centre: float = Field(0.8, gt=0, description="x of the dome_3d centre [mm]")
    colony_surface: Path | None = Field(
        None,
        description="colony_3d: the colony's surface (STL, PLY, OBJ, VTU, ...; closed or its "
        "upper part), model axes: x along the flow, y height above the floor, z across; "
        "a height field y = h(x, z) (fbia.plugins.ale_fsi.colony3d) [path, mm]",
    )
    colony_offset: tuple[float, float, float] = Field(
        (0.0, 0.0, 0.0), description="colony_3d: translation of colony_surface [mm]"
    )
    colony_resolution: float = Field(
        0.02, gt=0, description="colony_3d: grid spacing of the colony's height field [mm]"
    )
    colony_smoothing: float = Field(
        0.02,
        ge=0,
        description="colony_3d: Gaussian smoothing width of the height field (voxel steps "
        "of a segmented surface, spline ringing at a steep foot); 0: none [mm]",
    )
    outline: list[Point] | OutlineName | None = Field(
        None,
        description="biofilm outline from the upstream to the downstream foot, both on "
        "the floor y = 0, or a named one; default 'paper_a_facts', derived from the facts "
        "the thesis publishes about its mound ('fig2_sketch': fbia's earlier one; "
        "fbia.plugins.fem.outlines) [mm]",
    )
    smooth_outline: bool = Field(
        True, description="interpolate the outline by a cubic spline (else polygon) [-]"
    )
    subdomains: list[list[Point]] = Field(
        default_factory=list,
        description="closed polygons cutting the biofilm into regions solid_1..solid_n; "
        "the rest of the biofilm is region n+1 (Paper A Fig. 9) [mm]",
    )
    mesh_file: Path | None = Field(
        None,
        description="user mesh (gmsh .msh or any meshio format; 3-D: tetrahedra, also "
        "netgen .vol) with regions fluid, solid[_k] and boundaries inflow, outflow, walls, "
        "interface, solid_fixed [, obstacle, symmetry]; replaces the builders [path]",
    )
    curved: bool = Field(
        True,
        description="curved element geometry: order 2 along the biofilm outline of the "
        "flow-cell builder, order `order` on the dome_3d's dome (user meshes and ridge_3d "
        "have straight sides) [-]",
    )
    mesh_size: float = Field(0.12, gt=0, description="maximum element size [mm]")
    interface_mesh_size: float | None = Field(
        None,
        gt=0,
        description="element size at the fluid-biofilm interface; default: a named "
        "outline's own (paper_a_facts: 0.057, 67 interface vertices as Paper B's n_in = 66), "
        "else 0.03 [mm]",
    )
    solid_mesh_size: float | None = Field(
        None,
        gt=0,
        description="element size inside the biofilm and on its base, graded from the "
        "interface size; default 2 x interface_mesh_size [mm]",
    )
    fluid_density: float = Field(1e-3, gt=0, description="fluid density [g/mm^3]")
    fluid_viscosity: float = Field(1e-3, gt=0, description="dynamic viscosity [g/(mm s)]")
    solid_density: float = Field(1e-3, gt=0, description="biofilm density [g/mm^3]")
    gravity: tuple[float, float] = Field(
        (0.0, 0.0), description="body force per unit mass on the solid only [mm/s^2]"
    )
    outflow: Literal["horizontal", "do_nothing"] = Field(
        "horizontal",
        description="outflow condition: horizontal flow (v_y = 0, traction-free in x, "
        "Paper A) or do-nothing (traction-free) [-]",
    )
    mesh_motion: Literal["elastic", "harmonic"] = Field(
        "elastic", description="pseudo-solid extension of the displacement into the fluid [-]"
    )
    mesh_motion_layer: float | None = Field(
        None,
        gt=0,
        description="the ALE mesh moves only in the fluid elements with a vertex within "
        "this distance of the interface; beyond, the mesh stays fixed (fewer unknowns, a "
        "sparser Jacobian; the solution changes at the size of the discretisation error). "
        "It must take the interface's displacement: a fold fails the run. Default: the "
        "whole fluid moves [mm]",
    )
    mesh_motion_order: int | None = Field(
        None,
        ge=1,
        description="polynomial order of the ALE mesh displacement inside the fluid: 1 fixes "
        "its edge and face unknowns away from the biofilm at zero, a piecewise-linear mesh "
        "motion (the interface keeps the full order); at order 3 in 3-D about 18 % fewer "
        "unknowns, the solution changes at the size of the discretisation error. Default: "
        "order [-]",
    )
    mesh_stiffening: float = Field(
        1.0, ge=0, description="exponent of the Jacobian-based mesh stiffening [-]"
    )
    order: int = Field(2, ge=2, le=4, description="polynomial order of v and d; p: order-1 [-]")
    newton_tol: float = Field(
        1e-10, gt=0, lt=1e-2, description="tolerance on the scaled Newton update [-]"
    )
    newton_max_iter: int = Field(
        12, ge=1, description="Jacobian assemblies per Newton solve (chord steps extra) [-]"
    )
    min_det_f: float = Field(
        0.01, ge=0, description="smallest admissible det F of the ALE map and solid [-]"
    )
    min_element_quality: float = Field(
        0.02, ge=0, lt=1, description="smallest admissible deformed fluid element quality [-]"
    )
    warm_start: bool = Field(
        True,
        description="start from the converged states of earlier runs of this model object "
        "(same mesh): the nearest one, moved to first order by its tangents or, without "
        "them, along the affine interpolant of the nearest states at the same inflow [-]",
    )
    probes: list[Probe] = Field(
        default_factory=list,
        description="reference points (x, y) in 2-D, (x, y, z) in 3-D, whose displacement "
        "is reported in the diagnostics ('probe_displacements', one list per coordinate) [mm]",
    )
    write_vtu: bool = Field(
        False, description="write a VTU file per coordinate into the run's workdir [-]"
    )
    time_step: float = Field(0.25, gt=0, description="transient time step [s]")
    theta: float = Field(1.0, ge=0.5, le=1.0, description="one-step-theta parameter [-]")
    ramp_time: float = Field(10.0, ge=0, description="duration of the inflow ramp [s]")
    ramp_steps: int = Field(1, ge=1, description="cosine stairs of the inflow ramp [-]")
    threads: int = Field(1, ge=1, description="NGSolve task-manager threads [-]")
    linear_solver: Literal["direct", "block_gmres"] = Field(
        "direct", description="Newton systems: Pardiso, or GMRes with block preconditioner [-]"
    )
    native_code: bool = Field(
        True,
        description="compile the weak forms' integrands to machine code (NGSolve's "
        "realcompile; needs a C++ compiler, else the interpreted code, a warning and a note "
        "in the run's diagnostics): the 2-D cell's runs about 1.8x faster, a 3-D Jacobian "
        "at order 3 about 1.4x; the same problem as false (the interpreted code), the bits "
        "of a result not; the first use of a setting compiles for 4-6 s per integrand, "
        "later processes take it from the cache in $FBIA_CACHE_DIR or ~/.cache/fbia in "
        "about 0.2 s (fbia.plugins.fem.native) [-]",
    )

    @property
    def interface_size(self) -> float:
        """The interface element size in use (mm): ``interface_mesh_size``, else the
        outline's own in the 2-D flow cell and ridge (named outlines), else 0.03."""
        if self.interface_mesh_size is not None:
            return self.interface_mesh_size
        if self.mesh_file is None and self.geometry in ("flow_cell", "ridge_3d"):
            return outline_mesh_size(self.outline)
        return DEFAULT_INTERFACE_MESH_SIZE

    @field_validator("outline", mode="before")
    @classmethod
    def _outline_name(cls, v: Any) -> Any:
        if isinstance(v, str) and v not in NAMED_OUTLINES:
            raise ValueError(
                f"unknown outline {v!r}; named outlines: {', '.join(sorted(NAMED_OUTLINES))} "
                "(or give the points)"
            )
        return v

    @field_validator("outline")
    @classmethod
    def _outline_len(cls, v: list[Point] | str | None) -> list[Point] | str | None:
        if isinstance(v, list) and len(v) < 3:
            raise ValueError("an outline needs at least 3 points")
        return v

    @model_validator(mode="after")
    def _mesh_source(self) -> AleFsiOptions:
        if self.mesh_file is not None and (self.outline is not None or self.subdomains):
            raise ValueError("give either mesh_file or outline/subdomains, not both")
        if (self.geometry == "colony_3d") != (self.colony_surface is not None):
            raise ValueError("geometry 'colony_3d' and colony_surface go together")
        if self.mesh_file is not None and self.geometry != "flow_cell":
            raise ValueError(f"give either mesh_file or geometry {self.geometry!r}, not both")
        if self.geometry != "flow_cell":
            # not yet supported in 3-D (say so rather than half-work)
            clash = [
                name
                for name, on in (
                    ("subdomains", bool(self.subdomains)),
                    ("outline", self.outline is not None and self.geometry != "ridge_3d"),
                )
                if on
            ]
            if clash:
                raise ValueError(f"geometry {self.geometry!r} does not support yet: {clash}")
        return self

    @model_validator(mode="after")
    def _colony_surface_usable(self) -> AleFsiOptions:
        # the surface file read and sampled now (fbia validate), not at the first run
        if self.geometry == "colony_3d" and self.colony_surface is not None:
            from ...core.errors import ConfigError
            from .colony3d import colony_field

            try:
                colony_field(
                    self.colony_surface,
                    self.channel_length,
                    self.channel_height,
                    self.channel_width,
                    self.colony_offset,
                    self.colony_resolution,
                    self.colony_smoothing,
                )
            except ConfigError as err:
                raise ValueError(f"colony_surface {err}") from None
        return self

    @model_validator(mode="after")
    def _motion_order(self) -> AleFsiOptions:
        if self.mesh_motion_order not in (None, 1, self.order):
            raise ValueError(
                f"mesh_motion_order must be 1 or the order ({self.order}), "
                f"got {self.mesh_motion_order}"
            )
        return self

    @model_validator(mode="after")
    def _probe_dimension(self) -> AleFsiOptions:
        # a mesh file's dimension is known only once it is read (AleFsiForwardModel checks)
        if self.mesh_file is None:
            dim = 2 if self.geometry == "flow_cell" else 3
            wrong = [p for p in self.probes if len(p) != dim]
            if wrong:
                raise ValueError(
                    f"probes need {dim} coordinates in geometry {self.geometry!r}, got {wrong}"
                )
        return self


#: The recommended 3-D settings (``dome_3d`` and ``colony_3d``): the largest displacement of
#: the dome within 1 % of both references of ``benchmarks/bench_ale_fsi_3d.py``, which measures
#: them; the docs, the benchmarks and the slow test take them from here.
RECOMMENDED_3D: Mapping[str, Any] = MappingProxyType(
    {
        "order": 3,
        "interface_mesh_size": 0.15,
        "mesh_size": 0.2,
        "curved": True,
        "threads": 2,
        "mesh_motion_layer": 0.15,
        "mesh_motion_order": 1,
        # from the 1 % target: against 1e-10 the dome's largest displacement moves by at most
        # 1.4e-7 relative, and a run takes half the Newton iterations (CHANGELOG, issue 47)
        "newton_tol": 1e-6,
    }
)


def solver_settings(o: AleFsiOptions) -> Any:
    """The solver's :class:`~fbia.plugins.ale_fsi.forms.SolverSettings` from the plugin's
    options (the one place they are mapped; ``growth`` uses it too)."""
    from .forms import SolverSettings

    return settings_from(
        o,
        SolverSettings,
        {
            "min_quality": "min_element_quality",
            "motion_layer": "mesh_motion_layer",
            "motion_order": "mesh_motion_order",
        },
    )
