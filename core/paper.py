"""Published numbers beside fbia's: the ``[paper]`` table of a study file and its comparison.

A study that reproduces an example of a paper states, as data, what the paper reported and
what "agrees" means for each number::

    [paper]
    source = "Paper A, Table 2, row sigma = 1e-3 mm"
    note = "optional: what differs from the paper's set-up as a whole"

    [[paper.values]]
    quantity = "mean.E"        # a name the result exposes (Result.quantities())
    paper = 408.0              # the published value
    unit = "Pa"
    rule = "relative"          # what "agrees" means (RULES below); default relative
    tolerance = 0.05           # of the rule (relative: 5 %)
    label = "mean E"           # optional: how the report names the row
    why = "different noise draw: the optimum moves with the noise (Table 2)"

:func:`read_paper` checks the table (unknown keys, wrong types, a rule without the tolerance
it needs: one-line :class:`~fbia.core.errors.ConfigError` naming the file and the key) and
returns a :class:`PaperSpec`; :func:`compare` looks each quantity up in the result's
:meth:`~fbia.core.problem.Result.quantities` (an unknown name is a ConfigError that lists the
available ones) and returns one :class:`Comparison` per value.  :mod:`fbia.core.paper_report`
writes them as ``report.md`` and ``paper.json`` and composes the summary of many studies.

>>> spec = read_paper({"source": "Paper A", "values": [
...     {"quantity": "x.E", "paper": 400.0, "unit": "Pa", "tolerance": 0.01}]}, "s.toml")
>>> rows = compare(spec, {"x.E": 402.0, "x.nu": 0.3})
>>> rows[0].agrees, round(rows[0].rel_diff, 4)
(True, 0.005)
>>> compare(spec, {"x.nu": 0.3})                               # doctest: +ELLIPSIS
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: s.toml: [[paper.values]] #1 quantity: ... 'x.E'; available: x.nu
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

from .errors import ConfigError
from .study_schema import PaperSection, PaperValueSection, parse_section

__all__ = [
    "RULES",
    "Comparison",
    "PaperSpec",
    "PaperValue",
    "compare",
    "lookup",
    "read_paper",
    "verdict",
]

#: The rules and what "agrees" means under each (t: the tolerance, p: paper, f: fbia).
RULES: dict[str, str] = {
    "relative": "|f - p| <= t |p| (t required)",
    "absolute": "|f - p| <= t (t required)",
    "magnitude": "|log10(f / p)| <= t: the same order of magnitude (t default 1)",
    "equal": "f == p (counts, flags such as converged = 1)",
    "same_sign": "f and p have the same sign (0 counts as its own sign)",
    "above": "f > the result's quantity `than` (an ordering the paper states)",
    "below": "f < the result's quantity `than`",
    "none": "shown, not judged (a number the paper gives that fbia cannot reproduce in kind)",
}
_NEEDS_TOLERANCE = ("relative", "absolute")
_ORDERING = ("above", "below")


@dataclass(frozen=True)
class PaperValue:
    """One published number (or ordering) and what "agrees" means for it."""

    quantity: str
    paper: float | None
    unit: str
    rule: str
    tolerance: float | None
    than: str | None
    label: str
    why: str

    @property
    def name(self) -> str:
        """How the report names the row: the label, else the quantity."""
        return self.label or self.quantity

    def criterion(self) -> str:
        """The rule in a few words, e.g. ``within 5 %``."""
        t = self.tolerance
        if self.rule == "relative":
            return f"within {100 * (t or 0):g} %"
        if self.rule == "absolute":
            return f"within {t:g} {self.unit}".rstrip()
        if self.rule == "magnitude":
            return f"within a factor 10^{1.0 if t is None else t:g}"
        if self.rule in _ORDERING:
            return f"{'>' if self.rule == 'above' else '<'} {self.than}"
        return {"equal": "equal", "same_sign": "same sign", "none": "not judged"}[self.rule]


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

    ``agrees`` is None for rule ``none``; ``abs_diff``/``rel_diff`` are None where there is
    no published number or the relative difference is undefined (paper value 0).
    """

    value: PaperValue
    fbia: float
    abs_diff: float | None
    rel_diff: float | None
    agrees: bool | None
    reference: float | None = None  # the `than` quantity's value (rules above/below)

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
    values = []
    for k, item in enumerate(section.values, start=1):
        at = f"{file}: [[paper.values]] #{k}"
        v = parse_section(PaperValueSection, item, at)
        needs_paper = v.rule not in _ORDERING
        if needs_paper and v.paper is None:
            raise ConfigError(f"rule {v.rule!r} needs the published value 'paper'", at)
        if v.rule in _NEEDS_TOLERANCE and v.tolerance is None:
            raise ConfigError(f"rule {v.rule!r} needs a 'tolerance'", at)
        if v.tolerance is not None and v.rule not in (*_NEEDS_TOLERANCE, "magnitude"):
            raise ConfigError(f"rule {v.rule!r} takes no 'tolerance'", f"{at} tolerance")
        if v.rule in _ORDERING and v.than is None:
            raise ConfigError(f"rule {v.rule!r} needs 'than' (the quantity to compare with)", at)
        if v.than is not None and v.rule not in _ORDERING:
            raise ConfigError(f"'than' only for the rules above and below, not {v.rule!r}", at)
        if v.rule == "magnitude" and v.paper is not None and not v.paper > 0:
            raise ConfigError(f"rule 'magnitude' needs a positive paper value, got {v.paper}", at)
        values.append(
            PaperValue(
                quantity=v.quantity,
                paper=v.paper,
                unit=v.unit,
                rule=v.rule,
                tolerance=v.tolerance,
                than=v.than,
                label=v.label,
                why=" ".join(v.why.split()),
            )
        )
    return PaperSpec(section.source, " ".join(section.note.split()), tuple(values), file)


