"""fbia.plugins.growth: fluid-biofilm interaction, nutrient transport and surface growth
(Paper A eq. 1-9) on top of ``ale_fsi``.

>>> import fbia
>>> model = fbia.forward_model("growth", mode="quasi_static")                 # doctest: +SKIP
>>> sol = model.solve({"K1g": 6e4, "K2g": 5e-2, "K3g": 8e-2}, [{"day": 1}], "run")  # doctest: +SKIP

Modules: :mod:`.transport` (nutrient transport on the ALE mesh, eq. 5-8), :mod:`.growth_law`
(eq. 9 and the units decision), :mod:`.geometry` (Paper A's finger channel, the interface at
the vertices), :mod:`.mesh_update` (the grown mesh as the new reference), :mod:`.model` (the
plugin class).  Importing this package is cheap: NGSolve is imported when a model solves.
"""

from ...core.hookspecs import Register, hookimpl
from .model import GrowthForwardModel

__all__ = ["GrowthForwardModel"]


@hookimpl
def register_forward_models(register: Register) -> None:
    """Register ``growth``."""
    register("growth", GrowthForwardModel)
