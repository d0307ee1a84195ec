"""Integrands compiled to machine code: NGSolve's ``Compile(realcompile=True)``, cached.

NGSolve evaluates a symbolic integrand by walking its expression tree at every quadrature
point; ``Compile()`` flattens the tree, ``Compile(realcompile=True)`` writes it as C++ and
compiles it.  On the 2-D flow cell (``ale_fsi``, P2/P1) the Jacobian then assembles several
times faster and a calibration runs about twice as fast; the 3-D dome at order 3 gains less
(its assembly is bound by the element matrices, not the integrand).  The discrete problem is
the same: the Jacobian agrees with the interpreted one to round-off.  Figures:
``benchmarks/bench_lm_vs_scipy.py --set model.options.native_code=true`` and the CHANGELOG
(issue 47).

The price is the compiler: seconds per integrand the first time, and a C++ compiler on the
machine (NGSolve's pip wheels ship the ``ngscxx`` script that calls it, not the compiler).
:mod:`.native_cache` keeps the compiled objects in ``$FBIA_CACHE_DIR/native`` (default
``$XDG_CACHE_HOME/fbia`` or ``~/.cache/fbia``), so every later process takes an integrand it
has seen from there in a fraction of a second.

:func:`compile_integrand` is what a model calls; it falls back to ``Compile()`` (and says
why in its :class:`NativeCode`) where there is no compiler or a compilation fails, so a study
that asks for native code runs everywhere, at the interpreted speed where it must.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import threading
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["NativeCode", "cache_root", "compile_integrand", "toolchain"]

#: environment variable naming the folder of fbia's caches
CACHE_ENV = "FBIA_CACHE_DIR"

#: the cache tool that the ``ngscxx`` / ``ngsld`` wrappers run (standard library only)
CACHE_TOOL = Path(__file__).with_name("native_cache.py")


@dataclass(frozen=True)
class NativeCode:
    """How an integrand was compiled: ``requested`` (the model's ``native_code``), ``used``
    (machine code), ``reason`` (why not, when requested and not used)."""

    requested: bool = False
    used: bool = False
    reason: str = ""

    def describe(self) -> str:
        """``off``, ``compiled``, or ``interpreted: <why>`` (a run's diagnostics)."""
        if not self.requested:
            return "off"
        return "compiled" if self.used else f"interpreted: {self.reason}"

    @staticmethod
    def of_all(outcomes: Sequence[NativeCode]) -> NativeCode:
        """One outcome for a model of several integrands: the first that fell back to the
        interpreted code, else the first."""
        fell_back = (o for o in outcomes if o.requested and not o.used)
        return next(fell_back, outcomes[0] if outcomes else NativeCode())


@dataclass(frozen=True)
class Toolchain:
    """The wrappers that stand in for NGSolve's ``ngscxx`` and ``ngsld`` (``bin``) and the
    folder of the Python whose NGSolve the real scripts import."""

    bin: Path
    python_bin: Path

    @contextlib.contextmanager
    def on_path(self) -> Iterator[None]:
        """The wrappers first on ``PATH`` (NGSolve calls the scripts by name), then the
        Python's folder (the real ``ngscxx`` calls ``python3`` to import NGSolve's config)."""
        before = os.environ.get("PATH", "")
        os.environ["PATH"] = os.pathsep.join([str(self.bin), str(self.python_bin), before])
        try:
            yield
        finally:
            os.environ["PATH"] = before


def cache_root() -> Path:
    """fbia's cache folder: ``$FBIA_CACHE_DIR``, else ``$XDG_CACHE_HOME/fbia``, else
    ``~/.cache/fbia``."""
    if os.environ.get(CACHE_ENV):
        return Path(os.environ[CACHE_ENV])
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "fbia"


def _compiler_of(script: str) -> str | None:
    """The C++ compiler NGSolve's ``ngscxx`` script calls: the first existing absolute path of
    its ``if [ -f ... ]`` tests (a toolset on NGSolve's build machines), else ``c++``."""
    for path in re.findall(r"if \[ -f (/\S+) \]", script):
        if Path(path).is_file() and not path.endswith("ccache"):
            return path
    return shutil.which("c++")


@functools.cache
def toolchain() -> Toolchain | str:
    """The wrappers, written once per process into the cache folder of this NGSolve and
    compiler; or why there are none (no ``ngscxx`` beside Python, no C++ compiler)."""
    python_bin = Path(sys.executable).parent
    ngscxx = python_bin / "ngscxx"
    if not ngscxx.is_file():
        found = shutil.which("ngscxx")
        if found is None:
            return "NGSolve's ngscxx script is not installed beside Python"
        ngscxx = Path(found)
    script = ngscxx.read_text(encoding="utf-8", errors="replace")
    cxx = _compiler_of(script)
    if cxx is None:
        return "no C++ compiler (c++) on PATH"
    try:
        version = subprocess.run(
            [cxx, "--version"], capture_output=True, text=True, timeout=30, check=True
        ).stdout.splitlines()[0]
    except (OSError, subprocess.SubprocessError, IndexError) as exc:
        return f"the C++ compiler {cxx} does not run ({exc})"
    import ngsolve
    import ngsolve.config

    key = "\n".join(
        [
            ngsolve.__version__,
            version,
            platform.machine(),
            hashlib.sha256(script.encode()).hexdigest(),
            hashlib.sha256(CACHE_TOOL.read_bytes()).hexdigest(),
        ]
    )
    folder = cache_root() / "native" / hashlib.sha256(key.encode()).hexdigest()[:16]
    bin_dir = folder / "bin"
    try:
        bin_dir.mkdir(parents=True, exist_ok=True)
        settings = folder / "settings.json"
        _write(
            settings,
            json.dumps(
                {
                    "cache": str(folder),
                    "ngscxx": str(ngscxx),
                    "cxx": cxx,
                    "link_args": shlex.split(ngsolve.config.get_link_lib_args()),
                    "key": key,
                },
                indent=1,
            ),
        )
        for tool in ("ngscxx", "ngsld"):
            # -I -S: no site-packages (the tool needs the standard library alone; 15-20 ms a call)
            command = [sys.executable, "-I", "-S", str(CACHE_TOOL), str(settings), tool]
            wrapper = bin_dir / tool
            _write(wrapper, f'#!/bin/sh\nexec {shlex.join(command)} "$@"\n')
            wrapper.chmod(0o755)
    except OSError as exc:
        return f"the cache folder {folder} is not writable ({exc})"
    return Toolchain(bin_dir, python_bin)


def _write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary name (other processes read it whole)."""
    partial = path.with_name(f"{path.name}.{os.getpid()}")
    partial.write_text(text, encoding="utf-8")
    os.replace(partial, path)


#: compilations that failed in this process, by toolchain: later integrands skip the compiler
_FAILED: dict[Path, str] = {}

#: one compilation at a time in a process: ``PATH`` is the process's, and a Dask worker may run
#: tasks (and build models) in several threads
_COMPILING = threading.Lock()


def compile_integrand(cf: Any, native: bool) -> tuple[Any, NativeCode]:
    """``cf.Compile()``, or with ``native`` ``cf.Compile(realcompile=True, wait=True)``
    through the cache (``wait``: the machine code from the first evaluation on, not the
    interpreted one until the compiler is done); where that is not possible, ``Compile()``
    and the reason."""
    if not native:
        return cf.Compile(), NativeCode()
    chain = toolchain()
    if isinstance(chain, str):
        return _interpreted(cf, chain)
    if chain.bin in _FAILED:
        return _interpreted(cf, _FAILED[chain.bin])
    try:
        with _COMPILING, chain.on_path():
            compiled = cf.Compile(realcompile=True, wait=True)
    except Exception as exc:  # NGSolve reports a failed compiler call as a plain NgException
        reason = f"the compilation failed: {str(exc).splitlines()[0] if str(exc) else exc!r}"
        _FAILED[chain.bin] = reason
        return _interpreted(cf, reason)
    return compiled, NativeCode(True, True)


def _interpreted(cf: Any, reason: str) -> tuple[Any, NativeCode]:
    """``Compile()`` where machine code was asked for, with a warning (once per reason, by
    Python's default filter) and the reason in the outcome."""
    warnings.warn(
        f"native_code: {reason}; the integrands run interpreted (the same problem, slower)",
        RuntimeWarning,
        stacklevel=3,
    )
    return cf.Compile(), NativeCode(True, False, reason)
