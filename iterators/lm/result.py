"""The result of a Levenberg–Marquardt analysis: optimum, statistics, multi-start comparison.

Statistics of the fit at the optimum x* (n_r residuals, n_x parameters, RSS = ‖r‖²):

* Gauss–Newton covariance ``cov = σ² (JᵀJ)⁻¹`` with ``σ² = RSS / (n_r − n_x)`` and the
  correlation matrix ``corr_ij = cov_ij / √(cov_ii cov_jj)`` (so a compensation such as the
  E–ν coupling of Paper A shows as a number close to ±1).  J is the finite-difference Jacobian
  of eq. 23; a rank-deficient J gives a pseudo-inverse and ``cov_rank < n_x``.
* Information criteria for comparing forward models (Paper A, "Model selection"), with the
  Gaussian likelihood maximised over σ² as well (k = n_x + 1 fitted quantities)::

      AIC = n_r·ln(2π·RSS/n_r) + n_r + 2k
      BIC = n_r·ln(2π·RSS/n_r) + n_r + k·ln(n_r)

  Only differences between models fitted to the same data mean something; lower is better.
"""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar, TypedDict

import numpy as np
from numpy.typing import NDArray

from ...core.problem import Result, html_table
from .fit_quality import FitQuality

FloatArray = NDArray[np.float64]


@dataclass
class FitStatistics:
    """Covariance, correlation and information criteria of a least-squares fit."""

    sigma2: float | None
    cov: FloatArray | None
    corr: FloatArray | None
    stderr: FloatArray | None
    cov_rank: int
    aic: float | None
    bic: float | None

    @classmethod
    def of(cls, J: FloatArray, r: FloatArray) -> FitStatistics:
        n_r, n_x = J.shape
        rss = float(r @ r)
        aic = bic = None
        if rss > 0.0:
            loglik2 = n_r * math.log(2.0 * math.pi * rss / n_r) + n_r  # -2 ln L at the optimum
            k = n_x + 1
            aic, bic = loglik2 + 2.0 * k, loglik2 + k * math.log(n_r)
        if n_r <= n_x or not np.all(np.isfinite(J)):
            return cls(None, None, None, None, 0, aic, bic)
        sigma2 = rss / (n_r - n_x)
        _, sv, Vt = np.linalg.svd(J, full_matrices=False)
        tol = sv.max(initial=0.0) * max(J.shape) * np.finfo(float).eps
        keep = sv > tol
        inv = (Vt[keep].T / sv[keep] ** 2) @ Vt[keep]  # (JᵀJ)⁺
        cov = sigma2 * inv
        stderr = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = cov / np.outer(stderr, stderr)
        corr[~np.isfinite(corr)] = 0.0
        np.fill_diagonal(corr, np.where(stderr > 0, 1.0, 0.0))
        return cls(sigma2, cov, corr, stderr, int(keep.sum()), aic, bic)


@dataclass
class LMState:
    """What :meth:`~fbia.iterators.levenberg_marquardt.LevenbergMarquardtIterator.steps`
    yields after every batch of runs."""

    round: int
    nfev: int
    n_failed: int
    chains: list[dict[str, Any]]

    def __str__(self) -> str:
        parts = []
        for c in self.chains:
            tail = f" [{c['status']}]" if c["status"] else ""
            parts.append(
                f"start {c['start']}: it {c['iteration']}, err_res {c['err_res']:.3e}, "
                f"err_grad {c['err_grad']:.3e}, mu {c['mu']:.2e}{tail}"
            )
        return f"round {self.round}, {self.nfev} runs ({self.n_failed} failed): " + "; ".join(parts)


class _StartKeys(TypedDict):
    start: int
    status: str
    success: bool
    x: dict[str, float] | None
    err_res: float | None
    err_grad: float | None
    iterations: int
    nfev: int
    at_bound: list[str]
    best: bool
    equally_good: bool


class StartRecord(_StartKeys, total=False):
    """One row of :attr:`LMResult.starts` as ``result.json`` holds it (what
    :func:`fbia.load_result` checks it against): the keys above always, these where the
    run gave them; the rows may hold more."""

    x0: dict[str, float]
    message: str
    mu: float | None
    n_failed: int
    label: str


