"""Cheap forward models with an exact, vectorised log-likelihood for ``bench_bayes_targets.py``.

::

    from bayes_models import build_case
    case = build_case("7d")                    # or "2d", "2d_inflow"
    problem = case.problem                     # a real fbia.InverseProblem (ray measure)
    L = case.log_likelihood(z)                 # (N, d) -> (N,): Paper B eq. 5, vectorised
    case.check_log_likelihood(20, seed=0)      # max |L - L via InverseProblem.evaluate|

:class:`LayeredMoundForwardModel` is a biofilm mound on the floor of a flow channel (footprint
0.8 mm, crest height h = 0.5 mm, as ``analytic_mound_2d``) made of horizontal layers, each with
its own Young's modulus E_k and Poisson's ratio nu_k: one layer (homogeneous, inputs ``E``,
``nu``) or three (Paper B Fig. 11: a stiff footing Omega_3 on the floor, the bulk Omega_2, a cap
Omega_1 on top; inputs ``E1, nu1, E2, nu2, E3, nu3``), loaded by the flow of the inflow rate q
(``inflow_rate``, mm^2/s).  Its interface is the graph of the deformed height over a fixed grid
of x, in closed form:

    sigma    = fluid_load(q)                                   [Pa] (analytic mound, 10.08 at q=100)
    gamma_k  = tanh(C_S sigma / G_k),  G_k = E_k / (2 (1 + nu_k))        shear strain of layer k
    eps_k    = EPS_MAX tanh(C_V sigma / K_k),  K_k = E_k / (3 (1 - 2 nu_k))   compression of k
    U(y)     = sum_k gamma_k len_k(y),  V(y) = sum_k eps_k len_k(y)  [mm]  (len_k(y): thickness
               of layer k below height y; U: downstream shift, V: settlement at height y)
    Y(x)     = f0(x - U(f0(x))),  y(x) = Y(x) - V(Y(x))            f0(x) = h cos(pi s / 2),
                                                                   s = (x - x0) / (w / 2)

A material point at height y moves downstream by the shear accumulated in the layers below it
and settles by their compression: the lean probes (1 + nu)/E, the flattening (1 - 2 nu)/E, so
E and nu are coupled (the E-nu band of Paper B Fig. 9) and a nu near 0.5 leaves only the lean
(sloppy nu).  The bulk Omega_2 (60 % of the height) dominates, the cap (25 %) shows only near
the crest, the stiff, thin footing (15 %) hardly at all: E2 is well identified, E1 less, E3 and
nu3 barely (Paper B: "Only for subdomain Omega_2 the posterior marginals accumulate density").
An uncertain q trades against all E_k (the response depends on q / E_k up to the saturation).

The observation is that interface at the ground truth (Paper B: E = 400 Pa, nu = 0.3; E1 = 500,
nu1 = 0.2, E2 = 200, nu2 = 0.1, E3 = 1000, nu3 = 0.3; q = 100 mm^2/s) with Gaussian noise of
sigma_n,obs = 1 um on every vertex height (Paper B eq. 16, along the measurement directions as
in Paper A), and ``n_rays`` measurement points on it with vertical search directions (the ray
measure, Paper B eq. 6).  Each ray meets the simulated graph at a grid vertex, so the residuals
are y_obs - y(x_i) and eq. 5 is a closed-form function of the inputs: :meth:`Case.
log_likelihood` evaluates it for many points at once (the exact reference), and
:meth:`Case.check_log_likelihood` confirms that it equals what the pipeline computes
(``InverseProblem.evaluate`` -> ray measure -> :func:`fbia.core.likelihood.
gaussian_log_likelihood`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numba
import numpy as np
from numpy.typing import NDArray
from pydantic import Field

import fbia
from fbia.core.likelihood import gaussian_log_likelihood, measurement_count, noise_levels
from fbia.plugins.analytic._mechanics import MAX_FLATTENING, fluid_load

FloatArray = NDArray[np.float64]

#: Gain of the shear response C_S [-]: a crest lean of ~0.08 mm at E = 400 Pa, nu = 0.3, q = 100.
SHEAR_GAIN = 2.5
#: Gain of the compression C_V [-]: a crest settlement of ~0.01 mm there (lean and settlement
#: seen about equally well, so that E and nu are correlated but both identified).
VOLUMETRIC_GAIN = 1.0
#: Layer bounds as fractions of the crest height, Omega_1 (cap), Omega_2 (bulk), Omega_3
#: (footing), and of the single layer of the homogeneous mound.
LAYERS = {3: ((0.5, 1.0), (0.15, 0.5), (0.0, 0.15)), 1: ((0.0, 1.0),)}
#: Paper B's ground truths.
TRUTH_2D = {"E": 400.0, "nu": 0.3}
TRUTH_7D = {"E1": 500.0, "nu1": 0.2, "E2": 200.0, "nu2": 0.1, "E3": 1000.0, "nu3": 0.3}
TRUE_INFLOW = 100.0  # mm^2/s
#: the shape-map cases (ShapeMapModel): a on the banana's arm, +-a the two modes
TRUTH_SHAPE = {"banana": {"a": 0.3, "b": 0.2}, "bimodal": {"a": 0.6, "b": 0.3}}
#: every case build_case knows: the layered mound in 2-D, 2 + 1-D, 6 + 1-D, and the shape maps
#: with the inflow known (2-D) or uncertain (2 + 1-D)
#: the RKHS measure's kernel width [mm] (Paper B: ~10 % of the largest displacement; the
#: mounds move by up to ~0.1 mm) and its residual, D itself (as examples/paper_b/measures)
RKHS_SIGMA_W = 0.01
#: relative step of the central differences that give the closed forms' tangents
TANGENT_STEP = 1e-5
CASE_NAMES = ("2d", "2d_inflow", "7d", "banana", "banana_inflow", "bimodal", "bimodal_inflow")


class GraphMound(fbia.ForwardModelBase):
    """What the closed-form mounds share: the grid of x, the undeformed graph f0 and the
    inputs, pairs of material inputs (``material_names``) then ``inflow_rate``."""

    dim = 2

    class Options(fbia.PluginOptions):
        n_points: int = Field(41, ge=5, description="vertices of the interface polyline [-]")
        inflow_rate: float = Field(100.0, description="q when not given [mm^2/s]")
        height: float = Field(0.5, gt=0, description="crest height h [mm]")
        width: float = Field(0.8, gt=0, description="footprint width w [mm]")
        centre: float = Field(1.0, description="footprint centre x0 [mm]")

    options: Options
    material_names: list[str]

    def __init__(self, options: fbia.PluginOptions | None = None, /, **kwargs: Any) -> None:
        super().__init__(options, **kwargs)
        o = self.options
        self.x = np.linspace(o.centre - o.width / 2, o.centre + o.width / 2, o.n_points)

    def parameter_names(self) -> Sequence[str]:
        """The material inputs, then ``inflow_rate`` [mm^2/s]."""
        return [*self.material_names, "inflow_rate"]

    def reference_height(self, x: FloatArray) -> FloatArray:
        o = self.options
        s = np.clip((x - o.centre) / (o.width / 2), -1.0, 1.0)
        return np.asarray(o.height * np.cos(0.5 * math.pi * s))

    def heights(self, first: FloatArray, second: FloatArray, q: FloatArray) -> FloatArray:
        """Deformed heights y(x_j), shape (N, n_points), from :meth:`split`'s arrays."""
        raise NotImplementedError

    def tangent_inputs(self) -> list[str]:
        """Every input has a tangent (the closed form differentiated by central differences,
        accurate to ~1e-9 of a vertex: the model's own sensitivities, as ``ale_fsi`` gives)."""
        return list(self.parameter_names())

    def interface(self, values: Mapping[str, float], tangents: Sequence[str] = ()):
        """The deformed polyline at the inputs ``values`` (all of them), with the tangents
        d vertices / d input of ``tangents`` (``Interface.tangents``)."""
        names = list(self.parameter_names())
        base = np.array([float(values[n]) for n in names])
        rows = [base]
        steps = []
        for n in tangents:
            h = TANGENT_STEP * max(1.0, abs(base[names.index(n)]))
            for sign in (1.0, -1.0):
                row = base.copy()
                row[names.index(n)] += sign * h
                rows.append(row)
            steps.append(h)
        y = self.heights(*self.split(np.array(rows), names))
        interface = fbia.Interface.polyline(np.c_[self.x, y[0]])
        for k, (n, h) in enumerate(zip(tangents, steps, strict=True)):
            dy = (y[1 + 2 * k] - y[2 + 2 * k]) / (2.0 * h)
            interface.tangents[n] = np.c_[np.zeros_like(dy), dy]
        return interface

    def split(self, values: Mapping[str, float] | FloatArray, names: Sequence[str] | None = None):
        """(first, second of each material pair, q) arrays from one input dict, or from rows
        of ``values`` named ``names``."""
        if isinstance(values, Mapping):
            row = np.array([[float(values[n]) for n in self.parameter_names()]])
        else:
            assert names is not None
            cols = [list(names).index(n) for n in self.parameter_names()]
            row = np.asarray(values, dtype=float)[:, cols]
        return row[:, 0:-1:2], row[:, 1:-1:2], row[:, -1]


