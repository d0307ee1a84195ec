"""Noise judged over draws: a study with ``[synthetic] draws = N`` runs once per noise draw.

One noisy data set is one sample of what an experiment could give; a single fit to it says
little about how the method behaves at that noise level (Paper A, Table 2 and Remark 1 report
one draw each).  With ``draws = N`` (N > 1, noise_std > 0) :func:`fbia.studies.runner.run_study`
runs the study's iterator N times, each on its own synthetic data:

- draw 0 uses the study's synthetic seed (the data of the same study with ``draws = 1``),
  draw k >= 1 the seed ``SeedSequence(seed, spawn_key=(k,))`` (:func:`draw_seed`);
- draw k writes its own output folder ``<output>/draws/<k>`` (``result.json``, report,
  the interfaces at its estimate; no plots) and its forward runs go to the study's store,
  which every draw shares: a forward run at the same inputs is made once for all draws, and
  a study stopped between draws resumes from the store;
- the study's own ``result.json`` is a :class:`DrawsResult`: per draw its seed, status and
  quantities (``Result.quantities()``), and over the draws that gave a result the median and
  the central 95 % range (2.5 and 97.5 % percentiles) of every quantity;
- its ``[paper]`` rows are judged over the draws (:func:`fbia.studies.paper.compare_draws`,
  the rule ``DRAWS_RULE``): a published number agrees when it lies inside fbia's range.

How many draws: the central 95 % range estimated from N draws (percentiles interpolated
between order statistics) holds a further draw with probability about 87 % at N = 20 and 93 %
at N = 100 (the order statistics of N draws: it does not depend on the distribution), so a
range from 20 draws is a narrow one; Paper A's draws studies use 100.

The draws as a whole are ``completed`` when there are at least :data:`MIN_DRAWS` of them and
at most :data:`MAX_LOST` of them gave no result that is a success and not flagged unreliable
(the range is taken over the others; leaving out many would bias it); otherwise
``unreliable``, which agrees with nothing.

>>> draw_seed(7, 0), draw_seed(7, 1) == draw_seed(7, 1), draw_seed(7, 1) == draw_seed(7, 2)
(7, True, False)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..core.options import plugin_options
from ..core.problem import Result
from .paper import Comparison, PaperSpec, compare_draws
from .study import Study

__all__ = [
    "MAX_LOST",
    "MIN_DRAWS",
    "DrawRecord",
    "DrawsResult",
    "draw_seed",
    "draw_study",
    "fresh_model",
    "judge_draws",
    "run_draws",
]

#: the fewest draws for a 95 % range (below: ``unreliable``)
MIN_DRAWS = 20
#: the largest share of draws without a result that may be left out of the range
MAX_LOST = 0.1
#: the folder of the draws in the study's output folder
DRAWS_FOLDER = "draws"


def draw_seed(seed: int, k: int) -> int:
    """The noise seed of draw ``k``: ``seed`` itself for draw 0, a derived one after."""
    if k == 0:
        return int(seed)
    return int(np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(1)[0])


def draw_study(study: Study, k: int, output: Path, store: Path) -> Study:
    """The study of draw ``k``: its own noise seed and output folder, the shared ``store``,
    one draw, no ``[paper]`` (the draws are judged together), no plots, and a model object of
    its own (:func:`fresh_model`), so that neither its data nor its fit depend on the state
    an earlier draw left in the model (warm starts)."""
    spec = study.synthetic
    assert spec is not None and spec.draws > 1
    width = len(str(spec.draws - 1))
    return replace(
        study,
        model=fresh_model(study.model),
        name=f"{study.name} draw {k}",
        synthetic=replace(spec, seed=draw_seed(spec.seed, k), draws=1),
        output=output / DRAWS_FOLDER / f"{k:0{width}d}",
        store=store,
        paper=None,
        figures=False,
    )


def fresh_model(model: Any) -> Any:
    """A new model object with the options of ``model`` (no state of earlier runs: a model
    that warm-starts from its last solution gives, within its solver's tolerance, other
    numbers after other runs, which on an ill-conditioned fit moves the optimum); ``model``
    itself when its class cannot be built from its options."""
    try:
        return type(model)(**plugin_options(model, exclude_defaults=True))
    except Exception:  # a third-party model without an options constructor: shared
        return model


@dataclass(frozen=True)
class DrawRecord:
    """One draw: its noise seed, how its result ended, and its quantities."""

    draw: int
    seed: int
    status: str
    success: bool
    message: str
    nfev: int
    forward_time: float  # s, summed wall time of its forward runs (stored ones too)
    quantities: dict[str, float]

    @property
    def judged(self) -> bool:
        """Whether the draw counts: a success, not flagged unreliable."""
        return self.success and self.status != "unreliable"


@dataclass
class DrawsResult(Result):
    """The result of a study over noise draws (``status``: ``completed``, ``unreliable`` or
    ``no_result``; ``x``: the median over the judged draws of their estimates)."""

    draws: list[DrawRecord] = field(default_factory=list)

    @property
    def judged(self) -> list[DrawRecord]:
        return [d for d in self.draws if d.judged]

    @property
    def forward_time(self) -> float:
        return float(sum(d.forward_time for d in self.draws))

    def quantities(self) -> dict[str, float]:
        """``n_draws``, ``n_judged``; over the judged draws, for every quantity q of a draw,
        ``median.<q>``, ``low.<q>`` and ``high.<q>`` (2.5 / 97.5 % percentiles), and
        ``share_negative.x``: the share of draws whose estimate has a negative parameter
        (with Poisson's ratios: an auxetic fit, Paper A Remark 1)."""
        out = super().quantities()
        judged = self.judged
        out["n_draws"] = float(len(self.draws))
        out["n_judged"] = float(len(judged))
        names = sorted({q for d in judged for q in d.quantities})
        for q in names:
            f = np.array([d.quantities.get(q, math.nan) for d in judged], dtype=float)
            ok = f[np.isfinite(f)]
            out[f"median.{q}"] = float(np.median(ok)) if ok.size else math.nan
            out[f"low.{q}"] = float(np.percentile(ok, 2.5)) if ok.size else math.nan
            out[f"high.{q}"] = float(np.percentile(ok, 97.5)) if ok.size else math.nan
        if judged:
            negative = [
                any(v < 0 for k, v in d.quantities.items() if k.startswith("x.")) for d in judged
            ]
            out["share_negative.x"] = float(np.mean(negative))
        return out

    def to_dict(self) -> dict[str, Any]:
        out = super().to_dict()
        out["draws"] = [asdict(d) for d in self.draws]
        return out

    def summary(self) -> str:
        judged = self.judged
        lines = [
            f"{self.iterator} over {len(self.draws)} noise draws: {self.status} - {self.message}"
        ]
        if judged and self.x:
            q = self.quantities()
            for name in self.x:
                lines.append(
                    f"  {name}: median {q[f'median.x.{name}']:.6g}, 95 % range "
                    f"[{q[f'low.x.{name}']:.6g}, {q[f'high.x.{name}']:.6g}]"
                )
            lines.append(f"  share of draws with a negative parameter: {q['share_negative.x']:.2f}")
        lines.append(
            f"  {self.nfev} forward evaluations in all (runs shared between draws count in each)"
        )
        return "\n".join(lines)


def run_draws(
    study: Study,
    output: Path,
    store: Path,
    run_one: Callable[[Study, int], Result],
    echo: Callable[[str], None],
) -> DrawsResult:
    """Run the study once per draw (``run_one(draw_study, k)`` runs one) and collect them."""
    spec = study.synthetic
    assert spec is not None
    records = []
    for k in range(spec.draws):
        sub = draw_study(study, k, output, store)
        assert sub.synthetic is not None
        echo(f"-- draw {k + 1} of {spec.draws} (noise seed {sub.synthetic.seed}): {sub.output}")
        result = run_one(sub, k)
        forward = sum(e.time for e in result.evaluations if math.isfinite(e.time))
        records.append(
            DrawRecord(
                draw=k,
                seed=sub.synthetic.seed,
                status=result.status,
                success=bool(result.success),
                message=result.message,
                nfev=int(result.nfev),
                forward_time=float(forward),
                quantities={
                    k2: float(v) for k2, v in result.quantities().items() if math.isfinite(v)
                },
            )
        )
    return collect(records, str(study.iterator_name or ""))


def collect(records: Sequence[DrawRecord], iterator: str) -> DrawsResult:
    """The :class:`DrawsResult` of the draws ``records`` (status by ``MIN_DRAWS``,
    ``MAX_LOST``)."""
    judged = [d for d in records if d.judged]
    lost = len(records) - len(judged)
    if not judged:
        status, message = "no_result", f"none of the {len(records)} draws gave a result"
    elif len(records) < MIN_DRAWS:
        status = "unreliable"
        message = f"{len(records)} draws: a 95 % range needs at least {MIN_DRAWS}"
    elif lost > MAX_LOST * len(records):
        status = "unreliable"
        message = (
            f"{lost} of {len(records)} draws gave no result (more than "
            f"{100 * MAX_LOST:g} %): leaving them out would bias the range"
        )
    else:
        status = "completed"
        message = f"{len(judged)} of {len(records)} draws gave a result"
    names = [k[2:] for k in (judged[0].quantities if judged else {}) if k.startswith("x.")]
    x = {
        n: float(np.median([d.quantities[f"x.{n}"] for d in judged if f"x.{n}" in d.quantities]))
        for n in names
    } or None
    return DrawsResult(
        status=status,
        success=status == "completed",
        message=message,
        x=x,
        nfev=sum(d.nfev for d in records),
        iterator=iterator,
        draws=list(records),
    )


def judge_draws(spec: PaperSpec, result: DrawsResult) -> list[Comparison]:
    """The ``[paper]`` rows judged over the draws that gave a result (``DRAWS_RULE``)."""
    judged = result.judged
    if not judged:  # nothing to judge: every row "no", with the reason
        dummy = [dict.fromkeys(_names(spec), math.nan)]
        return compare_draws(spec, dummy, result.status, False)
    return compare_draws(spec, [d.quantities for d in judged], result.status, result.success)


def _names(spec: PaperSpec) -> list[str]:
    return [n for v in spec.values for n in (v.quantity, v.than) if n is not None]
