"""Warnings about units before anything runs: data in µm, noise in µm, moduli in kPa.

fbia's units are mm, s, Pa (``../shared/ARCHITECTURE.md``; docs/command_line.md, "Units").  A study
whose observed interfaces are in µm, whose noise is in µm or whose Young's moduli are in kPa
is valid to the schema, and then fails every forward run ("ray ... meets no element") or
calibrates nonsense.  :func:`unit_warnings` compares what a study file says with the scales
it implies and returns one line per suspicion; ``fbia validate`` and ``fbia run`` print them as
warnings (they do not stop the study: the scales of an unusual experiment may be right).

The checks, each with the factor that triggers it:

* an observed interface whose extent is more than 20 times the model's channel (its
  ``channel_*`` options in mm) or less than 1/200 of it (data in µm, or in m);
* a noise standard deviation (``[likelihood]``, ``[synthetic]``, an observation's own) of
  more than 20 % of the observed interfaces' extent (noise in µm);
* a parameter whose unit differs from the unit the model's option of the same name states
  (``E`` in kPa where the model takes Pa; a description may give alternatives, ``[s/g or
  mm^2 s/g]``, when another option decides);
* a Young's modulus (a parameter ``E`` or ``E_<k>`` in Pa) whose bounds lie entirely below
  1 Pa or above 1e7 Pa (biofilm moduli are reported between about 1 Pa and 1 MPa);
* a model option in Pa (a modulus) outside 1-1e7 Pa (``E = 4e8`` by a unit slip; lengths in
  mm the models check against their channel themselves);
* a synthetic truth outside its parameter's bounds (or its prior's support): the fit can only
  end at the bound, and a Levenberg-Marquardt result there is ``unreliable``.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from ..core.options import plugin_options

__all__ = ["unit_warnings"]

#: extent of the data against the model's channel beyond which the data look mis-scaled
TOO_LARGE, TOO_SMALL = 20.0, 1.0 / 200.0
#: noise against the data's extent beyond which the noise looks mis-scaled
NOISE_SHARE = 0.2
#: the range of Young's moduli a biofilm study can mean, in Pa
MODULUS_RANGE = (1.0, 1e7)
_MODULUS = re.compile(r"E(_\w+)?$")


def unit_warnings(study: Any) -> list[str]:
    """One line per unit suspicion of ``study`` (a :class:`fbia.studies.study.Study`)."""
    out: list[str] = []
    extents = [e for e in map(_extent, study.observations) if e is not None and e > 0]
    channel = _channel(study.model)
    for k, extent in enumerate(extents, start=1):
        if channel is None:
            break
        if extent > TOO_LARGE * channel or extent < TOO_SMALL * channel:
            out.append(
                f"observation {k}: the interface spans {extent:.4g} mm, the model's channel "
                f"{channel:g} mm: are the data in another unit (µm, m)? fbia's unit is mm"
            )
    scale = max(extents) if extents else None
    if scale:
        for where, noise in _noises(study):
            if noise is not None and noise > NOISE_SHARE * scale:
                out.append(
                    f"{where}: noise_std = {noise:g} mm is {100 * noise / scale:.0f} % of the "
                    f"observed interfaces' extent ({scale:.4g} mm): in µm? fbia's unit is mm"
                )
    stated = _option_units(study.model)
    for p in [*study.parameters, *study.uncertain]:
        model_unit = stated.get(p.name)
        if p.unit and model_unit and p.unit not in model_unit.split(" or "):
            out.append(
                f"parameter {p.name}: the study says {p.unit}, {study.model_name} takes "
                f"{model_unit}: values are passed as they are, not converted"
            )
        if _MODULUS.match(p.name) and p.bounds is not None and p.unit in ("Pa", ""):
            lo, hi = p.bounds
            if hi < MODULUS_RANGE[0] or lo > MODULUS_RANGE[1]:
                out.append(
                    f"parameter {p.name}: bounds [{lo:g}, {hi:g}] Pa lie outside "
                    f"{MODULUS_RANGE[0]:g}-{MODULUS_RANGE[1]:g} Pa, where biofilm moduli are "
                    "reported: in kPa or MPa? fbia's unit is Pa"
                )
    out += _option_warnings(study.model, stated)
    out += _truth_warnings(study)
    return out


def _option_warnings(model: Any, units: dict[str, str]) -> list[str]:
    """Model options whose values are implausible in the unit their description states."""
    out = []
    for name, value in plugin_options(model).items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        unit = units.get(name)
        in_range = MODULUS_RANGE[0] <= value <= MODULUS_RANGE[1]
        if unit == "Pa" and 0 < value < math.inf and not in_range:
            out.append(
                f"model option {name} = {value:g} Pa lies outside {MODULUS_RANGE[0]:g}-"
                f"{MODULUS_RANGE[1]:g} Pa, where biofilm moduli are reported: in another unit? "
                "fbia's unit is Pa"
            )
    return out


def _truth_warnings(study: Any) -> list[str]:
    """A synthetic truth outside its parameter's bounds or its prior's support."""
    if study.synthetic is None:
        return []
    out = []
    for p in [*study.parameters, *study.uncertain]:
        value = study.synthetic.truth.get(p.name)
        if value is None:
            continue
        lo, hi = p.bounds if p.bounds is not None else (-math.inf, math.inf)
        if p.prior is not None:
            lo, hi = max(lo, p.prior.support[0]), min(hi, p.prior.support[1])
        if not lo <= value <= hi:
            out.append(
                f"[synthetic] truth {p.name} = {value:g} lies outside [{lo:g}, {hi:g}], the "
                f"range {p.name} may take: the calibration can only end at the bound"
            )
    return out


def _extent(obs: Any) -> float | None:
    """The largest side of the bounding box of an observation's interface (or points)."""
    coords = None
    if obs.interface is not None:
        coords = np.asarray(obs.interface.vertices, dtype=float)
    elif obs.measurement_points is not None:
        coords = np.asarray(obs.measurement_points.points, dtype=float)
    if coords is None or coords.size == 0:
        return None
    return float(np.max(np.ptp(coords, axis=0)))


def _channel(model: Any) -> float | None:
    """The model's channel size in mm: the largest of its ``channel_*`` options."""
    sizes = [
        float(v)
        for k, v in plugin_options(model).items()
        if k.startswith("channel_") and isinstance(v, (int, float)) and math.isfinite(v)
    ]
    return max(sizes) if sizes else None


def _noises(study: Any) -> list[tuple[str, float | None]]:
    out: list[tuple[str, float | None]] = [("[likelihood]", study.noise_std)]
    if study.synthetic is not None:
        out.append(("[synthetic]", study.synthetic.noise_std))
    for k, obs in enumerate(study.observations, start=1):
        out.append((f"observation {k}", obs.noise_std))
    return out


def _option_units(model: Any) -> dict[str, str]:
    """Option name -> the unit its description states (``fbia plugins --options``)."""
    options = getattr(type(model), "Options", None)
    if options is None or not hasattr(options, "describe"):
        return {}
    return {k: v["unit"] for k, v in options.describe().items() if v.get("unit")}