class LayeredMoundForwardModel(GraphMound):
    """A layered mound whose deformed interface is a closed-form graph (module docstring)."""

    class Options(GraphMound.Options):
        subdomains: Literal[1, 3] = Field(3, description="layers: 1 (E, nu) or 3 (E1 .. nu3)")
        channel_height: float = Field(1.0, gt=0, description="channel height H [mm]")
        viscosity: float = Field(1e-3, gt=0, description="fluid viscosity [Pa s]")

    options: Options

    def __init__(self, options: fbia.PluginOptions | None = None, /, **kwargs: Any) -> None:
        super().__init__(options, **kwargs)
        o = self.options
        self.f0 = self.reference_height(self.x)
        bounds = np.array(LAYERS[o.subdomains]) * o.height
        self._lo, self._hi = bounds[:, 0], bounds[:, 1]
        self._len_f0 = self.layer_lengths(self.f0)  # (K, n_points)

    # -- inputs -------------------------------------------------------------------------------
    @property  # type: ignore[override]
    def material_names(self) -> list[str]:
        """``E, nu`` or ``E1, nu1, E2, nu2, E3, nu3`` [Pa, -]."""
        if self.options.subdomains == 1:
            return ["E", "nu"]
        return [f"{n}{k}" for k in range(1, 4) for n in ("E", "nu")]

    # -- the closed form ----------------------------------------------------------------------

    def layer_lengths(self, y: FloatArray) -> FloatArray:
        """len_k(y): thickness of layer k below height y, shape (K, *y.shape)."""
        lo = self._lo.reshape((-1,) + (1,) * np.ndim(y))
        hi = self._hi.reshape((-1,) + (1,) * np.ndim(y))
        return np.clip(np.asarray(y)[None] - lo, 0.0, hi - lo)

    def heights(self, E: FloatArray, nu: FloatArray, q: FloatArray) -> FloatArray:
        """Deformed heights y(x_j) at the grid, shape (N, n_points), for E, nu of shape (N, K)
        [Pa, -] and q of shape (N,) [mm^2/s]."""
        o = self.options
        sigma = fluid_load(1.0, 1.0, o.viscosity, o.channel_height - o.height, o.width) * q
        sigma = sigma[:, None]
        shear = np.tanh(SHEAR_GAIN * sigma * 2.0 * (1.0 + nu) / E)  # (N, K)
        compression = MAX_FLATTENING * np.tanh(VOLUMETRIC_GAIN * sigma * 3.0 * (1.0 - 2.0 * nu) / E)
        shift = shear @ self._len_f0  # U(f0(x)), (N, n_points)
        Y = self.reference_height(self.x[None, :] - shift)
        settle = np.einsum("nk,knj->nj", compression, self.layer_lengths(Y))
        return np.asarray(Y - settle)

    # -- fbia.ForwardModel ----------------------------------------------------------------
    def solve(
        self,
        parameters: Mapping[str, float],
        coordinates: Sequence[Mapping[str, float]],
        workdir: Path,
        tangents: Sequence[str] = (),
    ) -> fbia.Solution:
        """One deformed interface per coordinate (a coordinate's inflow_rate overrides), with
        the tangents of the inputs ``tangents``."""
        unknown = sorted(set(parameters) - set(self.parameter_names()))
        if unknown:
            raise fbia.ConfigError(f"unknown parameter(s) {unknown}", type(self).__name__)
        pairs = []
        for coordinate in coordinates:
            values = {"inflow_rate": self.options.inflow_rate, **parameters, **coordinate}
            missing = [n for n in self.material_names if n not in values]
            if missing:
                raise fbia.ConfigError(f"no value for {missing}", type(self).__name__)
            E, nu, q = self.split(values)
            if not (np.all(E > 0) and np.all(nu > -1.0) and np.all(nu <= 0.5)):
                raise fbia.ForwardModelError("E <= 0 or nu outside (-1, 0.5]")
            pairs.append((coordinate, self.interface(values, tangents)))
        return fbia.Solution.from_pairs(pairs)


