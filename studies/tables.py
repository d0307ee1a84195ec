"""Plain-text tables of a study: the discrepancy at a point, any list of rows.

>>> rows = [{"observation": "inflow_rate=100", "measure": "cpp", "D": 0.0012,
...          "n_residuals": 81, "max_abs_r": 0.004}]
>>> print(format_table(rows))
observation      measure  D       n_residuals  max_abs_r
---------------  -------  ------  -----------  ---------
inflow_rate=100  cpp      0.0012  81           0.004
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..core.observation import Solution
from ..core.problem import InverseProblem

__all__ = ["discrepancy_rows", "format_table"]


# -- tables ------------------------------------------------------------------------------------
def discrepancy_rows(
    problem: InverseProblem, solution: Solution, measure_name: str = ""
) -> list[dict[str, Any]]:
    """One row per observation: measure, distance D, number of residuals, max |r|, RMS of r.

    The RMS of r is Paper A's err_res (eq. 25) for that observation alone.
    """
    name = measure_name or type(problem.measure).__name__
    rows = []
    for obs in problem.observations:
        simulated = solution.interface(obs.coordinate)
        r = np.asarray(problem.measure.residuals(simulated, obs), dtype=float).ravel()
        d = float(problem.measure.distance(simulated, obs))
        rows.append(
            {
                "observation": obs.label(),
                "measure": name,
                "D": d,
                "n_residuals": int(r.size),
                "max_abs_r": float(np.max(np.abs(r))) if r.size else math.nan,
                "rms_r": float(np.sqrt(np.mean(r**2))) if r.size else math.nan,
            }
        )
    return rows


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """A plain-text table with a header line; floats in 6 significant digits."""
    if not rows:
        return "(no rows)"
    cols = list(columns) if columns is not None else list(rows[0])
    cells = [[_fmt(row.get(c, "")) for c in cols] for row in rows]
    widths = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(cols)]
    lines = [
        "  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True)).rstrip(),
        "  ".join("-" * w for w in widths),
    ]
    for r in cells:
        lines.append("  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip())
    return "\n".join(lines)


def _fmt(value: Any) -> str:
    if isinstance(value, bool) or value is None:
        return "" if value is None else str(value)
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.6g}"
    return str(value)
