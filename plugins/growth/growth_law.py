"""Surface growth law of Paper A, eq. 9, at the interface vertices.

.. math::

    \\mathbf d_g = \\Delta t_g \\bigl(K_{1g}\\, h - K_{2g}\\, |\\mathbf t\\cdot\\mathbf n|
                   - K_{3g}\\, |\\mathbf t\\cdot\\boldsymbol\\tau|\\bigr)\\,\\mathbf n

with ``n`` the unit normal out of the biofilm, ``tau`` the unit tangent (one in 2-D), ``h`` the
nutrient flux *into* the biofilm [mol/(mm^2 s)] (Paper A eq. 7) and ``t = sigma^F n`` the
traction the fluid exerts on the biofilm.  Only ``|t.n|`` and ``|t.tau|`` enter, so the sign
conventions of ``t`` and ``tau`` do not matter; a positive bracket grows the biofilm outwards,
a negative one erodes it.

Units of eq. 9 (issue 15, point 4)
----------------------------------
Paper A gives K1g [mm^3/mol], K2g and K3g [mm^2 s/g].  With ``h`` a flux density and ``t`` a
traction density [Pa = g/(mm s^2)] every term is a velocity, mm^3/mol * mol/(mm^2 s) = mm/s and
mm^2 s/g * g/(mm s^2) = mm/s, times ``dt_g`` [s] a length: **the stated units are those of the
density reading and are dimensionally consistent**.  The magnitudes are not, for the paper's
growth example (channel 0.6 x 0.3 mm, inflow 0.1 mm^2/s, mu = 1e-3 g/(mm s), dt_g = 1 day =
86400 s, K1g, K2g, K3g = 6e4, 5e-2, 8e-2):

* nutrient: Phi_in = 2.5e-11 mol/mm^3 >> K2R, and the zero-order penetration depth
  sqrt(2 D Phi_in / K1R) = 0.065 mm exceeds the finger's half width 0.02 mm, so the whole
  finger (area 3.8e-3 mm^2) consumes K1R = 3e-11 mol/(mm^3 s): 1.15e-13 mol/s per mm of depth
  through 0.223 mm of interface, h ~ 5.2e-13 mol/(mm^2 s) (less where the boundary layer
  starves it) and K1g h dt_g ~ **2.7 um per day**;
* traction: the wall shear of the Poiseuille flow 6 mu Q / H^2 = 6.7e-3 Pa gives
  K2g |t| dt_g = 5e-2 * 6.7e-3 * 86400 = **29 mm** and K3g: **46 mm per day**, 1e4 times the
  growth and 300 times the finger: erosion would wipe the biofilm out in the first step.

The numbers balance if, as issue 15 reports of the code that produced the paper, the
traction in eq. 9 is the *nodal force* of the quasi-2-D mesh, the traction times the area
of the node, ``F = t A`` [g mm/s^2].  Then eq. 9 reads
``dt_g (K1g h - K2g |F.n| - K3g |F.tau|) n`` with K2g, K3g in s/g, numerically the paper's
values (with the stated mm^2 s/g it would give mm^3: the paper's units belong to the density
reading, its numbers to the nodal-force one).  So that the law does not depend on the user's
mesh, :func:`growth_displacement` uses a *stated* node area
(unless ``nodal_area`` is given)::

    A = NODE_LENGTH * THICKNESS / 2 = 0.002 mm * 0.01 mm / 2 = 1e-5 mm^2

(the channel is 0.01 mm thick and meshed one hexahedron thick, so two nodes share the
thickness; a node carries 2 um of interface, the finger width over 20 -- the paper does not
publish its mesh, so this length is our choice, made as follows).  ``ale_fsi`` on the example
(:func:`~fbia.plugins.growth.geometry.finger_channel`, steady, inflow 0.1 mm^2/s, E = 100 Pa,
nu = 0.3, pressure zero at the outflow; mesh sizes 0.06 / 0.01 mm) gives on the finger:
|t.n| = 0.047-0.060 Pa on the upstream side (mostly pressure), |t.tau| up to 0.040 Pa over
the tip, below 0.008 Pa on the downstream side, and an FSI displacement of the interface up
to 2.1 um.  Per day, with A:

===================================  ==========  ==============  ==============
term                                  upstream    tip             downstream
===================================  ==========  ==============  ==============
growth K1g h dt_g (h ~ 5.2e-13)       2.7 um      2.7 um          2.7 um (less)
erosion K2g |t.n| A dt_g              2.0-2.6 um  0.05-2.6 um     < 0.35 um
erosion K3g |t.tau| A dt_g            < 0.3 um    up to 2.8 um    < 0.4 um
===================================  ==========  ==============  ==============

so growth and erosion balance upstream, growth wins downstream and erosion shows over the tip
-- Paper A's description of Fig. 21 -- and growth, erosion and the FSI displacement are all
of the order of microns: "the changes in biofilm geometry due to displacements and due to
growth range in the same order of magnitude".  With ``A = 1e-4 mm^2`` (a node carrying 0.01
mm, the full thickness) the erosion would be 10 times the growth and remove the upstream side
in one day; with ``traction_measure="density"`` 1e5 times.  Coefficients calibrated with one
area are not transferable to another: K2g, K3g scale as 1/A.

``traction_measure="density"`` keeps the literal reading (t in Pa, K2g, K3g in mm^2 s/g).
``|t.n|`` contains the fluid pressure, whose gauge (zero at the outflow in ``ale_fsi``) is a
modelling choice the erosion depends on.

>>> import numpy as np
>>> c = GrowthCoefficients(k1g=6e4, k2g=5e-2, k3g=8e-2)
>>> n = np.array([[0.0, 1.0]])
>>> d = growth_displacement(n, np.array([5e-13]), np.zeros((1, 2)), c, 86400.0)
>>> print(f"{d[0, 1] * 1e3:.2f} um")
2.59 um
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: Thickness of Paper A's quasi-2-D channel (mm).
THICKNESS = 0.01
#: Interface length (mm) a node of the quasi-2-D mesh is taken to carry (stated, not the mesh's).
NODE_LENGTH = 0.002
#: Node area (mm^2) of the ``"nodal_force"`` measure unless ``nodal_area`` is given: two nodes
#: through the thickness (one hexahedron thick), each carrying ``NODE_LENGTH`` of interface.
NODE_AREA = NODE_LENGTH * THICKNESS / 2
#: One day (s): Paper A's growth period.
DAY = 86400.0
TRACTION_MEASURES = ("nodal_force", "density")


@dataclass(frozen=True)
class GrowthCoefficients:
    """Coefficients of eq. 9: K1g [mm^3/mol] (growth by nutrient flux), K2g and K3g (erosion by
    normal and tangential traction; mm^2 s/g with a traction density, s/g with a nodal force)."""

    k1g: float
    k2g: float
    k3g: float


def growth_displacement(
    normals: ArrayLike,
    flux: ArrayLike,
    traction: ArrayLike,
    coeffs: GrowthCoefficients,
    dt_g: float,
    traction_measure: str = "nodal_force",
    nodal_area: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Growth displacement (mm) of the interface vertices by eq. 9 of Paper A.

    Parameters
    ----------
    normals
        (n, 2) unit normals out of the biofilm at the vertices.
    flux
        (n,) nutrient flux into the biofilm, mol/(mm^2 s).
    traction
        (n, 2) traction density the fluid exerts on the biofilm, Pa = g/(mm s^2).
    coeffs
        K1g, K2g, K3g.
    dt_g
        Growth time step, s.
    traction_measure
        ``"nodal_force"`` (default): the erosion terms use the nodal force ``traction *
        nodal_area`` (module docstring); ``"density"``: the traction itself.
    nodal_area
        (n,) or scalar node area in mm^2 for ``"nodal_force"``; default :data:`NODE_AREA`
        (stated, independent of the mesh).  Ignored for ``"density"``.
    """
    n = np.asarray(normals, dtype=float)
    h = np.asarray(flux, dtype=float)
    t = np.asarray(traction, dtype=float)
    if n.ndim != 2 or n.shape[1] != 2:
        raise ValueError(f"normals must have shape (n, 2), got {n.shape}")
    if h.shape != (len(n),) or t.shape != n.shape:
        raise ValueError(
            f"flux {h.shape} and traction {t.shape} must match normals {n.shape} as (n,), (n, 2)"
        )
    if traction_measure == "nodal_force":
        area = NODE_AREA if nodal_area is None else np.asarray(nodal_area, dtype=float)
        t = t * np.reshape(area, (-1, 1)) if np.ndim(area) else t * float(area)
    elif traction_measure != "density":
        raise ValueError(
            f"traction_measure must be one of {TRACTION_MEASURES}, got {traction_measure!r}"
        )
    tau = np.c_[n[:, 1], -n[:, 0]]
    t_n = np.abs(np.einsum("ij,ij->i", t, n))
    t_t = np.abs(np.einsum("ij,ij->i", t, tau))
    rate = coeffs.k1g * h - coeffs.k2g * t_n - coeffs.k3g * t_t
    return np.asarray(dt_g * rate[:, None] * n, dtype=float)
