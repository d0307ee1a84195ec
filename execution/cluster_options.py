"""The ``cluster_options`` a study may give the Dask executor's cluster: an allow-list.

A study file is data: it names registered plugins and options, it never runs code or opens the
network.  ``[executor] cluster_options`` go to ``distributed.LocalCluster`` or to a
dask-jobqueue cluster, and among their keyword arguments are ``preload`` (runs a script in
every worker), ``host`` or ``interface`` (bind Dask's scheduler or workers to a network
interface: ``host = "0.0.0.0"`` opens the cluster to the network), ``job_script_prologue``
(shell commands in the job script) and ``python`` (the program the job runs).  So only the keys
below are accepted.  A batch system's values go into its job script, as directives
(``#SBATCH -p short``) or on the worker's command line, which the shell runs: such a value is
one word of letters, digits and ``. , : = + - / @ % [ ]``, and each ``job_extra_directives``
entry is a flag of the batch system's allow-list (:data:`DIRECTIVE_FLAGS`) with such words as
its value, never one that sets the job's environment (``--export=ALL,LD_PRELOAD=...``).  A
site that needs one of the others (e.g. ``interface = "ib0"`` on an InfiniBand cluster, or a
directive fbia does not know) sets it in Dask's own configuration (``~/.config/dask/``,
e.g. ``jobqueue.slurm.job-extra-directives``), which belongs to the user, not to the study.

>>> check_cluster_options("local", {"memory_limit": "4GB"})
>>> check_cluster_options("slurm", {"job_extra_directives": ["--partition=short", "-q low"]})
>>> check_cluster_options("local", {"host": "0.0.0.0"})
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: 'host' is not allowed: a study file may not run code or open \
the network (a site that needs it sets it in Dask's configuration); allowed for cluster \
'local': dashboard, death_timeout, local_directory, memory_limit, resources, threads_per_worker
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from ..core.errors import ConfigError

__all__ = [
    "DIRECTIVE_FLAGS",
    "HTCONDOR_DIRECTIVES",
    "JOBQUEUE_OPTIONS",
    "LOCAL_OPTIONS",
    "check_cluster_options",
    "directive_items",
]

#: keyword arguments of ``distributed.LocalCluster`` (and of its workers) a study may set, and
#: ``dashboard`` (fbia's: true serves Dask's dashboard on a free loopback port)
LOCAL_OPTIONS = frozenset(
    {"memory_limit", "threads_per_worker", "local_directory", "death_timeout", "resources"}
    | {"dashboard"}
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

_PBS_FLAGS = frozenset({"-l", "-q", "-A", "-N", "-o", "-e", "-M", "-m", "-j", "-P"})
#: the flags a ``job_extra_directives`` entry may use, per batch system: resources, queue,
#: accounting, job name, mail and log files.  Not the flags that set the job's environment
#: (SLURM ``--export``, PBS and SGE ``-v``/``-V``, LSF ``-env``), run a program (OAR
#: ``--notify``) or change whose job it is.
DIRECTIVE_FLAGS: dict[str, frozenset[str]] = {
    "slurm": frozenset(
        {
            *("--account", "--partition", "--qos", "--time", "--mem", "--mem-per-cpu"),
            *("--cpus-per-task", "--constraint", "--gres", "--gpus", "--nodes", "--ntasks"),
            *("--ntasks-per-node", "--exclusive", "--mail-type", "--mail-user", "--job-name"),
            *("--output", "--error", "--reservation", "--nodelist", "--exclude"),
            *("-A", "-p", "-q", "-t", "-c", "-C", "-N", "-n", "-J", "-o", "-e", "-w", "-x"),
        }
    ),
    "pbs": _PBS_FLAGS,
    "moab": _PBS_FLAGS,  # dask-jobqueue's Moab jobs are PBS jobs
    "sge": frozenset({"-l", "-q", "-P", "-A", "-N", "-o", "-e", "-M", "-m", "-j", "-pe"}),
    "lsf": frozenset(
        {"-q", "-P", "-J", "-o", "-e", "-W", "-n", "-R", "-M", "-u", "-B", "-N", "-G", "-x"}
        | {"-gpu", "-sla"}
    ),
    "oar": frozenset({"-l", "-q", "-n", "-O", "-E", "-t", "--project"}),
}
#: the submit-file keys an HTCondor cluster's ``job_extra_directives`` (a table) may set
HTCONDOR_DIRECTIVES = frozenset(
    {
        *("request_gpus", "request_disk", "requirements", "rank", "priority"),
        *("accounting_group", "accounting_group_user", "notification", "notify_user"),
        "concurrency_limits",
    }
)
_ENVIRONMENT_FLAGS = frozenset({"--export", "--export-file", "--get-user-env", "-v", "-V", "-env"})
_WORD = re.compile(r"[A-Za-z0-9_.,:=+\-/@%\[\]]+")
_LD_VARIABLE = re.compile(r"(?<![A-Za-z0-9])LD_[A-Z]")  # LD_PRELOAD, LD_LIBRARY_PATH, ...
_WORD_CHARS = "letters, digits and . , : = + - / @ % [ ]"
# options whose values the job script never sees, or sees only to drop lines
_NOT_IN_SCRIPT = frozenset({"job_extra_directives", "job_directives_skip"})


def check_cluster_options(cluster: str, options: Mapping[str, Any]) -> None:
    """A ConfigError (one line) for the first key of ``options`` that ``cluster`` ("local" or
    a dask-jobqueue kind) may not take from a study, or for a value the job script would run
    (a line break, a shell character, a directive outside :data:`DIRECTIVE_FLAGS`)."""
    allowed = LOCAL_OPTIONS if cluster == "local" else JOBQUEUE_OPTIONS
    for key, value in options.items():
        if key not in allowed:
            raise ConfigError(
                f"{key!r} is not allowed: a study file may not run code or open the network "
                f"(a site that needs it sets it in Dask's configuration); allowed for cluster "
                f"{cluster!r}: "
                f"{', '.join(sorted(allowed))}"
            )
        if key == "job_extra_directives":  # each one named, line breaks included
            _check_directives(cluster, value)
        if _has_line_break(value):
            raise ConfigError(
                f"{key!r}: a value with a line break is not allowed (it would add lines to the "
                "job script)"
            )
        if key == "dashboard" and not isinstance(value, bool):
            raise ConfigError(f"'dashboard': expected true or false, got {value!r}")
        if cluster == "local" or key in _NOT_IN_SCRIPT:
            continue
        for word in value if isinstance(value, (list, tuple)) else [value]:
            if isinstance(word, str) and (reason := _not_a_word(word)):
                raise ConfigError(
                    f"{key!r}: {word!r} is refused ({reason}): a value goes into the job "
                    f"script, where it is one word of {_WORD_CHARS}"
                )


def _check_directives(cluster: str, directives: Any) -> None:
    if cluster == "htcondor":
        _check_submit_keys(directives)
        return
    if not isinstance(directives, (list, tuple)):
        raise ConfigError(
            f"'job_extra_directives': expected a list of directives, got {directives!r}"
        )
    flags = DIRECTIVE_FLAGS.get(cluster, frozenset())
    listed = ", ".join(sorted(flags, key=lambda f: (f.lower(), f)))
    for directive in directives:
        if reason := _directive_fault(directive, flags):
            raise ConfigError(
                f"'job_extra_directives': {directive!r} is refused ({reason}); allowed flags "
                f"for cluster {cluster!r}: {listed}"
            )


def _check_submit_keys(directives: Any) -> None:
    """HTCondor's ``job_extra_directives``: a table of submit-file keys and values."""
    if not isinstance(directives, Mapping):
        raise ConfigError(
            "'job_extra_directives': expected a table of submit-file keys for cluster "
            f"'htcondor', got {directives!r}"
        )
    for key, value in directives.items():
        if key not in HTCONDOR_DIRECTIVES:
            fault = f"{key!r} is not an allowed key"
        elif _LD_VARIABLE.search(str(value)) or any(c in str(value) for c in "$`"):
            fault = "a macro, a command or an LD_ variable in its value"
        else:
            continue
        raise ConfigError(
            f"'job_extra_directives': {key} = {value!r} is refused ({fault}); allowed "
            f"keys for cluster 'htcondor': {', '.join(sorted(HTCONDOR_DIRECTIVES))}"
        )


