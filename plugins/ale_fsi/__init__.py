"""fbia.plugins.ale_fsi: monolithic ALE fluid-biofilm interaction on NGSolve.

>>> import fbia
>>> model = fbia.forward_model("ale_fsi", mesh_size=0.1)            # doctest: +SKIP
>>> sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], "run")  # doctest: +SKIP

Importing this package is cheap: NGSolve is imported only when a model first meshes or solves.
Modules: :mod:`.geometry` (flow-cell builder, user-mesh reader/writer), :mod:`.geometry3d`
(3-D dome and ridge cells), :mod:`.colony3d` (a user's 3-D colony surface, an OCT scan's),
:mod:`.mesh_file3d` (3-D user meshes), :mod:`.solver` (weak forms, Newton, continuation, checks),
:mod:`.model` (the plugin class), :mod:`.output` (VTU), :mod:`.turek_hron` (benchmark
geometry and evaluation).
"""

from ...core.hookspecs import Register, hookimpl
from .model import AleFsiForwardModel

__all__ = ["AleFsiForwardModel"]


@hookimpl
def register_forward_models(register: Register) -> None:
    """Register ``ale_fsi``."""
    register("ale_fsi", AleFsiForwardModel)
