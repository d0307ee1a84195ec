"""fbia.plugins.cutfem_fpi: fixed-grid (CutFEM) fluid-poroelastic interaction on NGSolve+ngsxfem.

>>> import fbia
>>> model = fbia.forward_model("cutfem_fpi", background_mesh_size=0.05)      # doctest: +SKIP
>>> sol = model.solve({"E": 300.0, "phi0": 0.25}, [{"inflow_rate": 100.0}], "run")  # doctest: +SKIP

Importing this package is cheap: NGSolve and xfem are imported only when a model first meshes
or solves.  Modules: :mod:`.flow` (cut Navier-Stokes/Darcy with Beavers-Joseph coupling),
:mod:`.skeleton` (poroelastic skeleton on its fitted mesh), :mod:`.coupled` (partitioned
flow | skeleton scheme with Aitken relaxation), :mod:`.model` (the plugin class),
:mod:`.output` (VTU).
"""

from ...core.hookspecs import hookimpl
from .model import CutFemFpiForwardModel

__all__ = ["CutFemFpiForwardModel"]


@hookimpl
def register_forward_models(register):
    """Register ``cutfem_fpi``."""
    register("cutfem_fpi", CutFemFpiForwardModel)
