"""Closed-form load and response of a biofilm mound in a flow cell (shared by 2-D and 3-D).

The analytic mound models stand in for the FSI forward model of Paper A ("Physical models",
homogeneous example, Fig. 2-3) and Paper B ("Problem setup", Fig. 2-4): a soft mound on the
floor of a channel, loaded by the flow, leans downstream and is flattened.  Units: mm, s, g;
stresses in Pa = g/(mm s^2); 2-D inflow rate q in mm^2/s.

Fluid load (a characteristic interface stress, Pa).  The flow squeezes through the gap
``g = H - h`` between the mound crest (height h) and the channel lid (height H); plane
Poiseuille flow of the rate ``q`` through that gap gives a wall shear stress and a pressure
drop along the mound footprint ``w``::

    tau_w   = 6 mu q / g^2                     [Pa]
    dp      = 12 mu q w / g^3                  [Pa]
    sigma_f = s (tau_w + dp)                   [Pa]   (s: dimensionless ``load_scale``)

With water (mu = 1e-3 g/(mm s)), q = 100 mm^2/s, H = 1 mm, h = 0.5 mm, w = 0.8 mm:
tau_w = 2.4 Pa, dp = 7.68 Pa, sigma_f = 10.08 Pa.

Moduli (Saint-Venant-Kirchhoff at small strain): ``G = E / (2 (1 + nu))``,
``K = E / (3 (1 - 2 nu))`` and ``1/E = 1/(3 G) + 1/(9 K)``.

Response: two distinct shape features, both saturating (tanh) with the load so that no
parameter combination inverts the load-deformation curve, and both exactly zero at zero load:

* lean (bending of the bonded mound; Euler-Bernoulli bending is governed by E)::

      delta = h tanh(C_B sigma_f / E)                                [mm]   C_B = 6

  the crest moves downstream by ``delta`` (upstream if the flow is reversed);
* flattening (volumetric compression under the normal tractions, governed by K)::

      eps = EPS_MAX tanh(C_V |sigma_f| / K)                          [-]    C_V = 3, EPS_MAX = 0.5

  the mound loses height by the strain ``eps`` and contracts laterally towards its crest by
  the same strain, fading to zero at the bonded footing.

E sets both features (coupling); the ratio of flattening to lean, ~ E/K = 3 (1 - 2 nu), sets
nu (identifiability).  Lower E increases both; lower nu increases the flattening and leaves the
lean unchanged, so a softer or a more auxetic mound both deform more (Paper A, homogeneous
example: "quite similar surfaces can be obtained via large bending due to a low value for E or
by lateral deformation resulting from negative nu").  The gains C_B, C_V are chosen so that at
E = 400 Pa, nu = 0.3, q = 100 mm^2/s the crest moves by about 0.08 mm, the order of the
maximum displacement 5.3e-2 mm of Paper A's reference result.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self

import numpy as np
from pydantic import Field, model_validator

from ...core.errors import ConfigError, ForwardModelError
from ...core.interface import Interface
from ...core.observation import Solution
from ...core.options import PluginOptions
from ...core.protocols import ForwardModelBase

#: Gain of the lean (bending) response, C_B [-].
BENDING_GAIN = 6.0
#: Gain of the flattening (volumetric) response, C_V [-].
VOLUMETRIC_GAIN = 3.0
#: Largest flattening strain, EPS_MAX [-].
MAX_FLATTENING = 0.5

#: Model inputs the analytic mound models know, in the order of ``parameter_names()``.
PARAMETER_NAMES = ("E", "nu", "inflow_rate", "load_scale")
#: Coordinate keys a state may carry.
COORDINATE_KEYS = ("inflow_rate",)


class MoundOptions(PluginOptions):
    """Options shared by the 2-D and 3-D analytic mound models."""

    E: float = Field(400.0, gt=0, description="Young's modulus used when not given [Pa]")
    nu: float = Field(0.3, gt=-1.0, lt=0.5, description="Poisson's ratio used when not given [-]")
    inflow_rate: float = Field(
        100.0,
        description="inflow rate used when neither the coordinate nor the parameters give one "
        "[mm^2/s in 2-D; mm^3/s through the channel cross-section in 3-D]",
    )
    load_scale: float = Field(
        1.0, description="multiplier of the fluid load when not given as a parameter [-]"
    )
    viscosity: float = Field(
        1e-3, gt=0, description="fluid dynamic viscosity [g/(mm s) = Pa s]; water: 1e-3"
    )
    channel_height: float = Field(1.0, gt=0, description="channel height H [mm]")
    height: float = Field(0.5, gt=0, description="crest height h of the undeformed mound [mm]")
    crest_shift: float = Field(
        0.05,
        description="downstream shift of the crest against the footprint centre, a slight "
        "downstream lean of the grown mound [mm]; |crest_shift| < footprint/4",
    )
    failure_region: dict[str, tuple[float, float]] | None = Field(
        None,
        description="simulated failure: solve() raises ForwardModelError ('mesh distortion') "
        "when every named parameter lies in its [lo, hi] (units of the parameter)",
    )
    write_fields: bool = Field(
        False, description="write each state's interface into the work folder (CSV 2-D, VTU 3-D)"
    )

    @model_validator(mode="after")
    def _check_mound(self) -> Self:
        if self.height >= self.channel_height:
            raise ValueError(
                f"mound height {self.height} mm must be below the channel height "
                f"{self.channel_height} mm"
            )
        if self.failure_region is not None:
            for name, (lo, hi) in self.failure_region.items():
                if name not in PARAMETER_NAMES:
                    raise ValueError(
                        f"failure_region names unknown parameter {name!r}; "
                        f"valid: {', '.join(PARAMETER_NAMES)}"
                    )
                if not lo <= hi:
                    raise ValueError(f"failure_region[{name!r}] needs lo <= hi, got [{lo}, {hi}]")
        return self


@dataclass(frozen=True)
class MoundState:
    """The inputs and closed-form response of one state (all in mm, s, g, Pa)."""

    E: float
    nu: float
    inflow_rate: float
    load_scale: float
    load: float  # sigma_f [Pa]
    lean: float  # delta [mm]
    flattening: float  # eps [-]

    def describe(self) -> dict[str, float]:
        return {
            "E": self.E,
            "nu": self.nu,
            "inflow_rate": self.inflow_rate,
            "load_scale": self.load_scale,
            "load_Pa": self.load,
            "lean_mm": self.lean,
            "flattening": self.flattening,
        }


def fluid_load(
    inflow_rate: float, load_scale: float, viscosity: float, gap: float, footprint: float
) -> float:
    """sigma_f = s (6 mu q / g^2 + 12 mu q w / g^3) in Pa (gap g and footprint w in mm)."""
    tau_w = 6.0 * viscosity * inflow_rate / gap**2
    dp = 12.0 * viscosity * inflow_rate * footprint / gap**3
    return load_scale * (tau_w + dp)


def response(E: float, nu: float, load: float, height: float) -> tuple[float, float]:
    """Lean delta [mm] and flattening eps [-] of a mound of crest ``height`` under ``load``."""
    bulk = E / (3.0 * (1.0 - 2.0 * nu))
    lean = height * math.tanh(BENDING_GAIN * load / E)
    flattening = MAX_FLATTENING * math.tanh(VOLUMETRIC_GAIN * abs(load) / bulk)
    return lean, flattening


def resolve_states(
    model_name: str,
    options: MoundOptions,
    parameters: Mapping[str, float],
    coordinates: Sequence[Mapping[str, float]],
    gap: float,
    footprint: float,
) -> list[MoundState]:
    """Validate the inputs of ``solve()`` and compute the response of every state.

    A coordinate's ``inflow_rate`` takes precedence over ``parameters["inflow_rate"]``, which
    takes precedence over the option.  Raises ConfigError for unknown parameter or coordinate
    names, ForwardModelError for physically impossible values or inside ``failure_region``.
    """
    unknown = sorted(set(parameters) - set(PARAMETER_NAMES))
    if unknown:
        raise ConfigError(
            f"unknown parameter(s) {', '.join(map(repr, unknown))}; "
            f"valid: {', '.join(PARAMETER_NAMES)}",
            model_name,
        )
    if len(coordinates) == 0:
        raise ConfigError(
            "solve() needs at least one coordinate, e.g. {} or {'inflow_rate': 100.0}", model_name
        )
    base: dict[str, float] = {n: float(getattr(options, n)) for n in PARAMETER_NAMES}
    base.update({k: float(v) for k, v in parameters.items()})
    states = []
    for coordinate in coordinates:
        bad = sorted(set(coordinate) - set(COORDINATE_KEYS))
        if bad:
            raise ConfigError(
                f"unknown coordinate key(s) {', '.join(map(repr, bad))} in {dict(coordinate)}; "
                f"valid: {', '.join(COORDINATE_KEYS)}",
                model_name,
            )
        values = {**base, **{k: float(v) for k, v in coordinate.items()}}
        _check_physical(values)
        _check_failure_region(values, options.failure_region)
        load = fluid_load(
            values["inflow_rate"], values["load_scale"], options.viscosity, gap, footprint
        )
        lean, flattening = response(values["E"], values["nu"], load, options.height)
        states.append(MoundState(**values, load=load, lean=lean, flattening=flattening))
    return states


def _check_physical(values: Mapping[str, float]) -> None:
    bad = [f"{k}={v}" for k, v in values.items() if not math.isfinite(v)]
    if bad:
        raise ForwardModelError(f"non-finite input {', '.join(bad)}", reason="invalid_input")
    if not values["E"] > 0.0:
        raise ForwardModelError(
            f"Young's modulus must be positive, got E={values['E']} Pa", reason="invalid_input"
        )
    if not -1.0 < values["nu"] < 0.5:
        raise ForwardModelError(
            f"Poisson's ratio must lie in (-1, 0.5), got nu={values['nu']}",
            reason="invalid_input",
        )


def _check_failure_region(
    values: Mapping[str, float], region: Mapping[str, tuple[float, float]] | None
) -> None:
    if not region:
        return
    if all(lo <= values[name] <= hi for name, (lo, hi) in region.items()):
        where = ", ".join(
            f"{n}={values[n]:g} in [{lo:g}, {hi:g}]" for n, (lo, hi) in region.items()
        )
        raise ForwardModelError(
            f"forward run failed at {where} (simulated failure: mesh distortion)",
            reason="mesh_distortion",
        )


def diagnostics(states: Sequence[MoundState], max_displacement: Sequence[float]) -> dict[str, Any]:
    """JSON-ready diagnostics of a solve: per-state inputs and response."""
    return {
        "states": [
            {**s.describe(), "max_displacement_mm": float(d)}
            for s, d in zip(states, max_displacement, strict=True)
        ],
    }


class MoundModel(ForwardModelBase):
    """What the 2-D mound and the 3-D dome share: reference shape, parameter names, solve.

    A subclass gives ``Options``, ``_reference_shape()``, ``states()``, ``displacement()`` and
    ``field_suffix`` (the file type of written interfaces).
    """

    #: bumped when a change alters its numbers (the store keys runs by it, not by the
    #: package version: fbia.storage.fingerprints)
    numerics_version = "1"

    field_suffix = ".vtu"

    def __init__(self, options: PluginOptions | None = None, /, **kwargs: Any) -> None:
        super().__init__(options, **kwargs)
        self._reference = self._reference_shape()

    def _reference_shape(self) -> Interface:
        raise NotImplementedError

    def states(
        self, parameters: Mapping[str, float], coordinates: Sequence[Mapping[str, float]]
    ) -> list[MoundState]:
        raise NotImplementedError

    def displacement(self, state: MoundState) -> np.ndarray:
        raise NotImplementedError

    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]]:
        """Paper A's reference point E = 400 Pa, nu = 0.3 at two inflow rates."""
        return {"E": 400.0, "nu": 0.3}, [{"inflow_rate": 50.0}, {"inflow_rate": 100.0}]

    def parameter_names(self) -> Sequence[str]:
        """``E`` [Pa], ``nu`` [-], ``inflow_rate`` [mm^2/s in 2-D, mm^3/s in 3-D],
        ``load_scale`` [-]."""
        return PARAMETER_NAMES

    def undeformed(self) -> Interface:
        """The undeformed interface (what zero inflow gives)."""
        return self._reference

    def solve(
        self,
        parameters: Mapping[str, float],
        coordinates: Sequence[Mapping[str, float]],
        workdir: Path,
    ) -> Solution:
        """One deformed interface per coordinate.

        Raises
        ------
        fbia.ConfigError
            Unknown parameter names or coordinate keys.
        fbia.ForwardModelError
            E <= 0, nu outside (-1, 0.5), non-finite inputs, or inputs inside the option
            ``failure_region`` (simulated mesh distortion).
        """
        states = self.states(parameters, coordinates)
        pairs, dmax, fields = [], [], {}
        suffix = self.field_suffix
        for k, (coordinate, state) in enumerate(zip(coordinates, states, strict=True)):
            u = self.displacement(state)
            gamma = self._reference.with_vertices(self._reference.vertices + u)
            pairs.append((coordinate, gamma))
            dmax.append(float(np.linalg.norm(u, axis=1).max()))
            if self.options.write_fields:  # type: ignore[attr-defined]
                fields[f"interface_{k}"] = gamma.write(Path(workdir) / f"interface_{k}{suffix}")
        if self.options.write_fields:  # type: ignore[attr-defined]
            fields["undeformed"] = self._reference.write(Path(workdir) / f"undeformed{suffix}")
        return Solution.from_pairs(pairs, fields=fields, diagnostics=diagnostics(states, dmax))
