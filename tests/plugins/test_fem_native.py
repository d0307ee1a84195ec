"""Integrands compiled to machine code (fbia.plugins.fem.native) and the cache of their
objects (fbia.plugins.fem.native_cache): the same discrete problem as the interpreted code,
one compilation per integrand across processes, and the interpreted code with a reason where
there is no compiler or a compilation fails."""

from __future__ import annotations

import json
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("ngsolve")

from fbia.plugins.ale_fsi import AleFsiForwardModel  # noqa: E402
from fbia.plugins.fem import native, native_cache  # noqa: E402

COARSE = {"mesh_size": 0.2, "interface_mesh_size": 0.06, "warm_start": False}

CODE = b"""#include<coefficient.hpp>
extern "C" void * compiled_code_pointer%d;
extern "C" void * compiled_code_pointer%d;
void CompiledEvaluate() { use(compiled_code_pointer%d, compiled_code_pointer%d); }
"""


def test_normalise_renumbers_the_pointers_from_zero() -> None:
    a = native_cache.normalise(CODE % (88, 89, 88, 89))
    assert a == native_cache.normalise(CODE % (0, 1, 0, 1)) == CODE % (0, 1, 0, 1)
    assert native_cache.normalise(CODE % (7, 9, 7, 9)) == CODE % (0, 2, 0, 2)
    assert native_cache.normalise(b"int x;") == b"int x;"


def test_normalise_shifts_by_the_declared_pointers_not_the_used_ones() -> None:
    """The code file declares every pointer of its compilation but may use only some; the
    pointer file defines them all: both must shift alike, or the code binds another object."""
    code = (
        b'extern "C"  void * compiled_code_pointer88;\n'
        b'extern "C"  void * compiled_code_pointer89;\n'
        b"use(compiled_code_pointer89);\n"
    )
    pointers = (
        b"[[maybe_unused]]  void * compiled_code_pointer88 = reinterpret_cast<void *>(0x10);\n"
        b"[[maybe_unused]]  void * compiled_code_pointer89 = reinterpret_cast<void *>(0x20);\n"
    )
    assert native_cache.normalise(code).endswith(b"use(compiled_code_pointer1);\n")
    assert b"compiled_code_pointer1 = reinterpret_cast<void *>(0x20)" in native_cache.normalise(
        pointers
    )
    # a pointer used but not declared: left as it is (no shared object, no wrong binding)
    undeclared = b"use(compiled_code_pointer5);"
    assert native_cache.normalise(undeclared) == undeclared


def _fake_compiler(tmp_path: Path) -> dict[str, object]:
    """Settings of the cache tool with a stand-in for NGSolve's ngscxx that logs each call and
    writes the normalised source as its 'object'."""
    log = tmp_path / "calls.log"
    script = tmp_path / "ngscxx"
    script.write_text(
        f'#!/bin/sh\necho "$@" >> {log}\n'
        'while [ "$1" != "-o" ]; do src="$1"; shift; done\ncp "$src" "$2"\n'
    )
    script.chmod(0o755)
    cache = tmp_path / "cache"
    cache.mkdir()
    return {"cache": str(cache), "ngscxx": str(script), "cxx": "c++", "link_args": [], "key": "k"}


def test_the_cache_compiles_an_integrand_once_whatever_its_pointer_numbers(
    tmp_path: Path,
) -> None:
    settings = _fake_compiler(tmp_path)
    objects = []
    for k, first in enumerate([0, 28, 5]):  # three processes, three counters
        work = tmp_path / f"p{k}"
        work.mkdir()
        (work / "code_0.cpp").write_bytes(CODE % (first, first + 1, first, first + 1))
        args = ["-c", str(work / "code_0.cpp"), "-o", str(work / "code_0.o")]
        assert native_cache.compile_object(settings, args) == 0
        objects.append((work / "code_0.o").read_bytes())
        # the source the compiler saw (or would have seen) is renumbered in place
        assert (work / "code_0.cpp").read_bytes() == CODE % (0, 1, 0, 1)
    assert len((tmp_path / "calls.log").read_text().splitlines()) == 1
    assert objects[0] == objects[1] == objects[2]
    assert len(list(Path(str(settings["cache"])).glob("*.o"))) == 1
    # another integrand is another object
    work = tmp_path / "other"
    work.mkdir()
    (work / "code_0.cpp").write_bytes(CODE.replace(b"use", b"other") % (3, 4, 3, 4))
    native_cache.compile_object(
        settings, ["-c", str(work / "code_0.cpp"), "-o", str(work / "code_0.o")]
    )
    assert len((tmp_path / "calls.log").read_text().splitlines()) == 2