class ShapeMapModel(GraphMound):
    """A mound whose lean and settlement follow two shape inputs ``a``, ``b`` through a map
    that bends or splits the posterior (issue 42's family: banana-shaped and bimodal cases with
    exact posteriors).  With s = q / 100 (the inflow ``inflow_rate`` scales both responses):

        banana:   U = LEAN s a,        V = SETTLE s (b + a^2)
        bimodal:  U = LEAN_2 s a^2,    V = SETTLE s b

        Y(x) = f0(x - U f0(x) / h),    y(x) = Y(x) (1 - V)          [mm]

    The lean U probes a weakly (banana: a broad marginal), the settlement V probes b + a^2
    sharply, so the posterior lies along the parabola b = c - a^2; in the bimodal case only
    a^2 is seen, so +a and -a fit equally well (two modes of equal mass)."""

    class Options(GraphMound.Options):
        shape: Literal["banana", "bimodal"] = Field("banana", description="the map [-]")

    options: Options
    #: lean per unit a (banana) and per unit a^2 (bimodal) at q = 100 [mm]; settlement per
    #: unit b [-]
    LEAN, LEAN_2, SETTLE = 0.005, 0.02, 0.05
    material_names = ["a", "b"]

    def heights(self, a: FloatArray, b: FloatArray, q: FloatArray) -> FloatArray:
        """Deformed heights y(x_j), shape (N, n_points), for a, b of shape (N, 1) and q (N,)."""
        s = (np.asarray(q, dtype=float) / 100.0)[:, None]
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        if self.options.shape == "banana":
            lean, settle = self.LEAN * s * a, self.SETTLE * s * (b + a * a)
        else:
            lean, settle = self.LEAN_2 * s * a * a, self.SETTLE * s * b
        f0 = self.reference_height(self.x)[None, :]
        Y = self.reference_height(self.x[None, :] - lean * f0 / self.options.height)
        return np.asarray(Y * (1.0 - settle))

    def solve(
        self,
        parameters: Mapping[str, float],
        coordinates: Sequence[Mapping[str, float]],
        workdir: Path,
        tangents: Sequence[str] = (),
    ) -> fbia.Solution:
        """One deformed interface per coordinate (a coordinate's inflow_rate overrides), with
        the tangents of the inputs ``tangents``."""
        pairs = []
        for coordinate in coordinates:
            values = {"inflow_rate": self.options.inflow_rate, **parameters, **coordinate}
            pairs.append((coordinate, self.interface(values, tangents)))
        return fbia.Solution.from_pairs(pairs)


