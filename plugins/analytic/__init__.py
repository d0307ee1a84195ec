"""fbia.plugins.analytic: closed-form interface models for fast tests and demos.

``analytic_mound_2d`` (:class:`AnalyticMound2DForwardModel`) and ``analytic_mound_3d``
(:class:`AnalyticMound3DForwardModel`): a biofilm mound in a flow channel that leans
downstream and flattens under the flow, in closed form (formulas in
:mod:`fbia.plugins.analytic._mechanics`).
"""

from ...core.hookspecs import Register, hookimpl
from .mound_2d import AnalyticMound2DForwardModel
from .mound_3d import AnalyticMound3DForwardModel

__all__ = ["AnalyticMound2DForwardModel", "AnalyticMound3DForwardModel"]


@hookimpl
def register_forward_models(register: Register) -> None:
    """Register the analytic forward models."""
    register("analytic_mound_2d", AnalyticMound2DForwardModel)
    register("analytic_mound_3d", AnalyticMound3DForwardModel)
