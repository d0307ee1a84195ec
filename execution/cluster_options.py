"""The ``cluster_options`` a study may give the Dask executor's cluster: an allow-list.

A study file is data: it names registered plugins and options, it never runs code or opens the
network.  ``[executor] cluster_options`` go to ``distributed.LocalCluster`` or to a
dask-jobqueue cluster, and among their keyword arguments are ``preload`` (runs a script in
every worker), ``host`` or ``interface`` (bind Dask's unauthenticated scheduler or workers to
a network interface: ``host = "0.0.0.0"`` opens the cluster to the network),
``job_script_prologue`` (shell commands in the job script) and ``python`` (the program the
job runs).  So only the keys below are accepted, and a string with a line break (which would
add lines to a job script) is refused.  A site that needs one of the others (e.g.
``interface = "ib0"`` on an InfiniBand cluster) sets it in Dask's own configuration
(``~/.config/dask/``), which belongs to the user, not to the study.

>>> check_cluster_options("local", {"memory_limit": "4GB"})
>>> check_cluster_options("local", {"host": "0.0.0.0"})
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: 'host' is not allowed: a study file may not run code or open \
the network (a site that needs it sets it in Dask's configuration); allowed for cluster \
'local': death_timeout, local_directory, memory_limit, resources, threads_per_worker
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..core.errors import ConfigError

__all__ = ["JOBQUEUE_OPTIONS", "LOCAL_OPTIONS", "check_cluster_options"]

#: keyword arguments of ``distributed.LocalCluster`` (and of its workers) a study may set
LOCAL_OPTIONS = frozenset(
    {"memory_limit", "threads_per_worker", "local_directory", "death_timeout", "resources"}
)
#: keyword arguments of the dask-jobqueue clusters a study may set: the resources a job asks
#: for and where its files go (each cluster class takes its own subset of them)
JOBQUEUE_OPTIONS = frozenset(
    {
        "cores",
        "memory",
        "processes",
        "walltime",
        "queue",
        "account",
        "project",
        "name",
        "job_cpu",
        "job_mem",
        "ncpus",
        "mem",
        "disk",
        "lsf_units",
        "resource_spec",
        "memory_per_core_property_name",
        "job_extra_directives",
        "job_directives_skip",
        "death_timeout",
        "local_directory",
        "log_directory",
    }
)


def check_cluster_options(cluster: str, options: Mapping[str, Any]) -> None:
    """A ConfigError (one line) for the first key of ``options`` that ``cluster`` ("local" or
    a dask-jobqueue kind) may not take from a study, or for a value with a line break."""
    allowed = LOCAL_OPTIONS if cluster == "local" else JOBQUEUE_OPTIONS
    for key, value in options.items():
        if key not in allowed:
            raise ConfigError(
                f"{key!r} is not allowed: a study file may not run code or open the network "
                f"(a site that needs it sets it in Dask's configuration); allowed for cluster "
                f"{cluster!r}: "
                f"{', '.join(sorted(allowed))}"
            )
        if _has_line_break(value):
            raise ConfigError(
                f"{key!r}: a value with a line break is not allowed (it would add lines to the "
                "job script)"
            )


def _has_line_break(value: Any) -> bool:
    if isinstance(value, str):
        return any(c in value for c in "\n\r\x00")
    if isinstance(value, Mapping):
        return any(_has_line_break(k) or _has_line_break(v) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return any(_has_line_break(v) for v in value)
    return False
