"""Unit sanity before anything runs: data in µm, noise in µm, moduli in kPa, lengths in m.

fbia's units are mm, s, Pa (``../shared/ARCHITECTURE.md``; docs/command_line.md, "Units").  A study
whose observed interfaces are in µm, whose noise is in µm or whose Young's moduli are in kPa
is valid to the schema, and then fails every forward run ("ray ... meets no element") or
calibrates nonsense.  :func:`unit_errors` and :func:`unit_warnings` compare what a study file
says with the scales it implies, before any forward run (``fbia validate`` and ``fbia run``)::

    study = load_study("study.toml", build=False)
    if errors := unit_errors(study):
        raise errors[0]               # the CLI: one line, exit status 2
    for line in unit_warnings(study):
        print("warning:", line)       # the study still runs

**Errors**, what no study can mean (each a :class:`~fbia.core.errors.ConfigError` naming the
file and the section).  The channel is the model's ``channel_*`` options in mm; a model given
a ``mesh_file`` has its channel in that file, and is not compared with them.

* a noise standard deviation (``[likelihood]``, ``[synthetic]``, an observation's own) at
  least as large as the observed interfaces' whole extent (the largest side of their bounding
  box; without an observed interface, the channel's largest side, which bounds every
  interface in it): no data point says where the interface is;
* an observed interface (or its measurement points) spanning more than 1000 times the
  channel's largest side: no interface of the model can lie along it;
* an observed interface spanning less than 1/1000 of the channel's smallest side (under 1 µm
  in a 1 mm channel: smaller than a bacterium; data in m);
* a model option in mm (a position, a size, an outline's or a probe's points) beyond 1000
  times the channel's largest side: 10 m in a 2 mm channel.  The analytic mound models check
  their lengths against their channel when their options are read; ``ale_fsi`` does only when
  it builds its mesh, at the first forward run.  Left out: the ``channel_*`` options, which
  define the channel, and element sizes, grid spacings, smoothing widths and tolerances, where
  a huge value may mean "no limit" (netgen's own default element size is 1e99).

**Warnings**, what an unusual experiment may mean (one line each; the study still runs):

* an observed interface spanning more than 20 times the channel or less than 1/200 of it
  (data in µm, or in m);
* a noise standard deviation above 20 % of the observed interfaces' extent (or of the
  channel for synthetic data): noise in µm;
* ``channel_*`` options more than 1000 times apart (a channel 10 m high and 2 mm long; a
  microchannel may be 50 µm high and 60 mm long);
* a parameter whose unit differs from the unit the model's option of the same name states
  (``E`` in kPa where the model takes Pa; a description may give alternatives, ``[s/g or
  mm^2 s/g]``, when another option decides);
* a Young's modulus (a parameter ``E`` or ``E_<k>`` in Pa) whose bounds lie entirely below
  1 Pa or above 1e7 Pa (biofilm moduli are reported between about 1 Pa and 1 MPa);
* a model option in Pa (a modulus) outside 1-1e7 Pa (``E = 4e8`` by a unit slip);
* a synthetic truth outside its parameter's bounds (or its prior's support): the fit can only
  end at the bound, and a Levenberg-Marquardt result there is ``unreliable`` (a study of what
  a fit does then may mean it).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from typing import Any

import numpy as np

from ..core.errors import ConfigError
from ..core.options import plugin_options

__all__ = ["unit_errors", "unit_warnings"]

#: extent of the data against the model's channel beyond which the data look mis-scaled
TOO_LARGE, TOO_SMALL = 20.0, 1.0 / 200.0
#: noise against the data's extent beyond which the noise looks mis-scaled
NOISE_SHARE = 0.2
#: a length against the channel beyond which no study can mean it (data, options), and the
#: ratio of two channel sides beyond which one of them looks like another unit
IMPOSSIBLE = 1000.0
#: the range of Young's moduli a biofilm study can mean, in Pa
MODULUS_RANGE = (1.0, 1e7)
_MODULUS = re.compile(r"E(_\w+)?$")
#: an option in mm that sets a resolution or a tolerance, not the geometry (name, description)
_RESOLUTION = re.compile(r"size|spacing|resolution|smoothing|tolerance|tol\b", re.IGNORECASE)


def unit_errors(study: Any) -> list[ConfigError]:
    """The unit mistakes of ``study`` (a :class:`fbia.studies.study.Study`) that no study can
    mean, one :class:`ConfigError` each, naming the file and the section."""
    out: list[ConfigError] = []
    channel = _channel(study.model)
    if channel:
        for k, obs in enumerate(study.observations, start=1):
            message = _extent_error(obs, channel)
            if message:
                out.append(ConfigError(message, f"{study.file}: [[observations]] #{k}"))
    scale = _noise_scale(study, channel, interfaces_only=True)
    if scale is not None:
        size, what = scale
        for section, noise in _noises(study, "[[observations]] #{}"):
            if noise is not None and noise >= size:
                message = (
                    f"noise_std = {noise:g} mm is at least {what}: no data point says where "
                    "the interface is; in µm? fbia's unit is mm"
                )
                out.append(ConfigError(message, f"{study.file}: {section}"))
    if channel:
        largest = max(channel.values())
        named: set[str] = set()  # one error per option
        for name, value, scalar in _lengths(study.model):
            if name not in named and abs(value) > IMPOSSIBLE * largest:
                named.add(name)
                said = f"{name} = {value:g} mm is" if scalar else f"{name} holds {value:g} mm,"
                message = (
                    f"option {said} more than {IMPOSSIBLE:g} times the model's channel "
                    f"({largest:g} mm): in µm? fbia's unit is mm"
                )
                out.append(ConfigError(message, f"{study.file}: [model.options]"))
    return out


def unit_warnings(study: Any) -> list[str]:
    """One line per unit suspicion of ``study`` (a :class:`fbia.studies.study.Study`) that an
    unusual experiment may mean; what :func:`unit_errors` reports is not repeated here."""
    out: list[str] = []
    channel = _channel(study.model)
    if channel:
        largest = max(channel.values())
        for k, obs in enumerate(study.observations, start=1):
            extent = _extent(obs)
            if extent is None or extent <= 0 or _extent_error(obs, channel):
                continue
            if extent > TOO_LARGE * largest or extent < TOO_SMALL * largest:
                out.append(
                    f"observation {k}: the interface spans {extent:.4g} mm, the model's "
                    f"channel {largest:g} mm: are the data in another unit (µm, m)? fbia's "
                    "unit is mm"
                )
        long, smallest = max(channel, key=channel.__getitem__), min(channel.values())
        if largest > IMPOSSIBLE * smallest:
            out.append(
                f"model option {long} = {largest:g} mm is more than {IMPOSSIBLE:g} times the "
                f"channel's smallest side ({smallest:g} mm): in another unit (µm, m)? fbia's "
                "unit is mm"
            )
    scale = _noise_scale(study, channel, interfaces_only=False)
    fatal = _noise_scale(study, channel, interfaces_only=True)
    if scale is not None:
        size, what = scale
        for section, noise in _noises(study, "observation {}"):
            if noise is None or noise <= NOISE_SHARE * size:
                continue
            if fatal is not None and noise >= fatal[0]:
                continue  # one of unit_errors
            out.append(
                f"{section}: noise_std = {noise:g} mm is {100 * noise / size:.0f} % of "
                f"{what}: in µm? fbia's unit is mm"
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


def _extent_error(obs: Any, channel: dict[str, float]) -> str | None:
    """Why the extent of ``obs`` cannot be meant against the ``channel``, else None."""
    extent, shape = _extent(obs), _extent(obs, points=False)
    largest, smallest = max(channel.values()), min(channel.values())
    if extent is not None and extent > IMPOSSIBLE * largest:
        return (
            f"the observed interface spans {extent:.4g} mm, more than {IMPOSSIBLE:g} times the "
            f"model's channel ({largest:g} mm): no interface of the model can lie along it; "
            "are the data in another unit (µm, nm)? fbia's unit is mm"
        )
    # an interface's own extent only: a few measurement points may lie close together
    if shape is not None and 0 < shape < smallest / IMPOSSIBLE:
        return (
            f"the observed interface spans {shape:.4g} mm, less than 1/{IMPOSSIBLE:g} of the "
            f"smallest side of the model's channel ({smallest:g} mm): are the data in m? "
            "fbia's unit is mm"
        )
    return None


def _noise_scale(
    study: Any, channel: dict[str, float] | None, interfaces_only: bool
) -> tuple[float, str] | None:
    """The size in mm the noise is compared with, and what it is: the largest observed
    extent (of interfaces only, or also of measurement points), else the channel's largest
    side."""
    extents = [_extent(o, points=not interfaces_only) for o in study.observations]
    positive = [e for e in extents if e is not None and e > 0]
    if positive:
        size = max(positive)
        return size, f"the observed interfaces' extent ({size:.4g} mm)"
    if channel:
        size = max(channel.values())
        return size, f"the model's channel ({size:g} mm), which holds every interface"
    return None


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


def _extent(obs: Any, points: bool = True) -> float | None:
    """The largest side of the bounding box of an observation's interface (or, with
    ``points``, of its measurement points when it has no interface)."""
    coords = None
    if obs.interface is not None:
        coords = np.asarray(obs.interface.vertices, dtype=float)
    elif points and obs.measurement_points is not None:
        coords = np.asarray(obs.measurement_points.points, dtype=float)
    if coords is None or coords.size == 0:
        return None
    return float(np.max(np.ptp(coords, axis=0)))


def _channel(model: Any) -> dict[str, float] | None:
    """The model's ``channel_*`` options in mm (its channel's sides); None without any, or
    when a ``mesh_file`` gives the channel instead."""
    options = plugin_options(model)
    if options.get("mesh_file") is not None:
        return None
    sides = {
        k: float(v)
        for k, v in options.items()
        if k.startswith("channel_")
        and isinstance(v, (int, float))
        and not isinstance(v, bool)
        and math.isfinite(v)
        and v > 0
    }
    return sides or None


def _lengths(model: Any) -> Iterator[tuple[str, float, bool]]:
    """Name, value and whether it is the option's only number, of every number a model option
    in mm holds (points' coordinates too), but the channel's sides and resolutions
    (:data:`_RESOLUTION`)."""
    described = type(model).Options.describe()
    for name, value in plugin_options(model).items():
        about = described.get(name, {})
        if about.get("unit") != "mm" or name.startswith("channel_"):
            continue
        if _RESOLUTION.search(f"{name} {about.get('description', '')}"):
            continue
        scalar = not isinstance(value, (list, tuple))
        for number in _numbers(value):
            yield name, number, scalar


def _numbers(value: Any) -> Iterator[float]:
    """The finite numbers in ``value``, a number or nested lists of them."""
    if isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        if math.isfinite(value):
            yield float(value)
    elif isinstance(value, (list, tuple)):
        for item in value:
            yield from _numbers(item)


def _noises(study: Any, observation: str) -> list[tuple[str, float | None]]:
    """Every noise standard deviation of ``study`` with its section (``observation``: how
    to name the k-th observation, a format string)."""
    out: list[tuple[str, float | None]] = [("[likelihood]", study.noise_std)]
    if study.synthetic is not None:
        out.append(("[synthetic]", study.synthetic.noise_std))
    for k, obs in enumerate(study.observations, start=1):
        out.append((observation.format(k), obs.noise_std))
    return out


def _option_units(model: Any) -> dict[str, str]:
    """Option name -> the unit its description states (``fbia plugins --options``)."""
    return {k: v["unit"] for k, v in type(model).Options.describe().items() if v.get("unit")}