# -- the benchmark cases --------------------------------------------------------------------------
@dataclass
class Case:
    """One calibration problem with its exact vectorised log-likelihood."""

    name: str
    problem: fbia.InverseProblem
    model: GraphMound
    rays: NDArray[np.intp]  # grid indices of the measurement points
    y_obs: FloatArray  # observed heights there
    truth: dict[str, float]
    #: "ray" (Paper B eq. 6, one residual per ray) or "cpp" (eq. 7, one per simulated vertex)
    measure: str = "ray"
    #: the observed polyline (the cpp measure's target), shape (n_points, 2)
    observed: FloatArray | None = None

    @property
    def inputs(self) -> list[fbia.Parameter]:
        """x, then theta (the order of gp_smc's particles)."""
        return [*self.problem.parameters, *self.problem.uncertain]

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.inputs]

    @property
    def priors(self) -> list[fbia.Prior]:
        return [p.prior for p in self.inputs if p.prior is not None]

    def log_likelihood(self, z: FloatArray, chunk: int = 20_000) -> FloatArray:
        """Paper B eq. 5 at the rows of ``z`` (names :attr:`names`), without forward runs."""
        z = np.atleast_2d(np.asarray(z, dtype=float))
        full = np.empty((len(z), len(self.model.parameter_names())))
        fixed = self.problem.fixed
        for j, n in enumerate(self.model.parameter_names()):
            full[:, j] = z[:, self.names.index(n)] if n in self.names else fixed[n]
        (sigma,) = noise_levels(self.problem)
        n_meas = len(self.rays) if self.measure == "ray" else len(self.model.x)
        const = -0.5 * n_meas * math.log(2 * math.pi * sigma**2)
        out = np.empty(len(z))
        for a in range(0, len(z), chunk):
            E, nu, q = self.model.split(full[a : a + chunk], self.model.parameter_names())
            y = self.model.heights(E, nu, q)
            if self.measure == "rkhs":
                out[a : a + chunk] = self._rkhs_log_likelihood(y, sigma)
                continue
            if self.measure == "ray":
                r = self.y_obs[None, :] - y[:, self.rays]
            else:
                r = self.cpp_residuals(y)
            out[a : a + chunk] = const - np.sum(r**2, axis=1) / (2 * sigma**2)
        return out

    def _rkhs_log_likelihood(self, y: FloatArray, sigma: float) -> FloatArray:
        """Eq. 5 with the RKHS distance (eq. 11) of each simulated graph ``y`` (N, n_points) to
        the observation, through the measure itself (one distance per row: no vectorised
        form, so only grids of 2-D cases use it)."""
        (obs,) = self.problem.observations
        measure = self.problem.measure
        n = measurement_count(self.problem) or 1
        const = -0.5 * n * math.log(2 * math.pi * sigma**2)
        d = np.array(
            [measure.distance(fbia.Interface.polyline(np.c_[self.model.x, row]), obs) for row in y]
        )
        return np.asarray(const - d**2 / (2 * sigma**2))

    def cpp_residuals(self, y: FloatArray) -> FloatArray:
        """Eq. 7 for simulated graphs ``y`` (N, n_points) over the model's grid: each vertex's
        distance to the closest point on the observed polyline (on its segments), positive
        below it (the solid side: the observed graph spans the same x, so the side is that of
        the observed height at the vertex's x)."""
        assert self.observed is not None
        return _cpp_graph(np.ascontiguousarray(y), self.model.x, self.observed)

    def check_log_likelihood(self, n: int, seed: int) -> float:
        """Largest |eq. 5 vectorised - eq. 5 through the real pipeline| at the truth and ``n``
        prior draws: InverseProblem.evaluate (forward model + ray measure) and
        fbia.core.likelihood.gaussian_log_likelihood, as gp_smc computes it."""
        rng = np.random.default_rng(seed)
        z = np.column_stack([p.rvs(n, rng) for p in self.priors])
        z = np.vstack([[self.truth[k] for k in self.names], z])
        sigmas, count = noise_levels(self.problem), measurement_count(self.problem)
        with fbia.SerialEvaluator() as ev:
            records = ev.evaluate(self.problem, [dict(zip(self.names, r, strict=True)) for r in z])
        direct = np.array([gaussian_log_likelihood(r, sigmas, count) for r in records])
        return float(np.max(np.abs(direct - self.log_likelihood(z))))


