r"""The poroelastic skeleton against the confined column in the small-strain limit.

Derivation.  A column ``0 <= y <= H`` between sliding walls (``d_x = 0`` on the sides), clamped
at the drained bottom and in contact with fluid at pressure ``p_top`` on top, carries a steady
downward Darcy flow: with constant permeability (small strain) ``div q = 0`` gives the linear
pore pressure ``p(y) = p_top y / H``.  In steady state eq. 10b turns the drag of eq. 10c into
``-grad p``, which cancels the pressure term, so the *total* stress is divergence free:
``d sigma_yy / dy = 0``, and the top traction gives ``sigma_yy = -p_top`` everywhere.

Linearise the mixture stress at ``F = I, phi = phi0`` with ``e = eps_yy = tr eps`` and the
change ``ds`` of the solid volume fraction ``s = J (1 - phi)``.  The constitutive relation
(eq. 12-13) ``p = -kappa (1/(1-phi0) - 1/s) - eta (1/(J phi) - 1/phi0)`` becomes
``p = -a ds + b (e - ds)`` with ``a = kappa / (1 - phi0)^2``, ``b = eta / phi0^2``, so
``ds = (b e - p) / (a + b)``.  The penalty stress ``eta (1/phi0 - 1/(J phi)) I ~ b (e - ds) I``
then equals ``K_p e I + (b / (a + b)) p I`` with ``K_p = a b / (a + b)``; together with the
pore-pressure part ``-p I`` and the neo-Hooke part ``lambda e I + 2 mu eps``:

    sigma_yy = (M + K_p) e - alpha p,   M = lambda + 2 mu,   alpha = a / (a + b)  (Biot).

Hence ``e(y) = (alpha p(y) - p_top) / (M + K_p)`` and, with ``d_y(0) = 0``,

    d_y(y) = p_top / (M + K_p) * (alpha y^2 / (2 H) - y),
    phi(y) = phi0 + (1 - phi0) e - ds.

Both are polynomials the P2 / P1 discretisation represents exactly, so what remains is the
geometric nonlinearity, O(p_top / M) relative: the relative error must fall ~10x when the load
falls 10x.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("xfem")

E, NU, PHI0, KAPPA, ETA = 300.0, 0.3, 0.25, 100.0, 1.0
H, WIDTH = 1.0, 0.2


def _column(p_top: float) -> tuple[list[float], list[float], float, float]:
    import ngsolve as ngs
    from netgen.occ import OCCGeometry, Rectangle, X, Y

    from fbia.plugins.cutfem_fpi.skeleton import Skeleton, SkeletonSettings

    ngs.SetNumThreads(1)
    face = Rectangle(WIDTH, H).Face()
    face.edges.Min(Y).name = "solid_fixed"
    face.edges.Max(Y).name = "interface"
    face.edges.Min(X).name = "side"
    face.edges.Max(X).name = "side"
    mesh = ngs.Mesh(OCCGeometry(face, dim=2).GenerateMesh(maxh=0.1))
    sk = Skeleton(
        mesh,
        SkeletonSettings(kappa=KAPPA, eta=ETA),
        fixed_x="solid_fixed|side",
        fixed_y="solid_fixed",
    )
    sk.set_material(E, NU, PHI0)
    sk.reset()
    sk.pressure.Set(p_top * ngs.y / H)
    assert sk.solve() <= 6
    mu = E / (2 * (1 + NU))
    lam = E * NU / ((1 + NU) * (1 - 2 * NU))
    a, b = KAPPA / (1 - PHI0) ** 2, ETA / PHI0**2
    alpha, kp = a / (a + b), a * b / (a + b)
    ys = [0.25, 0.5, 0.75, 1.0]
    num = [float(sk.displacement(mesh(0.1, yy))[1]) for yy in ys]
    exact = [p_top / (lam + 2 * mu + kp) * (alpha * yy**2 / (2 * H) - yy) for yy in ys]
    yy = 0.5
    e = p_top / (lam + 2 * mu + kp) * (alpha * yy / H - 1)
    ds = (b * e - p_top * yy / H) / (a + b)
    phi_exact = PHI0 + (1 - PHI0) * e - ds
    return num, exact, float(sk.porosity(mesh(0.1, yy))), phi_exact


def test_confined_column_small_strain_limit() -> None:
    errors = []
    for p_top in (0.03, 0.003):
        num, exact, phi, phi_exact = _column(p_top)
        err = max(abs(n - x) for n, x in zip(num, exact, strict=True)) / abs(exact[-1])
        errors.append(err)
        assert err < 3e-4
        assert (phi - PHI0) == pytest.approx(phi_exact - PHI0, rel=1e-3)
        assert phi > PHI0  # pore pressure opens the pores
    assert errors[1] < 0.2 * errors[0]  # the error is the geometric nonlinearity


def test_porosity_out_of_range_raises() -> None:
    """A pore pressure that would drive phi past 1 is a ForwardModelError, not a result."""
    from fbia.core.errors import ForwardModelError

    with pytest.raises(ForwardModelError, match="porosity|Newton|inverted"):
        _column(-400.0)


def _extension_errors(h: float) -> tuple[float, float]:
    import ngsolve as ngs

    from fbia.plugins.cutfem_fpi.meshes import biofilm_mesh
    from fbia.plugins.cutfem_fpi.model import POROELASTIC_OUTLINE
    from fbia.plugins.cutfem_fpi.skeleton import Skeleton, SkeletonSettings
    from fbia.plugins.fem.outlines import NAMED_OUTLINES

    mesh = biofilm_mesh(NAMED_OUTLINES[POROELASTIC_OUTLINE], True, h)
    sk = Skeleton(mesh, SkeletonSettings())
    sk.set_material(E, NU, PHI0)
    out = []
    # K = K0: harmonic, no flux through y = 0 -- and K(x) from phi = phi0 + b x: the flux
    # -K p' is constant for p = phi0^3 / (1 - phi0^2) / b * (-1 / (2 phi^2) - ln phi)
    b = 0.1
    phi = PHI0 + b * ngs.x
    cases = [
        (PHI0, ngs.cos(2 * ngs.x) * (ngs.exp(2 * ngs.y) + ngs.exp(-2 * ngs.y)) / 2),
        (phi, PHI0**3 / (1 - PHI0**2) / b * (-1 / (2 * phi**2) - ngs.log(phi))),
    ]
    for porosity, exact in cases:
        sk.reset()
        sk.porosity.Set(porosity)
        sk.pressure.Set(5.0)  # interior values are replaced
        sk.pressure.Set(exact, ngs.BND, definedon=mesh.Boundaries("interface"))
        sk.extend_pressure()
        err = ngs.sqrt(ngs.Integrate((sk.pressure - exact) ** 2, mesh, order=8))
        out.append(float(err) / float(ngs.sqrt(ngs.Integrate(exact**2, mesh, order=8))))
    return out[0], out[1]


def test_pore_pressure_inside_from_its_interface_values() -> None:
    """``extend_pressure``: steady Darcy ``-Div(K Grad p) = 0`` in the reference configuration
    with the interface values as data and no flux through the floor, K of eq. 11 from the
    current porosity.  Two exact solutions, a harmonic one (K uniform) and a 1-D one for a
    porosity growing along x, are reproduced at the third order of P2."""
    coarse, fine = _extension_errors(0.08), _extension_errors(0.04)
    for c, f in zip(coarse, fine, strict=True):
        assert f < 2e-5
        assert np.log2(c / f) > 2.5