def test_the_cache_tool_reads_its_settings_file(tmp_path: Path) -> None:
    settings = _fake_compiler(tmp_path)
    path = tmp_path / "settings.json"
    path.write_text(json.dumps(settings))
    (tmp_path / "code_0.cpp").write_bytes(CODE % (4, 5, 4, 5))
    out = tmp_path / "code_0.o"
    args = [str(path), "ngscxx", "-c", str(tmp_path / "code_0.cpp"), "-o", str(out)]
    assert native_cache.main(args) == 0
    assert out.read_bytes() == CODE % (0, 1, 0, 1)


def test_without_a_compiler_the_model_runs_interpreted_and_says_why(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setattr(native, "toolchain", lambda: "no C++ compiler (c++) on PATH")
    with pytest.warns(RuntimeWarning, match="no C.. compiler .* run interpreted"):
        sol = AleFsiForwardModel(**COARSE, native_code=True).solve(
            {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path
        )
    assert sol.diagnostics["native_code"] == "interpreted: no C++ compiler (c++) on PATH"


def test_a_failed_compilation_falls_back_once_for_the_process(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    import ngsolve

    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    for tool in ("ngscxx", "ngsld"):
        (bin_dir / tool).write_text("#!/bin/sh\nexit 1\n")
        (bin_dir / tool).chmod(0o755)
    chain = native.Toolchain(bin_dir, Path(sys.executable).parent)
    monkeypatch.setattr(native, "toolchain", lambda: chain)
    monkeypatch.setattr(native, "_FAILED", {})
    x = ngsolve.Parameter(2.0)
    with pytest.warns(RuntimeWarning, match="the compilation failed"):
        compiled, outcome = native.compile_integrand(x * x + 1.0, native=True)
    assert outcome.requested and not outcome.used
    assert outcome.describe().startswith("interpreted: the compilation failed")
    assert native._FAILED[bin_dir] == outcome.reason
    # the interpreted code gives the value
    mesh = ngsolve.Mesh(__import__("netgen.geom2d").geom2d.unit_square.GenerateMesh(maxh=0.5))
    assert compiled(mesh(0.5, 0.5)) == pytest.approx(5.0)
    with pytest.warns(RuntimeWarning):
        _, again = native.compile_integrand(x + 1.0, native=True)
    assert again == outcome
    assert native.compile_integrand(x, native=False)[1].describe() == "off"


def test_cache_root_follows_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FBIA_CACHE_DIR", "/some/where")
    assert native.cache_root() == Path("/some/where")
    monkeypatch.delenv("FBIA_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", "/xdg")
    assert native.cache_root() == Path("/xdg/fbia")


@pytest.mark.skipif(isinstance(native.toolchain(), str), reason="no C++ compiler for NGSolve")
def test_machine_code_solves_the_same_discrete_problem(tmp_path: Path) -> None:
    """The coarse 2-D cell at 100 mm^2/s: the same Newton path, the same state to round-off,
    and the Jacobian at it to 1e-10 of its largest entry."""
    states, jacobians, diagnostics = [], [], []
    for flag in (False, True):
        model = AleFsiForwardModel(**COARSE, native_code=flag)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sol = model.solve({"E": 400.0, "nu": 0.3}, [{"inflow_rate": 100.0}], tmp_path)
        # off and compiled: no fallback warning (it fires only where the code is interpreted)
        assert not [w for w in caught if "native_code" in str(w.message)]
        solver = model.solver
        states.append(np.array(solver.vector.FV().NumPy()))
        solver.assemble_jacobian()
        jacobians.append(solver.matrix.AsVector().FV().NumPy().copy())
        diagnostics.append(sol.diagnostics)
    assert [d["native_code"] for d in diagnostics] == ["off", "compiled"]
    assert diagnostics[0]["newton_iterations"] == diagnostics[1]["newton_iterations"]
    scale = np.abs(states[0]).max()
    assert np.abs(states[1] - states[0]).max() <= 1e-10 * scale
    assert np.abs(jacobians[1] - jacobians[0]).max() <= 1e-10 * np.abs(jacobians[0]).max()


def test_the_compiler_is_the_one_ngscxx_calls(tmp_path: Path) -> None:
    toolset = tmp_path / "g++"
    toolset.write_text("")
    script = (
        "if [ -f /no/such/toolset/g++ ]\n"
        "  then NGSCXX=/no/such/toolset/g++\n  else NGSCXX=c++\nfi\n"
        "if [ -f /usr/bin/ccache ]\n"
    )
    assert native._compiler_of(script) == __import__("shutil").which("c++")
    assert native._compiler_of(script.replace("/no/such/toolset/g++", str(toolset))) == str(toolset)


LINKED_CODE = b"""#include <cstddef>
extern "C" void * compiled_code_pointer%d;
extern "C" void * compiled_code_pointer%d;
extern "C" void * first() { return compiled_code_pointer%d; }
extern "C" void * second() { return compiled_code_pointer%d; }
%s
"""
POINTERS = b"""extern "C" {
[[maybe_unused]]  void * compiled_code_pointer%d = reinterpret_cast<void *>(0x%x);
[[maybe_unused]]  void * compiled_code_pointer%d = reinterpret_cast<void *>(0x%x);
}
"""


def _real_compiler(tmp_path: Path) -> dict[str, object]:
    """Settings of the cache tool with the C++ compiler behind both of NGSolve's scripts, and
    a log of every call of the compiler the tool makes itself."""
    log = tmp_path / "cxx.log"
    cxx = tmp_path / "cxx"
    cxx.write_text(f'#!/bin/sh\necho "$@" >> {log}\nexec c++ "$@"\n')
    cxx.chmod(0o755)
    ngscxx = tmp_path / "ngscxx"
    ngscxx.write_text('#!/bin/sh\nexec c++ -fPIC "$@"\n')
    ngscxx.chmod(0o755)
    cache = tmp_path / "cache"
    cache.mkdir()
    return {
        "cache": str(cache),
        "ngscxx": str(ngscxx),
        "cxx": str(cxx),
        "link_args": [],
        "key": "k",
    }


def _build(
    settings: dict[str, object],
    work: Path,
    first: int,
    addresses: tuple[int, int],
    extra: bytes = b"",
) -> tuple[int, int]:
    """What NGSolve does for one integrand in a process whose pointer counter is at ``first``:
    the two files compiled, the library linked and loaded; the addresses its code reads."""
    import ctypes

    work.mkdir()
    a, b = first, first + 1
    (work / "code_0.cpp").write_bytes(LINKED_CODE % (a, b, a, b, extra))
    (work / "code_1.cpp").write_bytes(POINTERS % (a, addresses[0], b, addresses[1]))
    for k in (0, 1):
        args = ["-c", str(work / f"code_{k}.cpp"), "-o", str(work / f"code_{k}.o")]
        assert native_cache.compile_object(settings, args) == 0
    objects = [str(work / "code_0.o"), str(work / "code_1.o")]
    library = work / "library.so"
    assert native_cache.link_library(settings, ["-shared", *objects, "-o", str(library)]) == 0
    lib = ctypes.CDLL(str(library))
    lib.first.restype = lib.second.restype = ctypes.c_void_p
    return lib.first(), lib.second()


@pytest.mark.skipif(not native_cache.PATCHABLE, reason="placeholders are patched as 8 LE bytes")
@pytest.mark.skipif(isinstance(native.toolchain(), str), reason="no C++ compiler for NGSolve")
def test_the_library_is_linked_once_and_each_process_reads_its_own_addresses(
    tmp_path: Path,
) -> None:
    settings = _real_compiler(tmp_path)
    processes = [(0, (0x1000, 0x2000)), (28, (0x7F00DEAD0000, 0x1000)), (5, (0x10, 0x10))]
    for k, (first, addresses) in enumerate(processes):
        assert _build(settings, tmp_path / f"p{k}", first, addresses) == addresses
    # one compilation of the placeholder pointers and one link, for the first process only
    calls = (tmp_path / "cxx.log").read_text().splitlines()
    assert len(calls) == 2 and "-shared" in calls[1]
    assert len(list((tmp_path / "cache").glob("*.so"))) == 1


@pytest.mark.skipif(not native_cache.PATCHABLE, reason="placeholders are patched as 8 LE bytes")
@pytest.mark.skipif(isinstance(native.toolchain(), str), reason="no C++ compiler for NGSolve")
def test_a_library_holding_a_placeholder_elsewhere_is_linked_as_ngsolve_would(
    tmp_path: Path,
) -> None:
    """The code itself holds the first placeholder's bytes: patching could hit them, so no
    library is cached and each process compiles its pointers and links."""
    clash = b'extern "C" volatile unsigned long long clash = 0x%xULL;' % native_cache.PLACEHOLDER
    settings = _real_compiler(tmp_path)
    for k, addresses in enumerate([(0x1000, 0x2000), (0x3000, 0x4000)]):
        assert _build(settings, tmp_path / f"p{k}", 3 * k, addresses, clash) == addresses
    assert not list((tmp_path / "cache").glob("*.so"))


def test_patched_replaces_each_placeholder_that_occurs_exactly_once() -> None:
    mark = [__import__("struct").pack("<Q", native_cache.PLACEHOLDER + k) for k in (0, 1)]
    library = b"head" + mark[0] + b"mid" + mark[1] + b"tail"
    got = native_cache.patched(library, [0x1234, 0x5678])
    assert (
        got
        == b"head"
        + (0x1234).to_bytes(8, "little")
        + b"mid"
        + (0x5678).to_bytes(8, "little")
        + b"tail"
    )
    assert native_cache.patched(library + mark[1], [1, 2]) is None  # twice: which one?
    assert native_cache.patched(b"head" + mark[0], [1, 2]) is None  # missing
