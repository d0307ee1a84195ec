"""Accuracy and speed of the ale_fsi forward model (run by hand: it takes several minutes).

    python benchmarks/bench_ale_fsi.py                    # all sections
    python benchmarks/bench_ale_fsi.py convergence speed  # some of them
    python benchmarks/bench_ale_fsi.py --quick            # smaller meshes, fewer runs

Sections
--------
convergence  mesh convergence of the default flow cell (E = 400 Pa, nu = 0.3, 100 mm^2/s):
             max interface displacement and the displacement at two outline points, the
             observed order of the interface position under h -> h/2, and for each mesh the
             deviation from the mesh with about 4x the dofs (criterion: within 0.3 %).
speed        cold run (fresh model: meshing + set-up, then the solve) and warm run (a
             finite-difference neighbour E (1 + 1e-5), warm-started) on the default mesh:
             wall and CPU time, dofs, Newton iterations, assembly vs solve time, peak memory.
transient    Paper A's transient protocol (ramp over 10 s, state at 15 s) against the
             quasi-static state.
sweep        20 runs over E in [100, 800] Pa, nu in [-0.8, 0.5] (scrambled Halton, seed 0)
             on one warm-starting model, with the failures counted by reason.
table1       the LM starts of Paper A Table 1 (SVK and neo-Hooke, 100 mm^2/s) on the coarse
             test mesh and on the default mesh: solved or why not, and the cost.
stability    why the "blue" start (E = 200 Pa, nu = 0.4) fails with SVK on the default mesh:
             along the branch of steady states the smallest det F of the solid and of the ALE
             map and the smallest eigenvalue of the solid's tangent stiffness relative to the
             linear one (K(d) v = lambda K(0) v, SVK energy, dead load); the same for neo-Hooke;
             the rate at which SVK fails on meshes of different interface size.
turek_hron   CSM1, CFD1, FSI1 (Turek & Hron 2006) through the user-mesh path on a fine mesh,
             errors against the reference values.

The machine is shared: CPU times are printed next to wall times.
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fbia import ForwardModelError
from fbia.plugins.ale_fsi import AleFsiForwardModel, turek_hron

PROBES = [(1.22, 0.30), (0.94, 0.48)]  # outline points: downstream overhang, top
X_GT = {"E": 400.0, "nu": 0.3}
RATE = [{"inflow_rate": 100.0}]
DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "fsi" / "turek_hron_2006.json"


def peak_memory_mb() -> float:
    """Peak resident memory of this process (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def run(model: AleFsiForwardModel, params: dict, coords: list, workdir: Path) -> dict:
    t0, c0 = time.perf_counter(), time.process_time()
    sol = model.solve(params, coords, workdir)
    d = dict(sol.diagnostics)
    d["wall"] = time.perf_counter() - t0
    d["cpu"] = time.process_time() - c0
    d["solution"] = sol
    return d


def convergence(workdir: Path, quick: bool) -> None:
    print("\n== mesh convergence: default flow cell, E = 400 Pa, nu = 0.3, 100 mm^2/s ==")
    sizes = [0.08, 0.04, 0.02] if quick else [0.06, 0.04, 0.03, 0.02, 0.015, 0.01, 0.0075]
    rows = []
    print(
        f"{'h_iface':>8} {'h_max':>6} {'dofs':>7} {'max|d| mm':>11} {'d(P1) mm':>22} "
        f"{'d(P2) mm':>22} {'newton':>6} {'cpu s':>6}"
    )
    for h in sizes:
        m = AleFsiForwardModel(
            interface_mesh_size=h, mesh_size=4 * h, probes=PROBES, warm_start=False
        )
        d = run(m, X_GT, RATE, workdir)
        p = np.array(d["probe_displacements"][0])
        rows.append((h, d["ndof"], d["max_displacement"][0], p))
        print(
            f"{h:8.4f} {4 * h:6.3f} {d['ndof']:7d} {d['max_displacement'][0]:11.7f} "
            f"{str(p[0].round(7)):>22} {str(p[1].round(7)):>22} {d['newton_iterations']:6d} "
            f"{d['cpu']:6.2f}"
        )
    print("\nobserved order of the interface position (h -> h/2 -> h/4):")
    by_h = {r[0]: r for r in rows}
    for h in sizes:
        if h / 2 in by_h and h / 4 in by_h:
            a, b, c = by_h[h], by_h[h / 2], by_h[h / 4]
            for label, q in (("max|d|", lambda r: np.array([r[2]])), ("d(P1,P2)", lambda r: r[3])):
                e1 = np.linalg.norm(q(a) - q(b))
                e2 = np.linalg.norm(q(b) - q(c))
                print(
                    f"  h = {h:.3f}: {label:9s} |q_h - q_h/2| = {e1:.3e}, "
                    f"|q_h/2 - q_h/4| = {e2:.3e}, order {math.log2(e1 / e2):.2f}"
                )
    print("\ndeviation from the mesh with ~4x the dofs (criterion 0.3 % of max|d|):")
    for _h, n, dmax, _ in rows:
        finer = [r for r in rows if r[1] > 2.5 * n]
        if not finer:
            continue
        f = min(finer, key=lambda r: abs(r[1] / n - 4.0))
        dev = abs(dmax - f[2]) / f[2]
        ok = "ok" if dev <= 3e-3 else "--"
        print(f"  {n:7d} dofs vs {f[1]:7d} ({f[1] / n:.1f}x): {100 * dev:.3f} % {ok}")


def speed(workdir: Path, quick: bool) -> None:
    print("\n== speed on the default mesh (E = 400 Pa, nu = 0.3, 100 mm^2/s) ==")
    reps = 2 if quick else 3
    for threads in (1, 2):
        for k in range(reps):
            t0, c0 = time.perf_counter(), time.process_time()
            model = AleFsiForwardModel(threads=threads)
            model.solver  # meshing + spaces + forms  # noqa: B018
            setup_wall, setup_cpu = time.perf_counter() - t0, time.process_time() - c0
            cold = run(model, X_GT, RATE, workdir)
            warm = run(model, {"E": 400.0 * (1 + 1e-5), "nu": 0.3}, RATE, workdir)
            for label, d in (("cold", cold), ("warm", warm)):
                print(
                    f"  threads {threads} rep {k} {label}: wall {d['wall']:.3f} s, "
                    f"cpu {d['cpu']:.3f} s, dofs {d['ndof']}, newton {d['newton_iterations']} "
                    f"({d['jacobians']} Jacobians), assembly {d['assembly_time']:.3f} s, "
                    f"solve {d['solve_time']:.3f} s (wall)"
                )
            print(
                f"  threads {threads} rep {k} meshing + set-up: wall {setup_wall:.3f} s, "
                f"cpu {setup_cpu:.3f} s"
            )
    print(f"  peak memory (resident, whole process): {peak_memory_mb():.0f} MB")


def sweep(workdir: Path, quick: bool) -> None:
    from scipy.stats import qmc

    n = 8 if quick else 20
    print(f"\n== sweep: {n} runs, E in [100, 800] Pa, nu in [-0.8, 0.5], 100 mm^2/s ==")
    pts = qmc.scale(qmc.Halton(2, scramble=True, seed=0).random(n), [100.0, -0.8], [800.0, 0.5])
    model = AleFsiForwardModel()
    failures: dict[str, int] = {}
    times = []
    for E, nu in pts:
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            d = run(model, {"E": float(E), "nu": float(nu)}, RATE, workdir)
            status = (
                f"ok   max|d| {d['max_displacement'][0]:.4f} mm, newton {d['newton_iterations']}"
            )
        except ForwardModelError as exc:
            failures[exc.reason] = failures.get(exc.reason, 0) + 1
            status = f"FAIL ({exc.reason}) {str(exc)[:90]}"
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        times.append((wall, cpu))
        print(f"  E = {E:6.1f} Pa, nu = {nu:+.3f}: wall {wall:5.2f} s, cpu {cpu:5.2f} s  {status}")
    w, c = np.array(times).T
    print(
        f"  failures: {sum(failures.values())} of {n} {failures}; total wall {w.sum():.1f} s, "
        f"cpu {c.sum():.1f} s, median wall per run {np.median(w):.2f} s"
    )


#: Paper A, Table 1: initial guesses (E [Pa], nu) of the LM runs of the homogeneous example
TABLE_1 = {
    "blue": (200.0, 0.4),
    "orange": (200.0, 0.0),
    "green": (400.0, 0.45),
    "red": (400.0, 0.0),
    "purple": (600.0, 0.4),
    "brown": (600.0, 0.0),
    "pink": (400.0, -0.3),
    "gray": (400.0, -0.6),
    "olive": (400.0, -0.9),
    "cyan": (1000.0, 0.0),
    "black": (1000.0, 0.4),
}
COARSE = {"mesh_size": 0.2, "interface_mesh_size": 0.06}


def table1(workdir: Path, quick: bool) -> None:
    print("\n== Paper A Table 1 starts at 100 mm^2/s (fresh model per mesh, no warm start) ==")
    meshes = {"coarse (test)": COARSE} if quick else {"coarse (test)": COARSE, "default": {}}
    for material in ("svk", "neo_hooke"):
        for label, opts in meshes.items():
            model = AleFsiForwardModel(material=material, warm_start=False, **opts)
            model.solver  # noqa: B018
            for name, (E, nu) in TABLE_1.items():
                t0, c0 = time.perf_counter(), time.process_time()
                try:
                    d = run(model, {"E": E, "nu": nu}, RATE, workdir)
                    status = (
                        f"ok   max|d| {d['max_displacement'][0]:.5f} mm, min det F solid "
                        f"{d['min_det_f_solid']:.3f} / fluid {d['min_det_f_fluid']:.3f}, "
                        f"{d['jacobians']} Jacobians"
                    )
                except ForwardModelError as exc:
                    status = f"FAIL ({exc.reason}) {exc}"
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                print(
                    f"  {material:9s} {label:13s} {name:6s} E {E:6.0f} nu {nu:+.2f}: "
                    f"wall {wall:5.2f} s, cpu {cpu:5.2f} s  {status}"
                )


def _solid_stiffness_ratio(solver: object, material: str, E: float, nu: float) -> float:
    """Smallest lambda of K(d) v = lambda K(0) v for the solid alone (dead load, clamped base)."""
    import ngsolve as ngs
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla

    mesh = solver.mesh
    W = ngs.VectorH1(mesh, order=2, definedon="solid", dirichlet="solid_fixed")
    u = W.TrialFunction()
    mu, lam = E / (2 * (1 + nu)), nu * E / ((1 + nu) * (1 - 2 * nu))
    F = ngs.Id(2) + ngs.Grad(u)
    C = F.trans * F
    if material == "svk":
        G = 0.5 * (C - ngs.Id(2))
        energy = mu * ngs.InnerProduct(G, G) + 0.5 * lam * ngs.Trace(G) ** 2
    else:
        J = ngs.Det(F)
        energy = 0.5 * mu * (ngs.Trace(C) - 2) - mu * ngs.log(J) + 0.5 * lam * ngs.log(J) ** 2
    form = ngs.BilinearForm(W)
    form += ngs.Variation(energy * ngs.dx("solid", bonus_intorder=2))
    free = np.flatnonzero(np.array(W.FreeDofs()))

    def stiffness(gf: object) -> object:
        form.AssembleLinearization(gf.vec)
        v, c, r = form.mat.CSR()
        K = sp.csr_matrix((np.array(v), np.array(c), np.array(r)), shape=(W.ndof, W.ndof))
        return K[free][:, free]

    d = ngs.GridFunction(W)
    K0 = stiffness(d)
    d.Set(solver.displacement, definedon=mesh.Materials("solid"))
    vals = sla.eigsh(stiffness(d), k=1, M=K0, sigma=-0.5, which="LM", return_eigenvectors=False)
    return float(vals.min())


def stability(workdir: Path, quick: bool) -> None:
    import ngsolve as ngs

    E, nu = TABLE_1["blue"]
    print(f"\n== stability of the steady states, blue start E = {E:g} Pa, nu = {nu:g} ==")
    rates = [50.0, 80.0, 90.0, 95.0, 97.0, 97.5, 97.7, 98.0, 99.0, 100.0]
    for material in ("svk", "neo_hooke"):
        model = AleFsiForwardModel(material=material)  # warm starts: natural continuation
        solver = model.solver
        pts = solver._det_points
        xy = np.c_[np.asarray(ngs.x(pts)).ravel(), np.asarray(ngs.y(pts)).ravel()]
        fluid = solver._region_of_point
        for r in rates if not quick else rates[::3]:
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                d = run(model, {"E": E, "nu": nu}, [{"inflow_rate": r}], workdir)
            except ForwardModelError as exc:
                print(
                    f"  {material:9s} {r:6.1f} mm^2/s: FAIL ({exc.reason}) after wall "
                    f"{time.perf_counter() - t0:.2f} s, cpu {time.process_time() - c0:.2f} s: {exc}"
                )
                break
            det = np.asarray(ngs.Det(ngs.Id(2) + ngs.Grad(solver.displacement))(pts))[:, 0]
            ks = np.flatnonzero(~fluid)[np.argmin(det[~fluid])]
            kf = np.flatnonzero(fluid)[np.argmin(det[fluid])]
            ratio = _solid_stiffness_ratio(solver, material, E, nu)
            print(
                f"  {material:9s} {r:6.1f} mm^2/s: max|d| {d['max_displacement'][0]:.5f} mm, "
                f"min det F solid {det[ks]:.3f} at {xy[ks].round(3)}, fluid {det[kf]:.3f} at "
                f"{xy[kf].round(3)}; min eig K(d)/K(0) {ratio:.4f}"
            )
    print("  rate at which SVK fails (fresh model, 100 mm^2/s requested) vs interface size:")
    for h in (0.06, 0.045, 0.03, 0.02) if not quick else (0.06, 0.03):
        model = AleFsiForwardModel(interface_mesh_size=h, mesh_size=4 * h, warm_start=False)
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            d = run(model, {"E": E, "nu": nu}, RATE, workdir)
            status = f"solves, max|d| {d['max_displacement'][0]:.5f} mm"
        except ForwardModelError as exc:
            status = f"FAIL ({exc.reason}) {exc}"
        print(
            f"    h {h:.3f} mm ({model.solver.ndof} dofs): wall {time.perf_counter() - t0:.2f} s,"
            f" cpu {time.process_time() - c0:.2f} s: {status}"
        )


def transient(workdir: Path, quick: bool) -> None:
    print("\n== transient (Paper A): cosine ramp over 10 s, read at 15 s, one-step-theta ==")
    static = run(AleFsiForwardModel(warm_start=False), X_GT, RATE, workdir)
    ref = static["solution"].interface(RATE[0]).vertices
    for theta, dt in ((1.0, 0.5), (1.0, 0.25)) if not quick else ((1.0, 0.5),):
        model = AleFsiForwardModel(mode="transient", theta=theta, time_step=dt, ramp_time=10.0)
        coords = [{"time": 5.0}, {"time": 10.0}, {"time": 15.0}]
        d = run(model, X_GT, coords, workdir)
        dev = np.abs(d["solution"].interface({"time": 15.0}).vertices - ref).max()
        print(
            f"  theta {theta}, dt {dt} s: max|d| at t = 5, 10, 15 s: "
            f"{', '.join(f'{x:.5f}' for x in d['max_displacement'])} mm (quasi-static "
            f"{static['max_displacement'][0]:.5f}); |interface(15 s) - quasi-static| = "
            f"{dev:.2e} mm; newton {d['newton_iterations']}, wall {d['wall']:.1f} s, "
            f"cpu {d['cpu']:.1f} s"
        )


def turek_hron_fine(workdir: Path, quick: bool) -> None:
    ref = json.loads(DATA.read_text())["cases"]
    sizes = (60.0, 10.0, 20.0) if quick else (30.0, 5.0, 3.0)
    print(
        f"\n== Turek-Hron through the user-mesh path: channel h {sizes[0]} mm, bar h "
        f"{sizes[1]} mm, cylinder h {sizes[2]} mm =="
    )
    path = turek_hron.write_benchmark_mesh(
        workdir / "turek_hron.msh",
        mesh_size=sizes[0],
        bar_mesh_size=sizes[1],
        cylinder_mesh_size=sizes[2],
    )
    for case in ("CSM1", "CFD1", "FSI1"):
        t0, c0 = time.perf_counter(), time.process_time()
        q = turek_hron.quantities(turek_hron.model(case, path), case, workdir)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        errs = ", ".join(
            f"{k} {q[k]:.5g} (ref {v:.5g}, {100 * (q[k] - v) / abs(v):+.2f} %)"
            for k, v in ref[case]["reference"].items()
        )
        print(
            f"  {case}: {errs}; dofs {q['ndof']}, newton {q['newton_iterations']}, "
            f"wall {wall:.1f} s, cpu {cpu:.1f} s"
        )


SECTIONS = {
    "convergence": convergence,
    "speed": speed,
    "sweep": sweep,
    "table1": table1,
    "stability": stability,
    "transient": transient,
    "turek_hron": turek_hron_fine,
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sections", nargs="*", help=f"any of {', '.join(SECTIONS)} (default: all)")
    parser.add_argument("--quick", action="store_true", help="smaller meshes, fewer runs")
    args = parser.parse_args(argv)
    unknown = [s for s in args.sections if s not in SECTIONS]
    if unknown:
        parser.error(f"unknown section(s) {unknown}; valid: {', '.join(SECTIONS)}")
    import ngsolve

    print(f"ngsolve {ngsolve.__version__}, python {sys.version.split()[0]}")
    with tempfile.TemporaryDirectory(prefix="bench_ale_fsi_") as tmp:
        for name in args.sections or SECTIONS:
            SECTIONS[name](Path(tmp), args.quick)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