def lookup(quantities: Mapping[str, float], name: str, where: str = "") -> float:
    """``quantities[name]``, else a ConfigError that lists the available names."""
    if name in quantities:
        return float(quantities[name])
    available = ", ".join(sorted(quantities)) or "(none)"
    raise ConfigError(f"the result has no quantity {name!r}; available: {available}", where)


def compare(spec: PaperSpec, quantities: Mapping[str, float]) -> list[Comparison]:
    """One :class:`Comparison` per value of ``spec``, fbia's number from ``quantities``."""
    rows = []
    for k, v in enumerate(spec.values, start=1):
        at = f"{spec.where}: [[paper.values]] #{k}" if spec.where else f"[[paper.values]] #{k}"
        f = lookup(quantities, v.quantity, f"{at} quantity")
        ref = lookup(quantities, v.than, f"{at} than") if v.than is not None else None
        rows.append(_judge(v, f, ref))
    return rows


def _judge(v: PaperValue, f: float, ref: float | None) -> Comparison:
    p = v.paper
    abs_diff = rel_diff = None
    if p is not None and math.isfinite(f):
        abs_diff = f - p
        rel_diff = abs_diff / abs(p) if p != 0 else None
    agrees: bool | None
    if not math.isfinite(f):
        agrees = None if v.rule == "none" else False
    elif v.rule == "relative":
        agrees = abs(f - _num(p)) <= _num(v.tolerance) * abs(_num(p))
    elif v.rule == "absolute":
        agrees = abs(f - _num(p)) <= _num(v.tolerance)
    elif v.rule == "magnitude":
        t = 1.0 if v.tolerance is None else v.tolerance
        agrees = f > 0 and abs(math.log10(f / _num(p))) <= t
    elif v.rule == "equal":
        agrees = f == p
    elif v.rule == "same_sign":
        agrees = _sign(f) == _sign(_num(p))
    elif v.rule in _ORDERING:
        r = _num(ref)
        agrees = math.isfinite(r) and (f > r if v.rule == "above" else f < r)
    else:
        agrees = None
    return Comparison(v, f, abs_diff, rel_diff, agrees, ref)


def _num(x: float | None) -> float:
    assert x is not None  # read_paper guarantees it for the rule
    return x


def _sign(x: float) -> int:
    return (x > 0) - (x < 0)


def verdict(rows: Sequence[Comparison]) -> tuple[int, int]:
    """(rows that agree, rows judged)."""
    judged = [r for r in rows if r.agrees is not None]
    return sum(bool(r.agrees) for r in judged), len(judged)
