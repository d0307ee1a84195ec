"""The named biofilm outlines of the 2-D flow cell (the ``outline`` option takes a name).

``"paper_a_facts"`` (the default) is derived from what the thesis publishes about its mound,
which it calls "arbitrary, inspired by experiments" and gives no coordinates of (issue 26):

1. the largest displacement at E = 400 Pa, nu = 0.3, 100 mm^2/s is ~5.3e-2 mm (Paper A, text
   below Table 1): fbia 0.0528 mm (-0.4 %);
2. the likelihood's E-nu band: "an underestimation of E is coupled to an underestimation of
   nu" (Paper B), i.e. the largest displacement grows with nu at fixed E: 0.0431, 0.0528,
   0.0579 mm at nu = 0, 0.3, 0.45;
3. failures only for soft material (Paper B), and the Table 1 starts at 200 Pa ran: the
   lowest E with a steady state at 100 mm^2/s is 150 Pa at nu = 0 and 140 Pa at nu = 0.4;
4. all eleven Table 1 starts have a steady state;
5. n_in = 66 interface nodes (Paper B): 67 at the outline's interface element size
   0.057 mm (netgen gives 65 or 67 near it, never 66) -- the size the flow cell uses for this
   outline unless ``interface_mesh_size`` is given (:data:`OUTLINE_MESH_SIZES`).

(Saint Venant-Kirchhoff, quasi-static, the default mesh otherwise;
``benchmarks/flow_cell_outline.py`` prints these figures for any outline.)  How it was found:
about 45 candidates from 8 families (scaled ``fig2_sketch``, gentle feet, no overhang,
symmetric, steep upstream face, waisted, mushroom), each with its height set by bisection for
fact 1, all failed fact 3 or fact 2: the steady branch ends at a limit point (SVK softens in
compression, det F 0.3-0.7 at a concave spot) at about 0.10 mm, twice the truth's, so the
200 Pa starts sit at the edge; a waist carries 200 Pa but reverses the nu trend, the more so
upstream (an upstream-only waist: spread d(0.45) - d(0) = +0.0007 mm; downstream-only
+0.0123 mm).  What moves the limit point is a **downstream lean** of the cap (x shifted by
lean * w * y / h): it turns the upstream face into a ramp, so that at nu = 0.4 the branch
reaches 0.145-0.16 mm (lowest E, no upstream waist, downstream waist 0.6, w = 0.9 mm: 250,
210, 180, 150 Pa at lean 0, 0.15, 0.3, 0.45 at nu = 0.4), while a moderate downstream waist
keeps the nu = 0 displacement at 200 Pa near 0.08 mm.  ``paper_a_facts`` is that shape
(lean 0.45, footprint 0.5-1.4 mm, height fitted to 0.5036 mm); its cap overhangs the
downstream foot by 0.09 mm, as the mound of Paper A Fig. 2 does.  Coarser or finer meshes move
its limit by 10-20 Pa (interface 0.015 mm: 160/170 Pa; 0.06 mm: 150/140 Pa).

``"fig2_sketch"`` is fbia's earlier outline, drawn after Paper A Fig. 2 by eye: largest
displacement 0.0454 mm at the truth, 91 interface vertices at 0.03 mm, and the blue start
(200 Pa, 0.4) has no steady state beyond 97.7 mm^2/s.
"""

from __future__ import annotations

from typing import Literal

Point = tuple[float, float]

#: the outline derived from the thesis' published facts (mm), upstream foot -> downstream foot
PAPER_A_FACTS_OUTLINE: tuple[Point, ...] = (
    (0.5, 0.0),
    (0.5846, 0.0604),
    (0.747, 0.1763),
    (0.923, 0.3022),
    (1.1345, 0.4532),
    (1.355, 0.5036),
    (1.4945, 0.4532),
    (1.3928, 0.3022),
    (1.3106, 0.1763),
    (1.3694, 0.0604),
    (1.4, 0.0),
)

#: fbia's earlier outline (mm) after Paper A Fig. 2, upstream foot -> top -> downstream foot.
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

OutlineName = Literal["paper_a_facts", "fig2_sketch"]

#: name -> outline (mm)
NAMED_OUTLINES: dict[str, tuple[Point, ...]] = {
    "paper_a_facts": PAPER_A_FACTS_OUTLINE,
    "fig2_sketch": FIG2_SKETCH_OUTLINE,
}

#: name -> the interface element size (mm) the flow cell uses for it when none is given
OUTLINE_MESH_SIZES: dict[str, float] = {"paper_a_facts": 0.057, "fig2_sketch": 0.03}

#: the interface element size (mm) of an outline given as points, and of 3-D geometries
DEFAULT_INTERFACE_MESH_SIZE = 0.03

DEFAULT_OUTLINE_NAME: OutlineName = "paper_a_facts"

#: the default outline's points (mm)
DEFAULT_OUTLINE = NAMED_OUTLINES[DEFAULT_OUTLINE_NAME]


def resolve_outline(outline: str | list[Point] | tuple[Point, ...] | None) -> tuple[Point, ...]:
    """The points of an ``outline`` option: a name, the points themselves, or None (default)."""
    if outline is None:
        outline = DEFAULT_OUTLINE_NAME
    if isinstance(outline, str):
        return NAMED_OUTLINES[outline]
    return tuple((float(x), float(y)) for x, y in outline)


def outline_mesh_size(outline: str | list[Point] | tuple[Point, ...] | None) -> float:
    """The interface element size (mm) for an ``outline`` option when none is given: a named
    outline's own (:data:`OUTLINE_MESH_SIZES`), else :data:`DEFAULT_INTERFACE_MESH_SIZE`."""
    if outline is None:
        outline = DEFAULT_OUTLINE_NAME
    if isinstance(outline, str):
        return OUTLINE_MESH_SIZES[outline]
    return DEFAULT_INTERFACE_MESH_SIZE
