"""fbia.measures: discrepancy measures between interfaces (ray, cpp, rkhs).

``ray``: signed distances along rays from measurement points (Paper A; Paper B eq. 6);
``cpp``: signed closest-point distances of the simulated vertices (Paper B eq. 7);
``rkhs``: RKHS norm of the difference of the interfaces as surface currents (Paper B eq. 10-11).
"""

from ..core.hookspecs import Register, hookimpl
from .cpp import CppMeasure
from .ray import RayMeasure
from .rkhs import RkhsMeasure

__all__ = ["CppMeasure", "RayMeasure", "RkhsMeasure"]


@hookimpl
def register_measures(register: Register) -> None:
    """Register the built-in measures."""
    register("ray", RayMeasure)
    register("cpp", CppMeasure)
    register("rkhs", RkhsMeasure)
