"""fbia.iterators: inverse-analysis algorithms, registered through the ``fbia`` entry points."""

from ..core.hookspecs import hookimpl


@hookimpl
def register_iterators(register):
    """Register the built-in iterators (one line each)."""
    from .levenberg_marquardt import LevenbergMarquardtIterator

    register("levenberg_marquardt", LevenbergMarquardtIterator)
    from .gp_smc.iterator import GpSmcIterator

    register("gp_smc", GpSmcIterator)
    from .sobol_indices import SobolIndicesIterator

    register("sobol_indices", SobolIndicesIterator)
    from .surrogate_convergence import SurrogateConvergenceIterator

    register("surrogate_convergence", SurrogateConvergenceIterator)