#: How each ``jacobian`` option computes J, for the summary.
_JACOBIAN_SOURCE = {
    "tangent": "the model's tangents",
    "forward": "forward differences",
    "central": "central differences",
}


@dataclass
class LMResult(Result):
    """:class:`~fbia.core.problem.Result` of the Levenberg–Marquardt iterator.

    Attributes (besides those of ``Result``; ``x`` is the best optimum over all starts)
    ----------
    names
        Parameter names, in the order of the arrays below.
    err_res, err_grad, mu
        Paper A eq. 25, eq. 24 and the damping at the optimum.
    iterations
        LM steps taken by the best start.
    residuals
        r at the optimum (eq. 19).
    jac, jac_x
        The last finite-difference Jacobian (eq. 23) of the best start and the point where it
        was computed (x* itself, or the iterate before it when the run stopped on ftol/xtol
        right after its last step).
    sigma2, cov, corr, stderr, cov_rank
        Gauss–Newton estimates at the optimum (see the module docstring).
    aic, bic
        Akaike and Bayesian information criteria of the fit (module docstring).
    starts
        One row per initial guess: x0, status, x, err_res, err_grad, iterations, nfev, n_failed,
        parameters at a bound, and whether it fits as well as the best one.
    warnings
        Human-readable warnings: starts that fit equally well but found different optima, or
        fewer residuals than parameters (the optimum is then not determined).
    quality
        The verdict on the optimum (:class:`~fbia.iterators.lm.fit_quality.FitQuality`):
        parameters at a bound, the chi-square test against the stated noise; its causes make
        the status ``unreliable``. ``stderr`` leaves out the parameters at a bound, and is
        None when the best start never moved.
    """

    names: list[str] = field(default_factory=list)
    err_res: float | None = None
    err_grad: float | None = None
    mu: float | None = None
    iterations: int = 0
    residuals: FloatArray | None = field(default=None, repr=False)
    jac: FloatArray | None = field(default=None, repr=False)
    jac_x: dict[str, float] | None = field(default=None, repr=False)
    sigma2: float | None = None
    cov: FloatArray | None = field(default=None, repr=False)
    corr: FloatArray | None = field(default=None, repr=False)
    stderr: dict[str, float] | None = None
    cov_rank: int = 0
    aic: float | None = None
    bic: float | None = None
    starts: list[dict[str, Any]] = field(
        default_factory=list, repr=False, metadata={"read_as": list[StartRecord]}
    )
    warnings: list[str] = field(default_factory=list)
    quality: FitQuality | None = None
    #: what every LM result.json holds (fbia.load_result)
    required_fields: ClassVar[tuple[str, ...]] = ("names", "starts", "err_res")

    @property
    def x_array(self) -> FloatArray | None:
        """The optimum as an array in the order of ``names`` (None without result)."""
        if self.x is None:
            return None
        return np.array([self.x[n] for n in self.names])

    def check_loaded(self) -> None:
        """The optimum, the standard errors and the arrays against ``names``: ``x`` and every
        start's optimum over the names, ``residuals`` a vector, ``jac`` (n_r, n_x), ``cov``
        and ``corr`` (n_x, n_x)."""
        names, n = self.names, len(self.names)
        if len(set(names)) != n:
            raise ValueError(f"names {names} holds a name twice")
        for key, value in (("x", self.x), ("jac_x", self.jac_x), ("stderr", self.stderr)):
            if value is not None and not set(value) <= set(names):
                raise ValueError(f"{key} is over {sorted(value)}, not over names {names}")
        if self.x is not None and set(self.x) != set(names):
            raise ValueError(f"x is over {sorted(self.x)}, not over names {names}")
        shapes = {"jac": (None, n), "cov": (n, n), "corr": (n, n), "residuals": (None,)}
        for key, shape in shapes.items():
            a = getattr(self, key)
            if a is not None and (
                a.ndim != len(shape)
                or any(s not in (None, m) for s, m in zip(shape, a.shape, strict=True))
            ):
                want = ", ".join("n_r" if s is None else str(s) for s in shape)
                raise ValueError(f"{key} has shape {a.shape}, not ({want}) for names {names}")
        for i, s in enumerate(self.starts):
            if s["x"] is not None and (set(s["x"]) != set(names) or s["err_res"] is None):
                raise ValueError(
                    f"starts[{i}].x is over {sorted(s['x'])} with err_res {s['err_res']}, not "
                    f"over names {names} with a number"
                )

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()

        def arr(a: FloatArray | None) -> Any:
            return None if a is None else np.asarray(a).tolist()

        out.update(
            {
                "names": list(self.names),
                "err_res": self.err_res,
                "err_grad": self.err_grad,
                "mu": self.mu,
                "iterations": self.iterations,
                "residuals": arr(self.residuals),
                "jac": arr(self.jac),
                "jac_x": self.jac_x,
                "sigma2": self.sigma2,
                "cov": arr(self.cov),
                "corr": arr(self.corr),
                "stderr": self.stderr,
                "cov_rank": self.cov_rank,
                "aic": self.aic,
                "bic": self.bic,
                "starts": [_plain(s) for s in self.starts],
                "warnings": list(self.warnings),
                "quality": None if self.quality is None else _plain(asdict(self.quality)),
            }
        )
        return out

    def quantities(self) -> dict[str, float]:
        """Besides :meth:`Result.quantities`: ``err_res``, ``err_grad``, ``iterations`` and
        ``stderr.<name>`` (the standard errors of the covariance sigma^2 (J^T J)^-1, where it
        exists) of the best start; per start k (1-based, and by its label from ``x0_labels``,
        spaces as ``_``) ``start.<k>.<name>``, ``.err_res``, ``.err_grad``, ``.iterations``,
        ``.nfev``, ``.converged`` (1/0), ``.at_bound`` (parameters on a bound) (NaN where the
        start gave no result); over the starts with a result ``mean.<q>`` and ``std.<q>``
        (population std, ddof 0) of every parameter and err_res, and ``n_starts``,
        ``n_results``, ``n_converged``."""
        out = super().quantities()
        nan = math.nan
        for key in ("err_res", "err_grad"):
            value = getattr(self, key)
            out[key] = nan if value is None else float(value)
        out["iterations"] = float(self.iterations)
        fit = self.quality
        if fit is not None:
            out["n_at_bound"] = float(len(fit.at_bound))
            if fit.chi2 is not None and fit.dof:
                out["chi2"] = fit.chi2
                out["reduced_chi2"] = fit.chi2 / fit.dof
                out["p_chi2"] = nan if fit.p_value is None else fit.p_value
        for name, se in (self.stderr or {}).items():
            out[f"stderr.{name}"] = float(se)
        with_x = [s for s in self.starts if s["x"] is not None]
        for s in self.starts:
            x = s["x"] or {}
            row = {n: float(x.get(n, nan)) for n in self.names}
            row.update(
                err_res=nan if s["err_res"] is None else float(s["err_res"]),
                err_grad=nan if s["err_grad"] is None else float(s["err_grad"]),
                iterations=float(s["iterations"]),
                nfev=float(s["nfev"]),
                converged=float(bool(s["success"])),
                at_bound=float(len(s["at_bound"])),
            )
            keys = [str(s["start"])]
            if s.get("label"):
                keys.append("_".join(str(s["label"]).split()))
            for key in keys:
                out.update({f"start.{key}.{q}": v for q, v in row.items()})
        for q in [*self.names, "err_res"]:
            values = [float(s["x"][q] if q in self.names else s["err_res"]) for s in with_x]
            out[f"mean.{q}"] = float(np.mean(values)) if values else nan
            out[f"std.{q}"] = float(np.std(values)) if values else nan
        out["n_starts"] = float(len(self.starts))
        out["n_results"] = float(len(with_x))
        out["n_converged"] = float(sum(bool(s["success"]) for s in self.starts))
        return out

    def table(self) -> str:
        """The multi-start comparison as a text table (one row per initial guess)."""
        head = ["#", "status", *[f"{n}*" for n in self.names], "err_res", "iter", "nfev", "note"]
        rows = []
        for s in self.starts:
            x = s["x"] or {}
            note = []
            if s["best"]:
                note.append("best")
            elif s["equally_good"]:
                note.append("fits as well")
            if s["at_bound"]:
                note.append("at bound: " + ",".join(s["at_bound"]))
            rows.append(
                [
                    str(s["start"]),
                    s["status"],
                    *[f"{x[n]:.6g}" if n in x else "-" for n in self.names],
                    "-" if s["err_res"] is None else f"{s['err_res']:.3e}",
                    str(s["iterations"]),
                    str(s["nfev"]),
                    "; ".join(note),
                ]
            )
        widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
        lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
        lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
        return "\n".join(line.rstrip() for line in lines)

    def to_records(self) -> list[dict[str, Any]]:
        """The multi-start table as plain rows, one per initial guess (:meth:`to_dataframe`
        wraps them): ``start`` (1-based), ``label`` (from ``x0_labels``, else empty),
        ``status`` (the start's own stop tag), ``converged``, ``best``, ``fits_as_well``,
        ``x0.<name>`` where it started, ``x.<name>`` where it ended (NaN without result),
        ``err_res`` and ``err_grad`` there (eq. 25, 24), ``iterations``, ``nfev``,
        ``n_failed``, ``at_bound`` (the parameters on a bound, comma-separated) and
        ``message``."""
        nan = math.nan
        rows = []
        for s in self.starts:
            x, x0 = s["x"] or {}, s.get("x0") or {}
            row: dict[str, Any] = {
                "start": int(s["start"]),
                "label": str(s.get("label") or ""),
                "status": str(s["status"]),
                "converged": bool(s["success"]),
                "best": bool(s.get("best")),
                "fits_as_well": bool(s.get("equally_good")),
            }
            row.update({f"x0.{n}": float(x0.get(n, nan)) for n in self.names})
            row.update({f"x.{n}": float(x.get(n, nan)) for n in self.names})
            for key in ("err_res", "err_grad"):
                row[key] = nan if s[key] is None else float(s[key])
            for key in ("iterations", "nfev", "n_failed"):
                row[key] = int(s.get(key) or 0)
            row["at_bound"] = ", ".join(s["at_bound"])
            row["message"] = str(s.get("message", ""))
            rows.append(row)
        return rows

    def _html_body(self) -> str:
        """Parameter, value, standard error (none at a bound, none from a start that never
        moved: as :meth:`summary` says) and unit; the fit's figures; the starts (more than
        one); the warnings."""
        q = self.quality
        sides = {} if q is None else dict(zip(q.at_bound, q.bound_sides, strict=False))
        units, x = self.units(), self.x or {}
        rows = []
        for name in (n for n in self.names if n in x):
            if name in sides:
                se = f"none: at its {sides[name]} bound"
            elif self.stderr and name in self.stderr:
                se = f"± {self.stderr[name]:.3g}"
            elif self.iterations == 0 and self.err_res is not None:
                se = "none: the best start never moved"
            else:
                se = "-"
            rows.append([name, x[name], se, units.get(name, "")])
        head = ["parameter", "value", "std. error", "unit"]
        if not units:  # a unit column only where the result knows units
            head, rows = head[:-1], [row[:-1] for row in rows]
        parts = [html_table(head, rows)] if rows else []
        if self.err_res is not None:
            fit = (
                f"err_res = {self.err_res:.4e}, err_grad = {self.err_grad:.3e}, "
                f"{self.iterations} iterations, J from {self._jacobian_sources()}"
            )
            if q is not None and q.chi2 is not None:
                fit += f"; fit against the stated noise: {q.describe()}"
            parts.append(f"<p>{html.escape(fit)}</p>")
        if len(self.starts) > 1:
            head = ["start", "status", *[f"{n}*" for n in self.names], "err_res", "iter", "nfev"]
            table = []
            for r in self.to_records():
                notes = ["best"] if r["best"] else ["fits as well"] if r["fits_as_well"] else []
                if r["at_bound"]:
                    notes.append(f"at bound: {r['at_bound']}")
                start = f"{r['start']} ({r['label']})" if r["label"] else r["start"]
                err = "-" if math.isnan(r["err_res"]) else f"{r['err_res']:.3e}"
                xs = [r[f"x.{n}"] for n in self.names]
                table.append(
                    [start, r["status"], *xs, err, r["iterations"], r["nfev"], "; ".join(notes)]
                )
            parts.append(html_table([*head, "note"], table))
        parts += [f'<p style="color:#b00020">WARNING: {html.escape(w)}</p>' for w in self.warnings]
        return "".join(parts)

    def _jacobian_sources(self) -> str:
        """Where J came from: the option's source, or each source's count where they mix
        (tangents asked for, differences where a run gave none)."""
        counts = {k: v for k, v in self.info.get("jacobians", {}).items() if v}
        if len(counts) <= 1:
            return _JACOBIAN_SOURCE.get(self.info.get("jacobian", "forward"), "differences")
        return ", ".join(f"{_JACOBIAN_SOURCE[k]} ({n})" for k, n in counts.items())

    def summary(self) -> str:
        lines = [super().summary()]
        if self.err_res is not None:
            lines.append(
                f"  err_res = {self.err_res:.4e}, err_grad = {self.err_grad:.3e}, "
                f"{self.iterations} iterations, J from {self._jacobian_sources()}"
            )
        if self.stderr:
            lines.append(
                "  std. errors: " + ", ".join(f"{k} ± {v:.3g}" for k, v in self.stderr.items())
            )
        at_bound = () if self.quality is None else self.quality.at_bound
        if at_bound:
            lines.append(f"  no std. error at a bound: {', '.join(at_bound)}")
        elif self.stderr is None and self.err_res is not None and self.iterations == 0:
            lines.append("  no std. errors: the best start never moved from its initial guess")
        if self.quality is not None and self.quality.chi2 is not None:
            lines.append(f"  fit against the stated noise: {self.quality.describe()}")
        if self.corr is not None and len(self.names) > 1:
            pairs = [
                f"{self.names[i]}-{self.names[j]} {self.corr[i, j]:+.3f}"
                for i in range(len(self.names))
                for j in range(i + 1, len(self.names))
            ]
            lines.append("  correlation: " + ", ".join(pairs))
        if self.aic is not None and self.bic is not None:
            lines.append(f"  AIC = {self.aic:.4g}, BIC = {self.bic:.4g}")
        if len(self.starts) > 1:
            lines.append(self.table())
        lines += [f"  WARNING: {w}" for w in self.warnings]
        return "\n".join(lines)


