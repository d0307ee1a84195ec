"""The solid's material laws: Lame parameters and the second Piola-Kirchhoff stress
(Saint Venant-Kirchhoff, thesis eq. 2.15; neo-Hooke, eq. 2.18), plane strain in 2-D, and in 3-D."""

from __future__ import annotations

from typing import Any

__all__ = ["lame", "stress_pk2"]


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lame parameters from Young's modulus and Poisson's ratio (thesis eq. 2.16)."""
    mu = E / (2.0 * (1.0 + nu))
    lam = nu * E / ((1.0 + nu) * (1.0 - 2.0 * nu))
    return mu, lam


def stress_pk2(material: str, F: Any, mu: Any, lam: Any) -> Any:
    """Second Piola-Kirchhoff stress of the solid (plane strain for a 2x2 ``F``, else 3-D).

    SVK, eq. 2.15: ``S = lam tr(E) I + 2 mu E`` with ``E = (F^T F - I)/2``;
    neo-Hooke, eq. 2.18: ``S = mu (I - C^-1) + lam ln(J) C^-1`` with ``C = F^T F``.
    """
    import ngsolve as ngs

    identity = ngs.Id(F.dims[0])
    C = F.trans * F
    if material == "svk":
        E = 0.5 * (C - identity)
        return lam * ngs.Trace(E) * identity + 2.0 * mu * E
    if material == "neo_hooke":
        Cinv = ngs.Inv(C)
        return mu * (identity - Cinv) + lam * ngs.log(ngs.Det(F)) * Cinv
    raise ValueError(f"unknown material {material!r}")
