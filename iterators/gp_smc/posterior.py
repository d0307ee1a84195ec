"""Posterior statistics of weighted particles, and the posterior files other tools read.

* :func:`summarise`: the :class:`~fbia.iterators.gp_smc.result.ParticlePosterior` of an SMC
  run: mean and covariance (the global Gaussian approximation), credible intervals, the MAP
  (the best particle, or with uncertain inputs the heaviest histogram bin of the x-marginal,
  Paper B Remark 8, with its support over resamplings of the particles:
  :func:`map_by_binning`) and the Laplace approximation at the MAP;
* :func:`hpd_mass`: the posterior mass of the highest-density region through a point;
* :func:`save_posterior` / :func:`load_posterior`: ``posterior.npz`` + ``posterior.json``
  (format ``fbia-posterior-1``), and :func:`to_inference_data` for arviz.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...core.data_files import regular_file_bytes
from ...core.errors import ConfigError
from ...core.parameters import Parameter, Prior
from ...core.problem import jsonable
from ..smc.sampler import SmcResult
from .inference_data import inference_data
from .result import (
    MAP_RESAMPLINGS,
    FloatArray,
    GpSmcResult,
    LaplaceApproximation,
    ParticlePosterior,
    check_particles,
)

__all__ = [
    "MAX_POSTERIOR_BYTES",
    "POSTERIOR_FORMAT",
    "HistogramMap",
    "hpd_mass",
    "laplace_approximation",
    "load_posterior",
    "map_by_binning",
    "save_posterior",
    "summarise",
    "to_inference_data",
    "write_posterior_files",
]

#: Version tag of the posterior files written by :func:`save_posterior`.
POSTERIOR_FORMAT = "fbia-posterior-1"


# -- statistics ------------------------------------------------------------------------------------
def summarise(
    post: SmcResult,
    n_x: int,
    inputs: Sequence[Parameter],
    map_bins: int,
    log_posterior: Callable[[FloatArray], FloatArray] | None,
    seed: int = 0,
) -> ParticlePosterior:
    """The posterior of an SMC run; ``log_posterior`` (L + log p, vectorised) gives the
    Laplace approximation at the MAP when there are no uncertain inputs (None: no Laplace);
    ``seed`` seeds the resamplings that measure the histogram MAP's support."""
    x = post.particles[:, :n_x]
    w = post.weights
    mean = w @ x
    dx = x - mean
    cov = (dx * w[:, None]).T @ dx
    has_theta = post.particles.shape[1] > n_x
    laplace = None
    support = None
    if has_theta:
        binned = map_by_binning(x, w, inputs[:n_x], map_bins, seed)
        x_map, support = binned.x, binned.support
        method = (
            f"histogram, {map_bins} bins per parameter (Remark 8); the whole cell kept in "
            f"{binned.cell_support * 100:.0f} % of {MAP_RESAMPLINGS} resamplings of the particles"
        )
    else:
        x_map = post.map[:n_x]
        method = "particle of highest posterior in the last SMC step"
        if log_posterior is not None:
            laplace = laplace_approximation(log_posterior, x_map, cov)
    return ParticlePosterior(
        names=list(post.names),
        n_x=n_x,
        particles=post.particles,
        weights=w,
        log_likelihood=post.log_likelihood,
        log_prior=post.log_prior,
        log_evidence=float(post.log_evidence),
        log_evidence_se=float(post.log_evidence_se),
        mean=mean,
        cov=cov,
        mean_all=post.mean,
        cov_all=post.cov,
        max_likelihood=post.max_likelihood,
        credible_intervals={
            name: weighted_quantiles(post.particles[:, j], w, [0.025, 0.5, 0.975])
            for j, name in enumerate(post.names)
        },
        map=np.asarray(x_map),
        map_method=method,
        best_particle=post.map if has_theta else None,
        laplace=laplace,
        map_support=support,
    )


def weighted_quantiles(values: FloatArray, weights: FloatArray, q: Sequence[float]) -> list[float]:
    order = np.argsort(values)
    cdf = np.cumsum(weights[order])
    cdf /= cdf[-1]
    return [float(values[order][min(int(np.searchsorted(cdf, qi)), len(cdf) - 1)]) for qi in q]


@dataclass(frozen=True)
class HistogramMap:
    """The histogram MAP of :func:`map_by_binning`."""

    x: FloatArray  # the centre of the heaviest cell
    #: per parameter: the share of resamplings of the particles whose heaviest cell lies in
    #: the same interval of that parameter (1: the particles decide it; near 1/bins: noise)
    support: FloatArray
    cell_support: float  # the share whose heaviest cell is the same cell


