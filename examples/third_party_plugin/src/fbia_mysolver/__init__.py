"""fbia-mysolver: an fbia forward model that runs an external solver (a template to copy).

``fbia.forward_model("mysolver")`` (once installed) builds :class:`MySolverForwardModel`; the
entry point ``[project.entry-points.fbia] mysolver = "fbia_mysolver.plugin"`` in
``pyproject.toml`` is how fbia finds it.
"""

from fbia_mysolver.plugin import MySolverForwardModel

__version__ = "0.1.0"
__all__ = ["MySolverForwardModel"]
