"""The named biofilm outlines of the 2-D flow cell (the ``outline`` option takes a name).

``"fig2_sketch"`` (the default) is fbia's outline drawn after Paper A Fig. 2 by eye: it fills
about half of the channel height and overhangs on the downstream side, while the downstream
foot meets the floor almost at a right angle (an acute fluid wedge there inverts ALE
elements).  Against the facts the thesis publishes about its own mound it is off: largest
displacement 0.0454 mm at E = 400 Pa, nu = 0.3, 100 mm^2/s (thesis: ~5.3e-2 mm), 91 interface
vertices at the default 0.03 mm (Paper B: n_in = 66), and the blue Table 1 start
(200 Pa, 0.4) has no steady state beyond 97.7 mm^2/s.

An outline derived from the published facts (issue 26) is not found yet.  What was measured
(``benchmarks/flow_cell_outline.py`` prints these figures for any candidate; Saint
Venant-Kirchhoff, the default mesh):

- In every one of about 45 candidate outlines from 8 families (scaled fig2_sketch, gentle
  feet, no overhang, symmetric, steep upstream face, waisted, mushroom; heights set by
  bisection so that the largest displacement at the truth is 0.053 mm) the steady branch
  ends (a limit point: SVK softens in compression, det F 0.3 to 0.7 at a concave spot) where
  the largest displacement reaches about 0.10 mm, twice the truth's; E = 200 Pa gives about
  that, so the blue and orange starts sit at the edge in all.
- Outlines without a waist keep the thesis' E-nu band (the largest displacement grows with
  nu: 0.0341, 0.0454, 0.0517 mm at nu = 0, 0.3, 0.45 for ``fig2_sketch``; Paper B: "an
  underestimation of E is coupled to an underestimation of nu"), but their branch at
  200 Pa, nu = 0.4 ends below 100 mm^2/s (85-98 mm^2/s).
- Waisted outlines (a cap on a narrower neck) carry 200 Pa at nu = 0 and 0.4 (the lowest
  E with a steady state: 190 Pa at nu = 0, 150 Pa at nu = 0.4 for the best), but the deeper
  the waist, the flatter or reversed the nu trend (0.0531, 0.0530, 0.0493 mm at
  nu = 0, 0.3, 0.45): the fit then pulls the blue start to nu -> 0.5, where Paper A's
  algorithm stops at the bound (measured: blue ends with damping_limit at nu = 0.499).
  On a mesh with interface size 0.015 mm, orange (200 Pa, 0.0) fails on that outline too.

So no outline among those tried meets all of: 0.053 mm at the truth, the thesis' sign of the
E-nu band, and steady states at both 200 Pa starts.  The candidates and their figures are in
the benchmark; the next step is a wider family (or a measured reason why the thesis' coarse
linear elements carried 200 Pa: they do not resolve the compressed concave spot).
"""

from __future__ import annotations

from typing import Literal

Point = tuple[float, float]

#: fbia's outline (mm) after Paper A Fig. 2, upstream foot -> top -> downstream foot.
FIG2_SKETCH_OUTLINE: tuple[Point, ...] = (
    (0.50, 0.00),
    (0.55, 0.11),
    (0.64, 0.27),
    (0.78, 0.41),
    (0.94, 0.48),
    (1.08, 0.46),
    (1.18, 0.39),
    (1.22, 0.30),
    (1.21, 0.21),
    (1.18, 0.13),
    (1.17, 0.06),
    (1.17, 0.00),
)

OutlineName = Literal["fig2_sketch"]

#: name -> outline (mm)
NAMED_OUTLINES: dict[str, tuple[Point, ...]] = {"fig2_sketch": FIG2_SKETCH_OUTLINE}

DEFAULT_OUTLINE_NAME: OutlineName = "fig2_sketch"

#: the default outline's points (mm)
DEFAULT_OUTLINE = NAMED_OUTLINES[DEFAULT_OUTLINE_NAME]


def resolve_outline(outline: str | list[Point] | tuple[Point, ...] | None) -> tuple[Point, ...]:
    """The points of an ``outline`` option: a name, the points themselves, or None (default)."""
    if outline is None:
        outline = DEFAULT_OUTLINE_NAME
    if isinstance(outline, str):
        return NAMED_OUTLINES[outline]
    return tuple((float(x), float(y)) for x, y in outline)
