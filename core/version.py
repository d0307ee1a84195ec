"""The version of fbia (kept equal to ``project.version`` in pyproject.toml by a test)."""

__version__ = "0.2.0"
