"""fbia.plugins.analytic: closed-form interface models for fast tests and demos."""

from fbia.core.hookspecs import hookimpl


@hookimpl
def register_forward_models(register):  # type: ignore[no-untyped-def]
    """Register the analytic forward models."""
