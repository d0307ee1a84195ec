"""Does a higher initial porosity soften fbia's poroelastic biofilm? (issue 26)

    python examples/paper_a/poroelastic/porosity_stiffness.py     # about 1 min on 2 cores

Paper A explains both of its poroelastic findings (orange drifts to the bound phi_max = 0.9,
green needs 27 steps against blue's 9) by one property of its model: "higher porosity, due to
the interplay between porosity and Young's modulus, also lowers the effective stiffness of the
porous medium", so that E and phi0 trade along a valley that leads to the porosity bound.
fbia's paths show no such valley (orange converges, green takes 6 steps).  This script
measures the property itself in fbia's model (``study.toml``'s options): the interface's
displacement from the unloaded state at the inflow of the study, for phi0 from 0.25 to 0.9 at
E = 300 Pa, and for E from 200 to 400 Pa at phi0 = 0.25 for comparison.

With the thesis' eqs. 11-13 as written (which fbia implements), phi0 enters the skeleton's
stress only through the porosity penalty (eq. 13b, eta = 1 Pa against E = 300 Pa) and the
permeability's change with deformation: the reference permeability is K whatever phi0
(eq. 11 is K at J phi = phi0).  Output: the table on stdout.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

import fbia

HERE = Path(__file__).resolve().parent
CASES = [
    (300.0, 0.25),
    (300.0, 0.4),
    (300.0, 0.6),
    (300.0, 0.9),
    (200.0, 0.25),
    (350.0, 0.25),
    (400.0, 0.25),
]


def main() -> None:
    study = fbia.load_study(HERE / "study.toml", build=False)
    model = study.model
    assert study.synthetic is not None
    (coordinate,) = study.synthetic.coordinates
    reference = model.undeformed()
    print("| E [Pa] | phi0 | largest displacement [mm] | mean displacement [mm] |")
    print("|---|---|---|---|")
    for E, phi0 in CASES:
        with tempfile.TemporaryDirectory() as tmp:
            try:
                solution = model.solve({"E": E, "phi0": phi0}, [coordinate], Path(tmp))
            except fbia.ForwardModelError as err:  # a failed run is a row, not the end
                print(f"| {E:g} | {phi0:g} | failed: {err} | |", flush=True)
                continue
        u = np.linalg.norm(solution.interface(coordinate).vertices - reference.vertices, axis=1)
        print(f"| {E:g} | {phi0:g} | {u.max():.5f} | {u.mean():.5f} |", flush=True)


if __name__ == "__main__":
    main()