@numba.njit(cache=True)
def _segment_d2(observed: FloatArray, s: int, px: float, py: float) -> float:  # pragma: no cover
    """Squared distance of (px, py) to segment s of ``observed``."""
    ax, ay = observed[s, 0], observed[s, 1]
    bx, by = observed[s + 1, 0] - ax, observed[s + 1, 1] - ay
    qx, qy = px - ax, py - ay
    t = min(max((qx * bx + qy * by) / (bx * bx + by * by), 0.0), 1.0)
    dx, dy = qx - t * bx, qy - t * by
    return dx * dx + dy * dy


@numba.njit(cache=True, parallel=True)
def _cpp_graph(
    y: FloatArray, x: FloatArray, observed: FloatArray
) -> FloatArray:  # pragma: no cover
    """:meth:`Case.cpp_residuals` for every row of ``y``.  Exact: the observed polyline is a
    graph over the same x, so the segments are searched outwards from the vertex's own x and
    the search stops where a segment's x-distance alone exceeds the best distance so far."""
    n_rows, n = y.shape
    m = len(observed) - 1
    out = np.empty((n_rows, n))
    for r in numba.prange(n_rows):
        for j in range(n):
            best = (observed[j, 1] - y[r, j]) ** 2  # the observed vertex at the same x
            for s in range(j, m):  # segments to the right: [x_s, x_s+1], x_s >= x_j
                if (observed[s, 0] - x[j]) ** 2 > best:
                    break
                best = min(best, _segment_d2(observed, s, x[j], y[r, j]))
            for s in range(j - 1, -1, -1):  # to the left: x_s+1 <= x_j
                if (x[j] - observed[s + 1, 0]) ** 2 > best:
                    break
                best = min(best, _segment_d2(observed, s, x[j], y[r, j]))
            out[r, j] = np.sign(observed[j, 1] - y[r, j]) * math.sqrt(best)
    return out