def directive_items(directive: str) -> list[tuple[str, str]]:
    """A job directive as (flag, value) pairs: ``"--partition=short -q low"`` gives
    ``[("--partition", "short"), ("-q", "low")]``, ``"-pe smp 8"`` ``[("-pe", "smp 8")]``;
    words before the first flag are paired with an empty flag."""
    items: list[tuple[str, list[str]]] = []
    for word in directive.split():
        if word.startswith("--"):
            flag, _, value = word.partition("=")
            items.append((flag, [value] if value else []))
        elif word.startswith("-"):
            items.append((word, []))
        elif items:
            items[-1][1].append(word)
        else:
            items.append(("", [word]))
    return [(flag, " ".join(words)) for flag, words in items]


def _directive_fault(directive: Any, flags: frozenset[str]) -> str | None:
    """Why ``directive`` may not go into a job script, or None."""
    if not isinstance(directive, str):
        return "a directive is a string"
    if _has_line_break(directive):
        return "a line break would add lines to the job script"
    items = directive_items(directive)
    if not items:
        return "it is empty"
    for flag, value in items:
        if flag in _ENVIRONMENT_FLAGS:
            return f"{flag} sets the job's environment"
        if not flag:
            return f"{value!r} is not a flag"
        if flag not in flags:
            return f"{flag} is not an allowed flag"
        for word in value.split():
            if reason := _not_a_word(word):
                return reason
    return None


def _not_a_word(text: str) -> str | None:
    """Why ``text`` is not one harmless word of a job script, or None."""
    if _LD_VARIABLE.search(text):
        return "LD_ variables load code into the job's programs"
    bad = next((c for c in text if not _WORD.fullmatch(c)), None)
    if bad is not None:
        return "a space" if bad.isspace() else f"the character {bad!r}"
    return None


def _has_line_break(value: Any) -> bool:
    if isinstance(value, str):
        return any(c in value for c in "\n\r\x00")
    if isinstance(value, Mapping):
        return any(_has_line_break(k) or _has_line_break(v) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return any(_has_line_break(v) for v in value)
    return False
