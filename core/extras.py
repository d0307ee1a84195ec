"""Optional parts of fbia and the libraries they need (the package's extras).

``pip install fbia`` installs the core: the study files, the measures, Levenberg–Marquardt,
the analytic models, the store, the plots and the conformance kit (:mod:`fbia.testing`), so
a plugin author needs none of the heavy stacks.  The rest comes with an extra:

==========  ===========================================  ==================================
extra       what it gives                                modules
==========  ===========================================  ==================================
``fem``     the finite-element models (``ale_fsi``,      ``ngsolve``, ``netgen``, ``xfem``
            ``cutfem_fpi``, ``growth``)
``bayes``   Paper B's GP + SMC (``gp_smc``), Sobol'      ``GPy``, ``numba``, ``SALib``
            indices, the surrogate study
``oct``     OCT scans as observations                    ``skimage``, ``tifffile``, ``nrrd``
``dask``    the Dask executor                            ``distributed``
``tables``  results as ``pandas`` DataFrames             ``pandas``
``all``     all of them (``make demo`` and ``make test`` install it)
==========  ===========================================  ==================================

A plugin class states what it needs as ``requires = ("ngsolve", ...)`` (module names); the
registry checks them before it builds the plugin, and :func:`require` does the same for
fbia's own optional parts, so a missing extra is one line naming the extra to install, not
a traceback from inside the first forward run.

>>> require(("math",), "a test")      # present: nothing happens
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterable

from .errors import ConfigError

__all__ = ["EXTRA_OF_MODULE", "missing", "require"]

#: the extra that installs each optional module
EXTRA_OF_MODULE: dict[str, str] = {
    "ngsolve": "fem",
    "netgen": "fem",
    "xfem": "fem",
    "GPy": "bayes",
    "numba": "bayes",
    "SALib": "bayes",
    "skimage": "oct",
    "tifffile": "oct",
    "nrrd": "oct",
    "distributed": "dask",
    "dask": "dask",
    "pandas": "tables",
}


def missing(modules: Iterable[str]) -> list[str]:
    """The modules of ``modules`` that cannot be imported here."""
    out = []
    for name in modules:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):  # a parent package missing, or set to None
            found = False
        if not found:
            out.append(name)
    return out


def require(modules: Iterable[str], what: str) -> None:
    """Raise a one-line :class:`ConfigError` naming the extra(s) to install when one of
    ``modules`` is missing; ``what`` is the part of fbia that needs them."""
    absent = missing(modules)
    if not absent:
        return
    extras = sorted({EXTRA_OF_MODULE.get(m, "") for m in absent} - {""})
    hint = f"pip install 'fbia[{','.join(extras)}]'" if extras else f"install {', '.join(absent)}"
    raise ConfigError(f"needs {', '.join(absent)}, which is not installed: {hint}", what)
