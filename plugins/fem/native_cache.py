"""A cache of the objects NGSolve compiles for ``Compile(realcompile=True)``, keyed by content.

NGSolve turns a coefficient function into C++ source and calls two scripts by name, ``ngscxx
-c code_k.cpp -o code_k.o`` for each file and ``ngsld -shared ... -o library.so``, then loads
the library.  :mod:`fbia.plugins.fem.native` puts two small wrappers of that name first on
``PATH`` while it compiles; they run this file as a script (standard library only, no fbia
import: it starts in milliseconds), which does what NGSolve's scripts do, with a cache:

* The source names the objects it reads (proxies, grid functions, parameters) by a counter
  over every compilation of the process, ``compiled_code_pointer88`` ...; one file holds the
  code (declaring every pointer), another (no ``#include``) the pointers' addresses.  Both are
  renumbered from their smallest declared number (:func:`normalise`), so the same integrand
  compiles to the same code in any process.
* The code file's object is looked up by the SHA-256 of that code, the compiler's flags
  and the ``key`` (NGSolve's version, the compiler, the real ``ngscxx`` script); a miss calls
  the real ``ngscxx`` and stores its object (written to a temporary name and renamed, so
  concurrent processes never see half a file).
* The pointer file (addresses differ in every process) is compiled directly by the C++
  compiler, and the library linked directly with NGSolve's link arguments (``ngsld`` does the
  same after a Python start that imports NGSolve, half a second a call).

"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

#: the names by which NGSolve's generated code reaches its objects
POINTER = re.compile(rb"compiled_code_pointer(\d+)")

#: their declarations (``extern "C" void * ...;`` in the code file) and definitions (``void *
#: ... = <address>;`` in the pointer file): the same list of names in both files
DECLARED = re.compile(rb"void \* compiled_code_pointer(\d+)")


def normalise(source: bytes) -> bytes:
    """``source`` with the pointer names renumbered from 0: the smallest *declared* number is
    subtracted, so that the code file (which declares every pointer of the compilation) and the
    pointer file (which defines every one) are shifted alike even where the code uses only some
    of them.  A source that uses a pointer it does not declare is returned as it is (then no
    object is shared, but none is bound to the wrong pointer)."""
    declared = {int(n) for n in DECLARED.findall(source)}
    used = {int(n) for n in POINTER.findall(source)}
    if not used or not used <= declared:
        return source
    base = min(declared)
    return POINTER.sub(lambda m: b"compiled_code_pointer%d" % (int(m.group(1)) - base), source)


def cache_key(key: str, args: list[str], source: bytes) -> str:
    """SHA-256 of the cache's key, the compiler's flags (the source's and the output's names
    aside: the source is hashed by content) and the normalised source."""
    h = hashlib.sha256(key.encode())
    flags = [
        a
        for i, a in enumerate(args)
        if a != "-o" and not a.endswith(".cpp") and (i == 0 or args[i - 1] != "-o")
    ]
    h.update("\0".join(flags).encode())
    h.update(b"\0")
    h.update(source)
    return h.hexdigest()


def compile_object(settings: dict[str, Any], args: list[str]) -> int:
    """``ngscxx args``: one source file to one object, through the cache."""
    out = Path(args[args.index("-o") + 1])
    source_path = Path(next(a for a in args if a.endswith(".cpp")))
    source = normalise(source_path.read_bytes())
    source_path.write_bytes(source)
    if b"#include" not in source:  # the pointers' addresses: new in every process
        return subprocess.call([settings["cxx"], "-fPIC", *args])
    cached = Path(settings["cache"]) / f"{cache_key(settings['key'], args, source)}.o"
    if cached.is_file():
        shutil.copyfile(cached, out)
        return 0
    code = subprocess.call([settings["ngscxx"], *args])
    if code == 0:
        partial = cached.with_name(f"{cached.name}.{os.getpid()}")
        shutil.copyfile(out, partial)
        os.replace(partial, cached)
    return code


def link_library(settings: dict[str, Any], args: list[str]) -> int:
    """``ngsld args``: the objects to NGSolve's library, with NGSolve's link arguments."""
    return subprocess.call([settings["cxx"], *settings["link_args"], *args])


def main(argv: list[str]) -> int:
    """``native_cache.py SETTINGS TOOL ARGS...``: SETTINGS a JSON file (``cache``: the folder
    of the objects, ``ngscxx``: NGSolve's script, ``cxx``: the compiler it calls,
    ``link_args``: NGSolve's link arguments, ``key``: their versions), TOOL ``ngscxx`` or
    ``ngsld``, ARGS what NGSolve passed."""
    settings = json.loads(Path(argv[0]).read_text(encoding="utf-8"))
    tool, args = argv[1], argv[2:]
    if tool == "ngsld":
        return link_library(settings, args)
    return compile_object(settings, args)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
