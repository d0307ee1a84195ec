"""A study, read and checked: the :class:`Study` value that a study file describes.

:func:`fbia.studies.study_file.load_study` makes it from a TOML file (the format is described
there); :func:`fbia.studies.runner.run_study` runs it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..core.errors import ConfigError, ForwardModelError
from ..core.observation import Observation
from ..core.options import plugin_options
from ..core.parameters import Parameter, Prior
from ..core.problem import InverseProblem, IteratorMembers
from ..core.protocols import ForwardModelBase, MeasureBase
from ..execution.executors import ExecutorSpec
from .paper import PaperSpec
from .study_sources import StudySource

if TYPE_CHECKING:
    from .study_oct import OctRecord

__all__ = ["Study", "SyntheticSpec", "derived_seed"]

#: spawn keys of the seed sequence derived from [study] seed
SYNTHETIC_STREAM, ITERATOR_STREAM = 0, 1


def derived_seed(seed: int, stream: int) -> int:
    """A 32-bit seed for one consumer of randomness, derived from the study's seed."""
    return int(np.random.SeedSequence(seed, spawn_key=(stream,)).generate_state(1)[0])


@dataclass(frozen=True)
class SyntheticSpec:
    """Observations made from the forward model at ``truth`` plus Gaussian noise."""

    truth: dict[str, float]
    coordinates: list[dict[str, float]]
    noise_std: float = 0.0
    points: int | None = None
    seed: int = 0
    noise: str = "normal"
    placement: str = "even"  # where the points go (synthetic_observations)
    significant: float = 0.5
    draws: int = 1  # noise draws: the study runs once per draw (fbia.studies.draws)


