"""Where the ``ale_fsi`` mesh comes from: a user's mesh file or one of the built-in cells.

:func:`build_mesh` dispatches on the options (``mesh_file``, ``geometry``) to
:mod:`~fbia.plugins.fem.flow_cell` (2-D flow cell, 2-D mesh files),
:mod:`~fbia.plugins.ale_fsi.mesh_file3d` (3-D mesh files),
:mod:`~fbia.plugins.ale_fsi.geometry3d` (3-D dome and ridge) and
:mod:`~fbia.plugins.ale_fsi.colony3d` (a user's 3-D colony surface); :func:`regions_in_file`
names the solid regions of a mesh file without NGSolve, so that a model knows its parameters
before it meshes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ...core.errors import ConfigError
from ..fem.flow_cell import BOUNDARY_NAMES, FLUID, SOLID
from ..fem.outlines import resolve_outline
from .options import AleFsiOptions


def build_mesh(o: AleFsiOptions) -> Any:
    """The NGSolve mesh for these options (built or read on every call)."""
    from ..fem import flow_cell as geometry

    if o.mesh_file is not None:
        from .mesh_file3d import is_3d_mesh_file, read_mesh_3d

        if is_3d_mesh_file(o.mesh_file):
            return read_mesh_3d(o.mesh_file)
        return geometry.read_mesh(o.mesh_file)
    if o.geometry == "dome_3d":
        from .geometry3d import build_dome_cell

        return build_dome_cell(
            o.channel_length,
            o.channel_height,
            o.channel_width,
            dome_centre=o.dome_centre,
            dome_radius=o.dome_radius,
            dome_height=o.dome_height,
            mesh_size=o.mesh_size,
            interface_mesh_size=o.interface_size,
            curve_order=o.order if o.curved else 1,
        )
    if o.geometry == "colony_3d" and o.colony_surface is not None:
        from .colony3d import build_colony_cell

        return build_colony_cell(
            o.colony_surface,
            o.channel_length,
            o.channel_height,
            o.channel_width,
            offset=o.colony_offset,
            resolution=o.colony_resolution,
            smoothing=o.colony_smoothing,
            mesh_size=o.mesh_size,
            interface_mesh_size=o.interface_size,
        )
    if o.geometry == "ridge_3d":
        from .geometry3d import build_ridge_cell

        return build_ridge_cell(
            depth=o.channel_width,
            length=o.channel_length,
            height=o.channel_height,
            outline=resolve_outline(o.outline),
            smooth=o.smooth_outline,
            mesh_size=o.mesh_size,
            interface_mesh_size=o.interface_size,
            solid_mesh_size=(
                2.0 * o.interface_size if o.solid_mesh_size is None else o.solid_mesh_size
            ),
        )
    return geometry.build_flow_cell(
        length=o.channel_length,
        height=o.channel_height,
        outline=resolve_outline(o.outline),
        smooth=o.smooth_outline,
        subdomains=o.subdomains,
        mesh_size=o.mesh_size,
        interface_mesh_size=o.interface_size,
        solid_mesh_size=(
            2.0 * o.interface_size if o.solid_mesh_size is None else o.solid_mesh_size
        ),
        curve_order=2 if o.curved else 1,
    )


def regions_in_file(path: Path) -> list[str]:
    """Solid region names in a mesh file, read with meshio (no NGSolve needed)."""
    from ..fem.flow_cell import read_mesh_names
    from .mesh_file3d import is_3d_mesh_file, read_mesh_names_3d

    names = read_mesh_names_3d(path) if is_3d_mesh_file(path) else read_mesh_names(path)
    # boundaries are not regions: 'solid_fixed' is no subdomain 'solid_<k>'
    names = [n for n in names if n not in BOUNDARY_NAMES]
    solids = sorted(n for n in names if n == SOLID or n.startswith(SOLID + "_"))
    solids.sort(key=lambda s: (len(s), s))
    if not solids or FLUID not in names:
        raise ConfigError("mesh needs regions 'fluid' and 'solid[_k]'", str(path))
    return solids
