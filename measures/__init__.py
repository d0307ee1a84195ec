"""fbia.measures: discrepancy measures between interfaces (ray, cpp, rkhs)."""

from fbia.core.hookspecs import hookimpl


@hookimpl
def register_measures(register):  # type: ignore[no-untyped-def]
    """Register the built-in measures."""