def map_by_binning(
    x: FloatArray,
    weights: FloatArray,
    parameters: Sequence[Parameter],
    bins: int,
    seed: int = 0,
    resamplings: int = MAP_RESAMPLINGS,
) -> HistogramMap:
    """MAP of the theta-marginal: centre of the heaviest of ``bins`` intervals per parameter
    (Paper B Remark 8). The box is the parameters' bounds, else the particles' range; only
    occupied bins are counted, so any dimension works.

    Its support: the particles are a Monte Carlo sample, and where the posterior is flat at
    the bins' resolution the heaviest cell is decided by which cell drew a few particles
    more (example 8: 10^6 cells, the heaviest holds 18 of 10 000 particles, the next ones
    15-17). ``resamplings`` bootstrap resamplings of the particles with their weights
    (uniform draws with replacement, seeded by ``seed``) give the share in which each
    parameter's interval of the heaviest cell stays the same; it measures the particles'
    noise only, not the surrogate's."""
    lo = np.array(
        [p.lower if math.isfinite(p.lower) else x[:, j].min() for j, p in enumerate(parameters)]
    )
    hi = np.array(
        [p.upper if math.isfinite(p.upper) else x[:, j].max() for j, p in enumerate(parameters)]
    )
    width = np.where(hi > lo, (hi - lo) / bins, 1.0)
    idx = np.clip(np.floor((x - lo) / width).astype(np.int64), 0, bins - 1)
    cells, inverse = np.unique(idx, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    top = cells[int(np.argmax(np.bincount(inverse, weights=weights, minlength=len(cells))))]
    rng = np.random.default_rng(seed)
    kept = np.zeros(len(top))
    whole = 0
    for _ in range(resamplings):
        i = rng.integers(0, len(weights), len(weights))
        drawn = cells[int(np.argmax(np.bincount(inverse[i], weights[i], len(cells))))]
        kept += drawn == top
        whole += bool(np.all(drawn == top))
    return HistogramMap(
        x=np.asarray(lo + (top + 0.5) * width),
        support=kept / resamplings,
        cell_support=whole / resamplings,
    )


def laplace_approximation(
    log_posterior: Callable[[FloatArray], FloatArray], x_map: FloatArray, scale: FloatArray
) -> LaplaceApproximation:
    """Gaussian N(x_MAP, (-H)^-1) from a central finite-difference Hessian H of the
    log-posterior at the MAP (Paper B, Fig. 9a/c), steps 1e-3 of the posterior std."""
    d = len(x_map)
    h = 1e-3 * np.sqrt(np.maximum(np.diag(np.atleast_2d(scale)), 1e-300))
    pts = [x_map]
    for i in range(d):
        for j in range(d):
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                z = x_map.copy()
                z[i] += si * h[i]
                z[j] += sj * h[j]
                pts.append(z)
    vals = log_posterior(np.array(pts))
    hess = np.empty((d, d))
    k = 1
    for i in range(d):
        for j in range(d):
            fpp, fpm, fmp, fmm = vals[k : k + 4]
            hess[i, j] = (fpp - fpm - fmp + fmm) / (4 * h[i] * h[j])
            k += 4
    hess = 0.5 * (hess + hess.T)
    eig = np.linalg.eigvalsh(-hess)
    ok = bool(np.all(eig > 0) and np.all(np.isfinite(vals)))
    return LaplaceApproximation(
        mean=x_map,
        hessian=hess,
        cov=np.asarray(np.linalg.inv(-hess), dtype=float) if ok else None,
        negative_definite=ok,
    )


def hpd_mass(result: GpSmcResult, point: Mapping[str, float]) -> float:
    """Posterior mass of the highest-posterior-density region whose boundary passes through
    ``point`` (0: the point is the mode; near 1: it lies outside the bulk of the posterior).

    The log-posterior at ``point`` comes from the GP surrogate and the priors; the region's
    mass from the weighted particles. Defined for results without uncertain parameters.
    """
    post, fit = result.posterior, result.surrogate
    if post is None or fit is None or len(result.names) != result.n_x:
        raise ConfigError(
            "hpd_mass needs a surrogate-mode result without uncertain parameters", "hpd_mass"
        )
    missing = [n for n in result.names if n not in point]
    if missing:
        raise ConfigError(f"no value for {', '.join(missing)}", "hpd_mass")
    z = np.array([[float(point[n]) for n in result.names]])
    gp = fit.surrogate()
    log_prior = sum(
        float(Prior.from_spec(p["prior"]).logpdf(z[0, j])) for j, p in enumerate(result.priors)
    )
    level = float(gp.predict_mean(z)[0] + gp.log_feasibility(z)[0]) + log_prior
    return float(np.sum(post.weights[post.log_posterior > level]))


# -- files that other tools read ------------------------------------------------------------------
def save_posterior(result: GpSmcResult, folder: str | Path) -> tuple[Path, Path]:
    """Write ``posterior.npz`` (arrays) and ``posterior.json`` (description) into ``folder``.

    posterior.npz (format ``fbia-posterior-1``):

    ``names`` (d,) str: x names then theta names; ``n_x``: number of calibration parameters;
    ``particles`` (N, d) float; ``weights`` (N,) normalised; ``log_likelihood`` (N,) the
    (surrogate) L of eq. 5; ``log_prior`` (N,); ``log_posterior`` (N,) = L + log p
    (unnormalised); ``theta`` (N, d - n_x) the uncertain parameters; ``design`` (n, d) the
    Sobol design; ``design_log_likelihood`` (n,) L of each run (-inf: failed);
    ``design_ok`` (n,) bool; ``train_mask`` (n,) bool (False: held-out test point).

    posterior.json: format, names, units, priors, point estimates, log-evidence, GP
    hyperparameters and errors, SMC history. :func:`load_posterior` reads both back;
    :func:`to_inference_data` turns them into an ``arviz.InferenceData`` if arviz is installed.
    """
    post = result.posterior
    if post is None:
        raise ConfigError(f"the result has no posterior ({result.status})", "save_posterior")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {
        "format": np.array(POSTERIOR_FORMAT),
        "names": np.array(post.names),
        "n_x": np.array(post.n_x),
        "particles": post.particles,
        "weights": post.weights,
        "log_likelihood": post.log_likelihood,
        "log_prior": post.log_prior,
        "log_posterior": post.log_posterior,
        "theta": post.particles[:, post.n_x :],
    }
    if result.design is not None:
        arrays.update(
            design=result.design.points,
            design_log_likelihood=result.design.log_likelihood,
            design_ok=result.design.ok,
            train_mask=result.design.train_mask,
        )
    npz = folder / "posterior.npz"
    np.savez_compressed(npz, **arrays)
    arrays_elsewhere = ("particles", "weights", "log_likelihood", "log_prior")
    estimates = {k: v for k, v in asdict(post).items() if k not in arrays_elsewhere}
    meta = {
        "format": POSTERIOR_FORMAT,
        "arrays": "posterior.npz",
        "status": result.status,
        "message": result.message,
        "x_map": result.x,
        "mode": result.mode,
        "priors": result.priors,
        **estimates,
        "gp": None if result.surrogate is None else result.surrogate.summary,
        "posterior_check": None if result.check is None else asdict(result.check),
        "smc": None if result.smc is None else asdict(result.smc),
        "seconds": result.seconds,
    }
    js = folder / "posterior.json"
    js.write_text(json.dumps(jsonable(meta), indent=1, default=str))
    return npz, js


#: the largest posterior file read, and the most its arrays may unpack to
MAX_POSTERIOR_BYTES = 2 << 30
#: the arrays of posterior.npz: always, and those of a design (all four or none)
_PER_PARTICLE = ("log_likelihood", "log_prior", "log_posterior")
_ARRAYS = ("format", "names", "n_x", "particles", "weights", *_PER_PARTICLE, "theta")
_DESIGN = ("design", "design_log_likelihood", "design_ok", "train_mask")
#: the dtype kinds of the arrays (numpy's ``dtype.kind``; the rest are numbers, "iuf")
_KINDS = {"format": "U", "names": "U", "n_x": "iu", "design_ok": "b", "train_mask": "b"}
_KIND_NAMES = {"U": "text", "iu": "an integer", "b": "true/false", "iuf": "numbers"}


def load_posterior(folder: str | Path) -> dict[str, Any]:
    """Read :func:`save_posterior`'s files: the npz arrays plus ``"meta"`` (the JSON).

    A strict reader (as :func:`fbia.load_result`): regular files (a FIFO or a device is never
    read) of at most :data:`MAX_POSTERIOR_BYTES`, the npz without pickled objects and with
    exactly the arrays :func:`save_posterior` writes, their shapes consistent (a column of
    ``particles`` per name, a weight per particle, the weights summing to 1), the JSON of
    the same format, names and ``n_x``; any problem is one ConfigError naming the file and
    the array or key."""
    folder = Path(folder)
    npz, js = folder / "posterior.npz", folder / "posterior.json"
    out = _read_npz(npz)
    where = str(npz)
    try:
        if "format" in out and str(out["format"]) != POSTERIOR_FORMAT:
            raise ValueError(f"format is {str(out['format'])!r}, not {POSTERIOR_FORMAT!r}")
        _check_arrays(out)
    except ValueError as exc:
        raise ConfigError(str(exc), where) from None
    out["names"] = [str(n) for n in out["names"]]
    meta = _read_meta(js)
    same = {"format": POSTERIOR_FORMAT, "names": out["names"], "n_x": int(out["n_x"])}
    for key, value in same.items():
        if meta.get(key) != value or isinstance(meta.get(key), bool):
            raise ConfigError(f"{key} is {meta.get(key)!r}, not posterior.npz's {value!r}", str(js))
    out["meta"] = meta
    return out


def _file_bytes(path: Path) -> bytes:
    try:
        return regular_file_bytes(path, MAX_POSTERIOR_BYTES, str(path))
    except FileNotFoundError:
        raise ConfigError("cannot be read (no such file)", str(path)) from None


def _read_npz(path: Path) -> dict[str, Any]:
    raw = _file_bytes(path)
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as archive:
            unpacked = sum(member.file_size for member in archive.infolist())
        if unpacked > MAX_POSTERIOR_BYTES:
            raise ValueError(f"its arrays unpack to {unpacked} bytes")
        with np.load(io.BytesIO(raw), allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise ConfigError(f"not a posterior.npz of fbia ({exc})", str(path)) from None


def _check_arrays(out: Mapping[str, Any]) -> None:
    """ValueError naming the first array of posterior.npz that is missing, unknown, of
    another kind or does not fit the others."""
    expected = {*_ARRAYS, *(_DESIGN if any(k in out for k in _DESIGN) else ())}
    missing, unknown = sorted(expected - set(out)), sorted(set(out) - expected)
    if missing:
        raise ValueError(f"has no array {missing[0]}")
    if unknown:
        raise ValueError(f"has an array {unknown[0]}, which fbia does not write")
    for key, value in out.items():
        kinds = _KINDS.get(key, "iuf")
        if value.dtype.kind not in kinds:
            raise ValueError(f"{key} holds {value.dtype} values, not {_KIND_NAMES[kinds]}")
    names, n_x = [str(n) for n in np.atleast_1d(out["names"])], out["n_x"]
    if out["names"].ndim != 1 or n_x.ndim != 0:
        raise ValueError(f"names has shape {out['names'].shape}, n_x {n_x.shape}: not (d,), ()")
    particles = np.asarray(out["particles"], dtype=float)
    per_particle = {k: np.asarray(out[k], dtype=float) for k in _PER_PARTICLE}
    weights = np.asarray(out["weights"], dtype=float)
    check_particles("", names, int(n_x), particles, weights, per_particle)
    theta = (len(particles), len(names) - int(n_x))
    if out["theta"].shape != theta:
        raise ValueError(f"theta has shape {out['theta'].shape}, not {theta}: the last columns")
    if "design" in out:
        n = len(out["design"])
        if out["design"].ndim != 2:
            raise ValueError(f"design has shape {out['design'].shape}, not (n, d)")
        for key in _DESIGN[1:]:
            if out[key].shape != (n,):
                raise ValueError(f"{key} has shape {out[key].shape}, not ({n},): one per run")


def _read_meta(path: Path) -> dict[str, Any]:
    def constant(name: str) -> float:
        raise ValueError(f"{name} is not JSON as fbia writes it")

    try:
        meta = json.loads(
            _file_bytes(path).decode("utf-8"),
            parse_constant=constant,
        )
    except UnicodeDecodeError as exc:
        raise ConfigError(f"not UTF-8 text (byte {exc.start})", str(path)) from None
    except RecursionError:
        raise ConfigError("nested too deeply: not a posterior.json", str(path)) from None
    except ValueError as exc:
        raise ConfigError(f"not JSON ({exc})", str(path)) from None
    if not isinstance(meta, dict):
        raise ConfigError("not a JSON object", str(path))
    return meta


def to_inference_data(posterior: Mapping[str, Any], n_draws: int | None = None, seed: int = 0):
    """An ``arviz.InferenceData`` of a :func:`load_posterior` result
    (:mod:`~fbia.iterators.gp_smc.inference_data`; without the prior, the units and the
    study's attributes, which ``GpSmcResult.to_inference_data`` adds)."""
    return inference_data(
        list(posterior["names"]),
        np.asarray(posterior["particles"]),
        np.asarray(posterior["weights"]),
        np.asarray(posterior["log_likelihood"]),
        np.asarray(posterior["log_prior"]),
        seed=seed,
        n_draws=n_draws,
    )


def write_posterior_files(result: Any, folder: str | Path, seed: int = 0) -> list[Path]:
    """What ``fbia run`` writes of a ``gp_smc`` posterior: ``posterior.npz`` +
    ``posterior.json`` (:func:`save_posterior`) and, with arviz installed, ``posterior.nc``:
    the :func:`to_inference_data` of its particles, which ``arviz.from_netcdf`` reads."""
    if not isinstance(result, GpSmcResult) or result.posterior is None:
        return []
    folder = Path(folder)
    paths = list(save_posterior(result, folder))
    try:
        data = result.to_inference_data(seed=seed)
    except ConfigError:  # arviz is not installed
        return paths
    data.to_netcdf(str(folder / "posterior.nc"))
    return [*paths, folder / "posterior.nc"]
