"""fbia-example-plugin: a tiny third-party fbia plugin, used by tests/core/test_plugins.py.

It is *not* installed: the test writes a ``fbia_example_plugin-1.2.3.dist-info`` whose
``entry_points.txt`` declares ``[fbia] example = fbia_example_plugin`` and puts it, and this
folder, on ``sys.path`` for the duration of one test.  Nothing in fbia knows about it.

``example_bump``: a 2-D bump ``y = amplitude (q / 100) sin^2(pi x)`` [mm] on ``x`` in [0, 1],
``q`` the coordinate ``inflow_rate`` [mm^2/s]; it fails (ForwardModelError) above
``max_amplitude``.  ``example_bbox``: compares the bounding boxes of two interfaces.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from pydantic import Field

import fbia

__version__ = "1.2.3"


class ExampleBumpForwardModel(fbia.ForwardModelBase):
    """A closed-form bump whose height scales with the inflow rate."""

    class Options(fbia.PluginOptions):
        n_points: int = Field(41, ge=3, description="vertices of the interface polyline [-]")
        max_amplitude: float = Field(
            1.0, gt=0, description="amplitude above which a run fails [mm]"
        )

    @classmethod
    def example_parameters(cls) -> tuple[dict[str, float], list[dict[str, float]]]:
        return {"amplitude": 0.2}, [{"inflow_rate": 50.0}, {"inflow_rate": 100.0}]

    def parameter_names(self) -> Sequence[str]:
        return ("amplitude",)

    def solve(
        self,
        parameters: Mapping[str, float],
        coordinates: Sequence[Mapping[str, float]],
        workdir: Path,
    ) -> fbia.Solution:
        a = float(parameters.get("amplitude", 0.2))
        if a > self.options.max_amplitude:
            raise fbia.ForwardModelError(
                f"amplitude {a} mm exceeds max_amplitude {self.options.max_amplitude} mm",
                reason="diverged",
            )
        x = np.linspace(0.0, 1.0, self.options.n_points)
        pairs = []
        for c in coordinates:
            y = a * c.get("inflow_rate", 100.0) / 100.0 * np.sin(np.pi * x) ** 2
            pairs.append((c, fbia.Interface.polyline(np.c_[x, y])))
        return fbia.Solution.from_pairs(pairs, diagnostics={"amplitude": a})


class ExampleBoundingBoxMeasure(fbia.MeasureBase):
    """Differences of the lower and upper corners of the bounding boxes [mm]."""

    class Options(fbia.PluginOptions):
        weight: float = Field(1.0, gt=0, description="factor on every residual [-]")

    def residuals(self, simulated: fbia.Interface, observation: fbia.Observation) -> np.ndarray:
        if observation.interface is None:
            raise fbia.MeasureError("the bounding-box measure needs an observed interface")
        lo_s, hi_s = simulated.bounds
        lo_o, hi_o = observation.interface.bounds
        return self.options.weight * np.r_[lo_s - lo_o, hi_s - hi_o]

    def distance(self, simulated: fbia.Interface, observation: fbia.Observation) -> float:
        return float(np.linalg.norm(self.residuals(simulated, observation)))


@fbia.hookimpl
def register_forward_models(register):  # type: ignore[no-untyped-def]
    register("example_bump", ExampleBumpForwardModel)


@fbia.hookimpl
def register_measures(register):  # type: ignore[no-untyped-def]
    register("example_bbox", ExampleBoundingBoxMeasure)
