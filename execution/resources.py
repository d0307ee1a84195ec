"""What the machine can hold: checked before a large allocation, said in one line.

A study file with ``n_particles = 1e9`` or ``workers = 100000`` should not end in an
out-of-memory traceback (or the kernel's OOM killer) minutes later: the plugin estimates
what it will need and :func:`check_memory` compares that with the memory the machine has
available now.

>>> check_memory(1e3, "a tiny array", "example")     # fine
>>> check_memory(1e18, "1e18 bytes", "example", "lower n")  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: example: 1e18 bytes needs about 1e+09 GB of memory; ...
"""

from __future__ import annotations

import os

from ..core.errors import ConfigError

__all__ = ["WORKER_BYTES", "available_memory", "check_memory", "check_workers"]

#: the share of the available memory one allocation may plan to take
SHARE = 0.8

#: the least memory one worker process takes (Python with numpy and fbia imported), bytes
WORKER_BYTES = 100e6


def available_memory() -> float | None:
    """Bytes of memory available to a new allocation now (Linux ``MemAvailable``; else the
    physical memory), None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(nbytes: float, what: str, where: str, hint: str = "") -> None:
    """Raise a one-line ConfigError at ``where`` if ``what`` (about ``nbytes``) would take
    more than 80 % of the memory available; ``hint`` says which setting to lower."""
    available = available_memory()
    if available is None or nbytes <= SHARE * available:
        return
    tail = f"; {hint}" if hint else ""
    raise ConfigError(
        f"{what} needs about {nbytes / 1e9:.3g} GB of memory; this machine has "
        f"{available / 1e9:.3g} GB available{tail}",
        where,
    )


def check_workers(workers: int, where: str) -> None:
    """Refuse more local worker processes than the memory can start (each takes at least
    :data:`WORKER_BYTES` before it runs a model)."""
    check_memory(
        workers * WORKER_BYTES,
        f"{workers} worker processes",
        where,
        "lower workers (each worker process needs at least 0.1 GB before it runs a model)",
    )