def compare_starts(
    starts: list[dict[str, Any]],
    names: Sequence[str],
    typical: FloatArray,
    fit_rtol: float,
    agree_rtol: float,
) -> tuple[int | None, list[str]]:
    """Mark the best start and those fitting as well; warn where such optima disagree.

    A start fits as well as the best when its err_res is within ``fit_rtol`` (relative) of the
    best one; two such optima disagree on a parameter when they differ by more than
    ``agree_rtol · max(|x|, typical)``.  Returns the index of the best start and the warnings.
    """
    with_result = [i for i, s in enumerate(starts) if s["x"] is not None]
    for s in starts:
        s["best"] = s["equally_good"] = False
    if not with_result:
        return None, []
    best = min(with_result, key=lambda i: starts[i]["err_res"])
    ref = starts[best]
    ref["best"] = ref["equally_good"] = True
    warnings = []
    xb = np.array([ref["x"][n] for n in names])
    for i in with_result:
        if i == best:
            continue
        s = starts[i]
        if s["err_res"] <= ref["err_res"] * (1.0 + fit_rtol) + 1e-300:
            s["equally_good"] = True
            xi = np.array([s["x"][n] for n in names])
            scale = np.maximum(np.maximum(np.abs(xb), typical), 1e-300)
            off = np.abs(xi - xb) > agree_rtol * scale
            if np.any(off):
                diff = ", ".join(
                    f"{n} = {xi[j]:.4g} vs {xb[j]:.4g}" for j, n in enumerate(names) if off[j]
                )
                warnings.append(
                    f"starts {s['start']} and {ref['start']} fit equally well (err_res "
                    f"{s['err_res']:.3e} vs {ref['err_res']:.3e}) but disagree: {diff}; the "
                    "data may not determine these parameters (compensation) or the objective "
                    "has several minima - judge the optima by plausibility"
                )
    return best, warnings


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.floating | np.integer):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value