def inflow_parameter() -> fbia.Parameter:
    """Paper B Fig. 10: the inflow rate ~ Beta(2.6, 1.4) on [0, 110] mm^2/s (mode 88)."""
    return fbia.Parameter("inflow_rate", unit="mm^2/s", prior=fbia.priors.beta(2.6, 1.4, 0, 110))


def build_case(
    name: str,
    noise_obs: float = 0.001,
    sigma_n: float = 0.01,
    n_points: int = 41,
    seed: int = 0,
    measure: str = "ray",
) -> Case:
    """``"2d"`` (E, nu at q = 100), ``"2d_inflow"`` (E, nu under the uncertain q), ``"7d"``
    (E_k, nu_k of three layers under the uncertain q), or a :class:`ShapeMapModel` case
    (``"banana"``, ``"bimodal"`` at q = 100, ``..._inflow`` under the uncertain q; uniform
    priors on [-1, 1]): the model, synthetic data with
    ``noise_obs`` [mm] (Paper B eq. 16: 1 um), the ray measure at every other interior vertex,
    sigma_N = ``sigma_n`` [mm] (eq. 5; Paper B uses 0.01 mm with the ray measure), and the
    priors of Paper B (uniform E [100, 800] Pa in 2-D, [100, 1500] Pa per layer in 7-D;
    uniform nu [-0.8, 0.5]; the Beta inflow of Fig. 10).  ``measure="cpp"``: the cpp measure
    (eq. 7, one residual per simulated vertex) against the observed polyline instead of rays
    (issue 30's 6 + 1-D case: cpp with sigma_N = 2 um); ``measure="rkhs"``: the RKHS distance
    of surface currents (eq. 11, sigma_W = :data:`RKHS_SIGMA_W`) as the one residual, whose
    likelihood has no vectorised form (grids of the 2-D cases only)."""
    if name not in CASE_NAMES:
        raise ValueError(f"unknown case {name!r}; valid: {', '.join(CASE_NAMES)}")
    if measure not in ("ray", "cpp", "rkhs"):
        raise ValueError(f"unknown measure {measure!r}; valid: ray, cpp, rkhs")
    layered = name == "7d"
    shape = name.removesuffix("_inflow")
    model: GraphMound
    parameters = []
    if shape in ("banana", "bimodal"):
        model = ShapeMapModel(shape=shape, n_points=n_points)
        truth = dict(TRUTH_SHAPE[shape])
        for n in model.material_names:
            parameters.append(fbia.Parameter(n, bounds=(-1.0, 1.0), unit="-"))
    else:
        model = LayeredMoundForwardModel(subdomains=3 if layered else 1, n_points=n_points)
        truth = dict(TRUTH_7D if layered else TRUTH_2D)
        e_max = 1500.0 if layered else 800.0
        for n in model.material_names:
            lo, hi = (100.0, e_max) if n.startswith("E") else (-0.8, 0.5)
            parameters.append(
                fbia.Parameter(n, bounds=(lo, hi), unit="Pa" if n.startswith("E") else "-")
            )
    E, nu, q = model.split({**truth, "inflow_rate": TRUE_INFLOW})
    y_true = model.heights(E, nu, q)[0]
    rng = np.random.default_rng(seed)
    y_data = y_true + noise_obs * rng.standard_normal(len(y_true))
    y_data[[0, -1]] = 0.0  # the bonded feet
    rays = np.arange(1, n_points - 1, 2)
    points = np.c_[model.x[rays], y_data[rays]]
    observed = np.c_[model.x, y_data]
    obs = fbia.Observation(
        interface=fbia.Interface.polyline(observed),
        points=points,
        directions=np.tile([0.0, 1.0], (len(rays), 1)),
        name=f"{name} at q = {TRUE_INFLOW:g} mm^2/s",
    )
    extra: dict[str, Any]
    if name in ("2d", "banana", "bimodal"):
        extra = {"fixed": {"inflow_rate": TRUE_INFLOW}}
    else:
        extra = {"uncertain": [inflow_parameter()]}
        truth["inflow_rate"] = TRUE_INFLOW
    problem = fbia.InverseProblem(
        model=model,
        measure=(
            fbia.measure(measure)
            if measure != "rkhs"
            else fbia.measure("rkhs", sigma_w=RKHS_SIGMA_W, residuals="distance")
        ),
        observations=[obs],
        parameters=parameters,
        noise_std=sigma_n,
        **extra,
    )
    return Case(name, problem, model, rays, y_data[rays], truth, measure, observed)


# -- brute-force posteriors -----------------------------------------------------------------------
@dataclass
class Moments:
    """Posterior mean and standard deviation of every input (x, then theta)."""

    names: list[str]
    mean: FloatArray
    std: FloatArray


def grid_posterior(case: Case, n: int, n_theta: int | None = None) -> Moments:
    """Mean and std of the posterior by quadrature: the midpoint rule on an ``n`` per input
    (``n_theta`` for theta) grid over the prior supports, weights exp(L) times the prior
    density.  For the 2-D cases (two or three inputs) only."""
    n_x = len(case.problem.parameters)
    axes = []
    for j, p in enumerate(case.priors):
        lo, hi = p.support
        k = n if j < n_x or n_theta is None else n_theta
        axes.append(lo + (np.arange(k) + 0.5) * (hi - lo) / k)
    mesh = np.meshgrid(*axes, indexing="ij")
    z = np.column_stack([m.ravel() for m in mesh])
    log_w = case.log_likelihood(z)
    for j, p in enumerate(case.priors):
        log_w += p.logpdf(z[:, j])
    w = np.exp(log_w - log_w.max())
    w /= w.sum()
    mean = w @ z
    std = np.sqrt(w @ (z - mean) ** 2)
    return Moments(case.names, mean, std)