@dataclass(eq=False)
class Study:
    """A study file, read and checked.

    The inverse problem (:attr:`problem`) is built on first use: synthetic observations need
    forward runs, which :func:`load_study` with ``build=False`` (``fbia validate``) avoids.
    Reading writes no file: what a run writes of the study's OCT scans is kept in
    :attr:`oct_records` until then (:mod:`fbia.studies.study_oct`).
    """

    path: Path
    name: str
    seed: int
    output: Path
    store: Path | None  # the study store's file when not <output>/store.sqlite
    model: ForwardModelBase
    model_name: str
    measure: MeasureBase
    measure_name: str
    parameters: list[Parameter]
    uncertain: list[Parameter]
    fixed: dict[str, float]
    observations: list[Observation]
    synthetic: SyntheticSpec | None
    noise_std: float | None
    noise_prior: Prior | None
    iterator: IteratorMembers | None
    iterator_name: str | None
    executor: ExecutorSpec
    raw: dict[str, Any] = field(repr=False)
    text: str = field(repr=False)
    sha256: str = ""  # of the file, or of it, its bases and the --set changes together
    #: the files it extends, nearest first, and the ``--set`` changes (:mod:`.study_sources`)
    bases: tuple[StudySource, ...] = field(default=(), repr=False)
    overrides: tuple[str, ...] = ()
    paper: PaperSpec | None = field(default=None, repr=False)  # [paper]: published numbers
    figures: bool = True  # False: no plots (each noise draw of fbia.studies.draws)
    # the segmentation record of each OCT scan, written by the runner under the output lock
    oct_records: tuple[OctRecord, ...] = field(default=(), repr=False)

    @property
    def file(self) -> str:
        """The study file as named by the user (used in messages)."""
        return str(self.path)

    @cached_property
    def problem(self) -> InverseProblem:
        """The :class:`InverseProblem` (makes the synthetic observations on first use)."""
        observations = list(self.observations)
        if self.synthetic is not None:
            observations += self._synthetic_observations()
        try:
            return InverseProblem(
                model=self.model,
                measure=self.measure,
                observations=observations,
                parameters=self.parameters,
                uncertain=self.uncertain,
                noise_std=self.noise_std,
                fixed=self.fixed,
                noise_prior=self.noise_prior,
                truth=None if self.synthetic is None else dict(self.synthetic.truth),
            )
        except ConfigError as err:
            raise err.located(self.file) from None

    def _synthetic_observations(self) -> list[Observation]:
        from ..core.synthetic import synthetic_observations

        spec = self.synthetic
        assert spec is not None
        where = f"{self.file}: [synthetic]"
        try:
            obs = synthetic_observations(
                self.model,
                {**self.fixed, **spec.truth},
                spec.coordinates,
                noise_std=spec.noise_std,
                seed=spec.seed,
                points=spec.points,
                noise=spec.noise,  # type: ignore[arg-type]
                placement=spec.placement,  # type: ignore[arg-type]
                significant=spec.significant,
            )
        except ForwardModelError as exc:
            raise ConfigError(f"the forward model failed at the truth: {exc}", where) from None
        except ConfigError as err:
            raise err.located(where) from None
        return list(obs)

    # -- what to show ------------------------------------------------------------------------
    def start_point(self, values: Mapping[str, float] | None = None) -> dict[str, float]:
        """Parameters' ``initial`` (else the middle of the bounds), overridden by ``values``.

        ``values`` may also set uncertain and fixed inputs (``fbia forward --set``).
        """
        values = dict(values or {})
        valid = [p.name for p in self.parameters] + [p.name for p in self.uncertain]
        valid += list(self.fixed)
        unknown = [k for k in values if k not in valid]
        if unknown:
            raise ConfigError(
                f"unknown name(s) {', '.join(map(repr, unknown))}; valid: {', '.join(valid)}",
                "--set",
            )
        x: dict[str, float] = {}
        for p in [*self.parameters, *self.uncertain]:  # as the study file's own values
            if p.name in values and p.bounds is not None:
                lo, hi = p.bounds
                if not lo <= float(values[p.name]) <= hi:
                    unit = f" {p.unit}" if p.unit and p.unit != "-" else ""
                    raise ConfigError(
                        f"{p.name} = {values[p.name]:g}{unit} lies outside its bounds "
                        f"[{lo:g}, {hi:g}]{unit}",
                        "--set",
                    )
        for p in self.parameters:
            if p.name in values:
                x[p.name] = float(values.pop(p.name))
            elif p.initial is not None:
                x[p.name] = p.initial
            elif p.bounds is not None:
                x[p.name] = 0.5 * (p.bounds[0] + p.bounds[1])
            else:
                raise ConfigError(
                    f"parameter {p.name!r} has neither an initial value nor bounds; "
                    f"give one with --set {p.name}=VALUE"
                )
        x.update({k: float(v) for k, v in values.items()})
        return x

    def summary(self) -> str:
        """A few lines that say what the study is (``fbia validate``)."""

        def par(p: Parameter) -> str:
            unit = f" [{p.unit}]" if p.unit else ""
            rng = f" in [{p.bounds[0]:g}, {p.bounds[1]:g}]" if p.bounds else ""
            prior = p.prior.kind if p.prior is not None else "none"
            return f"{p.name}{unit}{rng} ({prior} prior)"

        obs = [f"{o.label()} (file)" for o in self.observations]
        if self.synthetic is not None:
            draws = self.synthetic.draws
            tag = f" (synthetic, {draws} noise draws)" if draws > 1 else " (synthetic)"
            obs += [
                ", ".join(f"{k}={v:g}" for k, v in c.items()) + tag
                for c in self.synthetic.coordinates
            ]
        lines = [
            f"study      {self.name} ({self.file}, sha256 {self.sha256[:12]})",
            f"model      {self.model_name} {_opts(self.model)}".rstrip(),
            f"parameters {'; '.join(par(p) for p in self.parameters)}",
        ]
        if self.uncertain:
            lines.append(f"uncertain  {'; '.join(par(p) for p in self.uncertain)}")
        if self.fixed:
            lines.append("fixed      " + ", ".join(f"{k} = {v:g}" for k, v in self.fixed.items()))
        lines += [
            f"states     {'; '.join(obs)}",
            f"measure    {self.measure_name} {_opts(self.measure)}".rstrip(),
            f"iterator   {self.iterator_name or '(none: one forward run)'}",
            f"executor   {self.executor.label()}",
            f"seed       {self.seed}",
            *(
                [f"paper      {self.paper.source} ({len(self.paper.values)} values)"]
                if self.paper is not None
                else []
            ),
            f"output     {self.output}",
            *([] if self.store is None else [f"store      {self.store}"]),
        ]
        return "\n".join(lines)


def _opts(obj: Any) -> str:
    """The options that differ from their defaults, e.g. ``(n_points=81)``."""
    given = plugin_options(obj, exclude_defaults=True)
    return "(" + ", ".join(f"{k}={v!r}" for k, v in given.items()) + ")" if given else ""


def store_file(folder: Path, store: str | None, where: str) -> Path | None:
    """The study store a study file names (relative to its ``folder``), None for the default
    ``<output>/store.sqlite``; a folder is an error (``where``: the file and key)."""
    if store is None:
        return None
    path = folder / store
    if store.endswith(("/", "\\")) or Path(store).name in ("", ".", "..") or path.is_dir():
        raise ConfigError(
            f"{store!r} is a folder: name the store's file, e.g. 'runs.sqlite'", where
        )
    return path
