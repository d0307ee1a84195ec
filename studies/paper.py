"""Published numbers beside fbia's: the ``[paper]`` table of a study file and its comparison.

A study that reproduces an example of a paper states, as data, what the paper reported and
what *kind* of quantity each number is; the kind alone says what "agrees" means (``KINDS``:
one rule per kind, the same for every study, so that no row can choose a rule it cannot
fail)::

    [paper]
    source = "Paper A, Table 2, row sigma = 1e-3 mm"
    note = "optional: what differs from the paper's set-up as a whole"

    [[paper.values]]
    quantity = "mean.E"        # a name the result exposes (Result.quantities())
    kind = "modulus"           # KINDS below: modulus, ratio, scale, count, ordering, shown
    paper = 408.0              # the published value
    unit = "Pa"
    label = "mean E"           # optional: how the report names the row
    why = "measured cause of a difference, or 'cause not found' and what was measured"

    [[paper.values]]           # an ordering the paper states, of two quantities of the result
    quantity = "start.olive.iterations"
    kind = "ordering"
    above = "start.red.iterations"   # or below = "..."

:func:`read_paper` checks the table (unknown keys, wrong types, an unknown kind, a kind
without what it needs, the retired per-value ``rule``/``tolerance``: one-line
:class:`~fbia.core.errors.ConfigError` naming the file and the entry) and returns a
:class:`PaperSpec`; :func:`compare` looks each quantity up in the result's
:meth:`~fbia.core.problem.Result.quantities` (an unknown name is a ConfigError that lists the
available ones) and returns one :class:`Comparison` per value.  A result flagged
``unreliable``, or one whose ``success`` is false, agrees with nothing: every judged row is
"no", with that reason.  :mod:`fbia.studies.paper_report` writes the rows as ``report.md`` and
``paper.json`` and composes the summary of many studies, with the rules of ``KINDS`` stated
once at the top.

>>> spec = read_paper({"source": "Paper A", "values": [
...     {"quantity": "x.E", "kind": "modulus", "paper": 400.0, "unit": "Pa"}]}, "s.toml")
>>> rows = compare(spec, {"x.E": 407.0, "x.nu": 0.3})
>>> rows[0].agrees, round(rows[0].rel_diff, 4), rows[0].value.criterion()
(True, 0.0175, 'within 2 %')
>>> compare(spec, {"x.E": 407.0}, status="unreliable", success=False)[0].reason
'the result is flagged unreliable (status unreliable)'
>>> compare(spec, {"x.nu": 0.3})                               # doctest: +ELLIPSIS
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: s.toml: [[paper.values]] #1 quantity: ... 'x.E'; available: x.nu
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..core.errors import ConfigError
from .study_schema import PaperSection, PaperValueSection, parse_section

__all__ = [
    "KINDS",
    "Comparison",
    "Kind",
    "PaperSpec",
    "PaperValue",
    "DRAWS_RULE",
    "compare",
    "compare_draws",
    "lookup",
    "read_paper",
    "verdict",
]


@dataclass(frozen=True)
class Kind:
    """A kind of quantity and the one rule by which fbia's number f agrees with the paper's p.

    ``rule``: ``relative`` (|f - p| <= t |p|), ``absolute`` (|f - p| <= t), ``factor``
    (|log2(f / p)| <= log2 t), ``equal``, ``ordering`` (f above or below another quantity of
    the result), ``none`` (shown, not judged); ``tolerance``: t.
    """

    rule: str
    tolerance: float | None
    covers: str  # which quantities are of this kind, in words

    @property
    def criterion(self) -> str:
        """The rule in a few words, e.g. ``within 2 %``."""
        t = self.tolerance
        return {
            "relative": lambda: f"within {100 * _num(t):g} %",
            "absolute": lambda: f"within {_num(t):g}",
            "factor": lambda: f"within a factor {_num(t):g}",
            "equal": lambda: "equal",
            "ordering": lambda: "the order the paper states",
            "none": lambda: "not judged",
        }[self.rule]()

    @property
    def formula(self) -> str:
        """What "agrees" means exactly (f: fbia, p: the paper)."""
        t = self.tolerance
        return {
            "relative": lambda: f"|f - p| <= {_num(t):g} |p|",
            "absolute": lambda: f"|f - p| <= {_num(t):g}",
            "factor": lambda: f"|log2(f / p)| <= {math.log2(_num(t)):g}",
            "equal": lambda: "f = p exactly",
            "ordering": lambda: (
                "f > g (`above = g`) or f < g (`below = g`), g a quantity of the result"
            ),
            "none": lambda: "fbia's number beside the paper's",
        }[self.rule]()


#: The kinds of quantity and their rules: the only rules a [[paper.values]] entry can have.
KINDS: dict[str, Kind] = {
    "modulus": Kind(
        "relative",
        0.02,
        "Young's moduli and other moduli or stiffness-like parameters (E, K, growth constants)",
    ),
    "ratio": Kind(
        "absolute",
        0.02,
        "Poisson's ratio ν, porosity φ and other dimensionless parameters of order 1",
    ),
    "scale": Kind(
        "factor", 2.0, "residuals, spreads (std), errors and other scale quantities (p > 0)"
    ),
    "count": Kind(
        "equal",
        None,
        "iterations, numbers of converged starts, flags such as converged = 1",
    ),
    "ordering": Kind(
        "ordering",
        None,
        "an ordering the paper states (olive needs more iterations than red)",
    ),
    "shown": Kind(
        "none",
        None,
        "a number the paper gives that fbia's result does not reproduce in kind",
    ),
}

#: The tests of the rules that compare f with a published p (t: the kind's tolerance).
_TESTS: dict[str, Callable[[float, float, float | None], bool]] = {
    "relative": lambda f, p, t: abs(f - p) <= _num(t) * abs(p),
    "absolute": lambda f, p, t: abs(f - p) <= _num(t),
    "factor": lambda f, p, t: f > 0 and abs(math.log2(f / p)) <= math.log2(_num(t)),
    "equal": lambda f, p, t: f == p,
}
#: the keys of the per-value rules before KINDS, and what to write instead
_RETIRED = {
    "rule": "give kind = one of {kinds} instead: the kind fixes the rule",
    "tolerance": "give kind = one of {kinds} instead: the kind fixes the tolerance",
    "than": 'an ordering is kind = "ordering" with above = or below = the other quantity',
}


@dataclass(frozen=True)
class PaperValue:
    """One published number (or ordering) and the kind of quantity it is."""

    quantity: str
    kind: str
    paper: float | None
    unit: str
    above: str | None
    below: str | None
    label: str
    why: str

    @property
    def name(self) -> str:
        """How the report names the row: the label, else the quantity."""
        return self.label or self.quantity

    @property
    def than(self) -> str | None:
        """The other quantity of an ordering."""
        return self.above if self.above is not None else self.below

    def criterion(self) -> str:
        """The kind's rule in a few words, e.g. ``within 2 %``, ``> start.red.iterations``."""
        if self.above is not None:
            return f"> {self.above}"
        if self.below is not None:
            return f"< {self.below}"
        return KINDS[self.kind].criterion


