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
* The pointer file (addresses differ in every process) is not compiled: ``ngscxx`` leaves its
  source as the "object" (:data:`POINTER_FILE` first), and ``ngsld`` links the library once
  per content with placeholder addresses (:data:`PLACEHOLDER`: not a canonical address on
  x86-64 or aarch64), keeps it by the SHA-256 of the objects, the placeholder source and the
  link arguments, and writes a copy with each placeholder's 8 bytes replaced by the real
  address (:func:`patched`).  NGSolve defines every pointer as a literal address
  (``reinterpret_cast<void *>(0x...)``), which the compiler puts in ``.data`` as it stands, no
  relocation; the copy is used only where every placeholder occurs exactly once in the
  library, else the pointer file is compiled and the library linked as NGSolve would
  (``ngsld`` itself starts a Python that imports NGSolve, half a second a call).  A model's
  integrand from the cache then costs three short Python starts and a file copy instead of a
  compilation and a link (``bench`` figures: the CHANGELOG).

"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

#: the names by which NGSolve's generated code reaches its objects
POINTER = re.compile(rb"compiled_code_pointer(\d+)")

#: their declarations (``extern "C" void * ...;`` in the code file) and definitions (``void *
#: ... = <address>;`` in the pointer file): the same list of names in both files
DECLARED = re.compile(rb"void \* compiled_code_pointer(\d+)")

#: a pointer's definition in the pointer file, its address a literal
DEFINITION = re.compile(
    rb"(void \* compiled_code_pointer\d+ = reinterpret_cast<void \*>\()0x([0-9a-fA-F]+)(\))"
)

#: the first line of a pointer file's stand-in object (its source, linked by ``ngsld``)
POINTER_FILE = b"// fbia native_cache: pointer file, linked with placeholder addresses\n"

#: the placeholder address of pointer k is PLACEHOLDER + k: above the 48 (57) bits of a
#: canonical user-space address on x86-64 and aarch64, so never a real pointer
PLACEHOLDER = 0xF1BA_0000_0000_0000

#: placeholders are patched as 8 little-endian bytes
PATCHABLE = sys.byteorder == "little" and struct.calcsize("P") == 8


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
        if PATCHABLE and len(DEFINITION.findall(source)) == len(DECLARED.findall(source)) > 0:
            out.write_bytes(POINTER_FILE + source)  # linked by ngsld (link_library)
            return 0
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
    """``ngsld args``: the objects to NGSolve's library, with NGSolve's link arguments.  With
    pointer files among them (:func:`compile_object`), the library is the cached one of the
    same content with placeholder addresses, patched; where it cannot be, the pointer files
    are compiled and the library linked directly."""
    out = Path(args[args.index("-o") + 1])
    pointer_files = [
        i for i, a in enumerate(args) if a.endswith(".o") and _is_pointer_file(Path(a))
    ]
    if not pointer_files:
        return _link(settings, args)
    sources = {i: Path(args[i]).read_bytes()[len(POINTER_FILE) :] for i in pointer_files}
    addresses: list[int] = []
    placeholders: dict[int, bytes] = {}
    for i, source in sources.items():

        def placeholder(m: re.Match[bytes]) -> bytes:
            addresses.append(int(m.group(2), 16))
            return m.group(1) + b"0x%x" % (PLACEHOLDER + len(addresses) - 1) + m.group(3)

        placeholders[i] = DEFINITION.sub(placeholder, source)
    h = hashlib.sha256(settings["key"].encode())
    h.update("\0".join(settings["link_args"]).encode())
    output = args.index("-o")
    for i, a in enumerate(args):
        if i in (output, output + 1):  # the library's name: another temporary one each time
            continue
        if i in placeholders:
            h.update(b"\0pointers\0" + placeholders[i])
        elif a.endswith(".o"):
            h.update(b"\0object\0" + Path(a).read_bytes())
        else:
            h.update(b"\0" + a.encode())
    cached = Path(settings["cache"]) / f"{h.hexdigest()}.so"
    if not cached.is_file():
        _link_with_placeholders(settings, args, placeholders, len(addresses), cached)
    library = patched(cached.read_bytes(), addresses) if cached.is_file() else None
    if library is None:  # compiled and linked as NGSolve would
        with tempfile.TemporaryDirectory(dir=out.parent) as work:
            for i, source in sources.items():
                cpp = Path(work) / f"pointers_{i}.cpp"
                cpp.write_bytes(source)
                code = subprocess.call([settings["cxx"], "-fPIC", "-c", str(cpp), "-o", args[i]])
                if code:
                    return code
        return _link(settings, args)
    out.write_bytes(library)
    return 0


def _is_pointer_file(path: Path) -> bool:
    with path.open("rb") as f:
        return f.read(len(POINTER_FILE)) == POINTER_FILE


def _link(settings: dict[str, Any], args: list[str]) -> int:
    return subprocess.call([settings["cxx"], *settings["link_args"], *args])


def _link_with_placeholders(
    settings: dict[str, Any],
    args: list[str],
    placeholders: dict[int, bytes],
    n: int,
    cached: Path,
) -> None:
    """Link the library with the placeholder addresses into ``cached`` (written under a
    temporary name and renamed), if each placeholder occurs exactly once in it."""
    work = Path(tempfile.mkdtemp(dir=cached.parent))
    try:
        linked = list(args)
        for i, source in placeholders.items():
            (work / f"pointers_{i}.cpp").write_bytes(source)
            linked[i] = str(work / f"pointers_{i}.o")
            compiled = [settings["cxx"], "-fPIC", "-c", str(work / f"pointers_{i}.cpp")]
            if subprocess.call([*compiled, "-o", linked[i]]):
                return
        library = work / "library.so"
        linked[linked.index("-o") + 1] = str(library)
        if _link(settings, linked) or patched(library.read_bytes(), [0] * n) is None:
            return
        os.replace(library, cached)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def patched(library: bytes, addresses: list[int]) -> bytes | None:
    """``library`` with placeholder k's 8 bytes replaced by ``addresses[k]``; None unless
    every placeholder occurs exactly once (then the bytes are the literal, nothing else)."""
    data = bytearray(library)
    for k, address in enumerate(addresses):
        mark = struct.pack("<Q", PLACEHOLDER + k)
        at = data.find(mark)
        if at < 0 or data.find(mark, at + 1) >= 0:
            return None
        data[at : at + 8] = struct.pack("<Q", address)
    return bytes(data)


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
