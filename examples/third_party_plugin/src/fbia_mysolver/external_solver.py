"""Stand-in for an external solver binary: reads an input JSON, writes one CSV per state.

Run as ``python external_solver.py input.json`` in the run's folder.  It uses the standard
library only, as a compiled solver would use none of fbia.  Replace it by your own program;
the file protocol is all the plugin relies on:

input JSON::

    {"parameters": {"E": 400.0, "nu": 0.3},
     "settings": {"n_points": 61},
     "states": [{"coordinate": {"inflow_rate": 100.0}, "output": "interface_000.csv"}, ...]}

output: for every state a CSV file ``output`` with a header ``x,y`` and one interface point
per row [mm], ordered from the upstream to the downstream foot of the biofilm.  Exit status 0
on success; otherwise a message on stderr and status 2 (bad input) or 3 (diverged).

The "physics" (mm, s, g; stresses in Pa): a mound ``y0 = h sin^2(pi (x - x_l) / w)`` of height
h = 0.3 mm on the footprint [0.7, 1.3] mm in a channel of height H = 1 mm, loaded by the wall
shear stress of plane Poiseuille flow through the gap above it, ``tau = 6 mu q / (H - h)^2``
(mu = 1e-3 Pa s, q the inflow rate in mm^2/s), with G = E / (2 (1 + nu)) and
K = E / (3 (1 - 2 nu)):

    u_x = 20 (tau / G) y0^2 / h,    u_y = -10 (tau / K) y0                    [mm]

A crest displacement u_x(h) above h / 2 counts as mesh distortion: status 3.
"""

from __future__ import annotations

import csv
import json
import math
import sys

HEIGHT = 0.3  # mm
CHANNEL_HEIGHT = 1.0  # mm
FOOT_LEFT, FOOT_WIDTH = 0.7, 0.6  # mm
VISCOSITY = 1e-3  # Pa s = g/(mm s)
LEAN_GAIN, SQUASH_GAIN = 20.0, 10.0  # stand-in gains [-]


def deformed(E: float, nu: float, q: float, n: int) -> list[tuple[float, float]]:
    """Interface points [mm] at Young's modulus E [Pa], Poisson's ratio nu, inflow rate q."""
    tau = 6.0 * VISCOSITY * q / (CHANNEL_HEIGHT - HEIGHT) ** 2
    shear = E / (2.0 * (1.0 + nu))
    bulk = E / (3.0 * (1.0 - 2.0 * nu))
    lean = LEAN_GAIN * tau / shear * HEIGHT
    if abs(lean) > 0.5 * HEIGHT:
        raise ArithmeticError(
            f"mesh distortion: crest displacement {lean:.3g} mm exceeds {0.5 * HEIGHT} mm "
            f"(E = {E} Pa too soft for q = {q} mm^2/s)"
        )
    points = []
    for k in range(n):
        x = FOOT_LEFT + FOOT_WIDTH * k / (n - 1)
        y = HEIGHT * math.sin(math.pi * k / (n - 1)) ** 2
        points.append((x + lean * (y / HEIGHT) ** 2, y - SQUASH_GAIN * tau / bulk * y))
    return points


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print("usage: external_solver.py input.json", file=sys.stderr)
        return 2
    try:
        with open(argv[1]) as fh:
            job = json.load(fh)
        E, nu = float(job["parameters"]["E"]), float(job["parameters"]["nu"])
        n = int(job["settings"]["n_points"])
    except (OSError, KeyError, TypeError, ValueError) as exc:
        print(f"bad input {argv[1]}: {exc!r}", file=sys.stderr)
        return 2
    if not (E > 0.0 and -1.0 < nu < 0.5 and n >= 3):
        print(f"bad input: E = {E} Pa, nu = {nu}, n_points = {n}", file=sys.stderr)
        return 2
    for state in job["states"]:
        q = float(state["coordinate"].get("inflow_rate", 100.0))
        print(f"solving E = {E} Pa, nu = {nu}, q = {q} mm^2/s")
        try:
            points = deformed(E, nu, q, n)
        except ArithmeticError as exc:
            print(str(exc), file=sys.stderr)
            return 3
        with open(state["output"], "w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(["x", "y"])
            writer.writerows((repr(x), repr(y)) for x, y in points)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