@dataclass(frozen=True)
class PaperSpec:
    """The ``[paper]`` table of a study: the source and its values."""

    source: str
    note: str
    values: tuple[PaperValue, ...]
    where: str = ""  # the study file, for the messages of compare()


@dataclass(frozen=True)
class Comparison:
    """One row of the report: the published number, fbia's, their difference, the verdict.

    ``agrees`` is None for kind ``shown``; ``abs_diff``/``rel_diff`` are None where there is
    no published number or the relative difference is undefined (paper value 0);
    ``reason``: why a row counts as "no" whatever its numbers (the result's status).
    """

    value: PaperValue
    fbia: float
    abs_diff: float | None
    rel_diff: float | None
    agrees: bool | None
    reference: float | None = None  # the other quantity's value (kind ordering)
    reason: str = ""
    low: float | None = None  # over noise draws (compare_draws): the 2.5 % percentile
    high: float | None = None  # ... the 97.5 % percentile (ordering: share that holds)
    n_draws: int = 0  # the draws judged; 0: one result

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["value"] = asdict(self.value)
        return {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in out.items()
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Comparison:
        value = PaperValue(**data["value"])
        fbia = data["fbia"]
        return cls(
            value,
            math.nan if fbia is None else float(fbia),
            data["abs_diff"],
            data["rel_diff"],
            data["agrees"],
            data.get("reference"),
            data.get("reason", ""),
            data.get("low"),
            data.get("high"),
            int(data.get("n_draws", 0)),
        )


def read_paper(raw: Any, file: str, has_iterator: bool = True) -> PaperSpec:
    """The ``[paper]`` table of the study file ``file``, checked (one ConfigError per fault);
    ``has_iterator``: whether the study has an ``[iterator]``, whose result it compares."""
    where = f"{file}: [paper]"
    if not has_iterator:
        raise ConfigError(
            "a [paper] table compares an iterator's result with the paper: give [iterator]", where
        )
    section = parse_section(PaperSection, raw, where)
    if not section.values:
        raise ConfigError("no [[paper.values]]: give at least one published number", where)
    kinds = ", ".join(KINDS)
    values = []
    for k, item in enumerate(section.values, start=1):
        at = f"{file}: [[paper.values]] #{k}"
        retired = next((key for key in _RETIRED if key in item), None)
        if retired is not None:
            hint = _RETIRED[retired].format(kinds=kinds)
            raise ConfigError(
                f"{retired!r} is no longer given per value: {hint}", f"{at} {retired}"
            )
        v = parse_section(PaperValueSection, item, at)
        if v.kind not in KINDS:
            raise ConfigError(f"unknown kind {v.kind!r}; valid: {kinds}", f"{at} kind")
        _check(v, at)
        values.append(
            PaperValue(
                quantity=v.quantity,
                kind=v.kind,
                paper=v.paper,
                unit=v.unit,
                above=v.above,
                below=v.below,
                label=v.label,
                why=" ".join(v.why.split()),
            )
        )
    return PaperSpec(section.source, " ".join(section.note.split()), tuple(values), file)


def _check(v: PaperValueSection, at: str) -> None:
    """What a value of its kind needs: a published number, or one other quantity."""
    if v.kind == "ordering":
        if (v.above is None) == (v.below is None):
            raise ConfigError(
                "kind 'ordering' needs one of 'above' and 'below' (the quantity to compare with)",
                at,
            )
        if v.paper is not None:
            raise ConfigError(
                "kind 'ordering' compares two quantities of the result: it takes no 'paper'",
                f"{at} paper",
            )
        return
    if v.above is not None or v.below is not None:
        key = "above" if v.above is not None else "below"
        raise ConfigError(f"{key!r} only for kind 'ordering', not {v.kind!r}", f"{at} {key}")
    if v.paper is None and v.kind != "shown":
        raise ConfigError(f"kind {v.kind!r} needs the published value 'paper'", at)
    if v.kind == "scale" and v.paper is not None and not v.paper > 0:
        raise ConfigError(f"kind 'scale' needs a positive paper value, got {v.paper}", at)


def lookup(quantities: Mapping[str, float], name: str, where: str = "") -> float:
    """``quantities[name]``, else a ConfigError that lists the available names."""
    if name in quantities:
        return float(quantities[name])
    available = ", ".join(sorted(quantities)) or "(none)"
    raise ConfigError(f"the result has no quantity {name!r}; available: {available}", where)


def compare(
    spec: PaperSpec,
    quantities: Mapping[str, float],
    status: str = "",
    success: bool = True,
    undetermined: Mapping[str, str] | None = None,
) -> list[Comparison]:
    """One :class:`Comparison` per value of ``spec``, fbia's number from ``quantities``.

    ``status``, ``success``: the result's; a result with status ``unreliable`` or without
    success agrees with nothing (every judged row "no", with that reason). ``undetermined``
    (``Result.undetermined``): quantities the result says it does not determine, each with
    why; a judged row of one (or ordered against one) is "no" with that reason."""
    loose = undetermined or {}
    flagged = ""
    if status == "unreliable":
        flagged = f"the result is flagged unreliable (status {status})"
    elif not success:
        flagged = f"the result is not a success (status {status or 'unknown'})"
    rows = []
    for k, v in enumerate(spec.values, start=1):
        at = f"{spec.where}: [[paper.values]] #{k}" if spec.where else f"[[paper.values]] #{k}"
        f = lookup(quantities, v.quantity, f"{at} quantity")
        key = "above" if v.above is not None else "below"
        ref = lookup(quantities, v.than, f"{at} {key}") if v.than is not None else None
        why = flagged or loose.get(v.quantity) or (loose.get(v.than) if v.than else None)
        rows.append(_judge(v, f, ref, why or ""))
    return rows


def _judge(v: PaperValue, f: float, ref: float | None, flagged: str) -> Comparison:
    kind = KINDS[v.kind]
    p = v.paper
    abs_diff = rel_diff = None
    if p is not None and math.isfinite(f):
        abs_diff = f - p
        rel_diff = abs_diff / abs(p) if p != 0 else None
    agrees: bool | None
    if kind.rule == "none":
        return Comparison(v, f, abs_diff, rel_diff, None, ref)
    if flagged:
        return Comparison(v, f, abs_diff, rel_diff, False, ref, flagged)
    if not math.isfinite(f):
        agrees = False
    elif kind.rule == "ordering":
        r = _num(ref)
        agrees = math.isfinite(r) and (f > r if v.above is not None else f < r)
    else:
        agrees = _TESTS[kind.rule](f, _num(p), kind.tolerance)
    return Comparison(v, f, abs_diff, rel_diff, agrees, ref)


#: the rule of a study judged over noise draws ([synthetic] draws, fbia.studies.draws)
DRAWS_RULE = (
    "over noise draws (a study with [synthetic] draws = N): a published number agrees when it "
    "lies within fbia's central 95 % range over the draws (the 2.5 and 97.5 % percentiles, "
    "linear interpolation, of the quantity over the draws that gave a result), an ordering "
    "when it holds in at least half of them; the kinds only say which rows are shown. "
    "Estimated from N draws, that range holds a new draw with probability about 87 % at "
    "N = 20, 90 % at N = 30 and 93 % at N = 100 (the percentiles interpolate between the "
    "extreme draws): Paper A's heterogeneous studies use N = 100, Table 2's N = 30 draws of "
    "the eleven starts each (330 fits)"
)


def compare_draws(
    spec: PaperSpec,
    draws: Sequence[Mapping[str, float]],
    status: str = "",
    success: bool = True,
) -> list[Comparison]:
    """One :class:`Comparison` per value of ``spec``, judged over noise draws (``DRAWS_RULE``).

    ``draws``: the quantities of each draw that gave a result (at least one); fbia's number
    is the median over them, ``low``/``high`` the 2.5/97.5 % percentiles (an ordering: the
    median of the quantity and, as ``high``, the share of draws in which it holds).
    ``status``/``success``: of the draws as a whole; flagged, every judged row is "no".

    >>> spec = read_paper({"source": "A", "values": [
    ...     {"quantity": "E", "kind": "modulus", "paper": 506.0}]}, "s.toml")
    >>> row = compare_draws(spec, [{"E": e} for e in range(400, 621, 10)])[0]
    >>> row.agrees, row.fbia, round(row.low, 1), round(row.high, 1), row.n_draws
    (True, 510.0, 405.5, 614.5, 23)
    """
    if not draws:
        raise ValueError("compare_draws needs the quantities of at least one draw")
    flagged = (
        ""
        if status != "unreliable" and success
        else (f"the draws as a whole are flagged unreliable (status {status or 'unknown'})")
    )
    rows = []
    for k, v in enumerate(spec.values, start=1):
        at = f"{spec.where}: [[paper.values]] #{k}" if spec.where else f"[[paper.values]] #{k}"
        f = _over_draws(draws, v.quantity, f"{at} quantity")
        ok = f[np.isfinite(f)]
        med = float(np.median(ok)) if ok.size else math.nan
        low, high = (
            (float(np.percentile(ok, 2.5)), float(np.percentile(ok, 97.5)))
            if ok.size
            else (math.nan, math.nan)
        )
        p = v.paper
        abs_diff = med - p if p is not None and math.isfinite(med) else None
        rel_diff = abs_diff / abs(p) if abs_diff is not None and p else None
        agrees: bool | None
        if v.than is not None:
            key = "above" if v.above is not None else "below"
            g = _over_draws(draws, v.than, f"{at} {key}")
            holds = f > g if v.above is not None else f < g
            share = float(np.mean(holds & np.isfinite(f) & np.isfinite(g)))
            agrees = share >= 0.5
            ref = float(np.median(g[np.isfinite(g)])) if np.isfinite(g).any() else math.nan
            row = Comparison(v, med, None, None, agrees, ref, "", None, share, len(draws))
        else:
            agrees = (
                None
                if KINDS[v.kind].rule == "none"
                else (p is not None and bool(ok.size) and low <= p <= high)
            )
            row = Comparison(v, med, abs_diff, rel_diff, agrees, None, "", low, high, len(draws))
        if flagged and row.agrees is not None:
            row = replace(row, agrees=False, reason=flagged)
        rows.append(row)
    return rows


def _over_draws(draws: Sequence[Mapping[str, float]], name: str, where: str) -> np.ndarray:
    """The quantity ``name`` of every draw (NaN where a draw lacks it: no result there);
    a name that no draw has is a ConfigError listing the available ones."""
    if not any(name in q for q in draws):
        lookup({k: 0.0 for q in draws for k in q}, name, where)
    return np.array([q.get(name, math.nan) for q in draws], dtype=float)


def _num(x: float | None) -> float:
    assert x is not None  # read_paper and KINDS guarantee it for the rule
    return x


def verdict(rows: Sequence[Comparison]) -> tuple[int, int]:
    """(rows that agree, rows judged)."""
    judged = [r for r in rows if r.agrees is not None]
    return sum(bool(r.agrees) for r in judged), len(judged)
