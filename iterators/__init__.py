"""fbia.iterators: inverse-analysis algorithms, registered through the ``fbia`` entry points."""

from fbia.core.hookspecs import hookimpl


@hookimpl
def register_iterators(register):  # type: ignore[no-untyped-def]
    """Register the built-in iterators (one line each)."""
    from fbia.iterators.levenberg_marquardt import LevenbergMarquardtIterator

    register("levenberg_marquardt", LevenbergMarquardtIterator)
    from fbia.iterators.gp_smc import GpSmcIterator

    register("gp_smc", GpSmcIterator)
