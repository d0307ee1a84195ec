"""Study files: one TOML file describes an inverse analysis; :func:`load_study` reads it.

>>> study = fbia.load_study("examples/flow_cell/study.toml")      # doctest: +SKIP
>>> print(fbia.run_study(study).summary())                          # doctest: +SKIP

The format (every section but ``[model]``, ``[[parameters]]``, ``[measure]`` and one of
``[[observations]]``/``[synthetic]`` is optional)::

    [study]
    name = "flow_cell"          # default: the file's stem
    seed = 1                    # every random choice derives from it (default 0)
    output = "output"           # output folder, relative to the study file (default "output")
    store = "../runs.sqlite"    # the study store, relative to the study file (default
                                # <output>/store.sqlite): studies of one model that name the
                                # same store share its forward runs (one study at a time;
                                # --fresh refuses it then); a regular file, no control characters
    extends = "base.toml"       # optional: read that study file first and merge this one's
                                # tables into it (fbia.studies.study_sources; --set changes a
                                # value on the command line)
    base_only = false           # true: the file holds what a family of variants shares and
                                # is no study by itself (fbia run refuses it; not inherited)

    [model]                     # a forward model from the registry (`fbia plugins`)
    name = "analytic_mound_2d"
    options = { n_points = 81 } # or a [model.options] table; unknown keys are errors

    [[parameters]]              # the calibration parameters x, one table each
    name = "E"                  # a name the forward model knows
    unit = "Pa"                 # for reports and plots
    bounds = [100.0, 800.0]     # lower < upper (optional if the prior has finite support)
    initial = 200.0             # optional initial guess, inside the bounds
    prior = { distribution = "uniform" }   # optional; default uniform on the bounds
                                # uniform | normal | truncated_normal | lognormal | beta

    [[uncertain]]               # uncertain inputs theta with a prior (Paper B eq. 3)
    name = "inflow_rate"
    prior = { distribution = "beta", a = 2.6, b = 1.4, lower = 0.0, upper = 110.0 }

    [fixed]                     # model inputs held at a value in every run
    inflow_rate = 100.0

    [[observations]]            # observed states from files, relative to the study file ...
    coordinate = { inflow_rate = 100.0 }     # which state (model-defined names)
    interface = "data/observed_100.csv"      # CSV x, y[, curve] (2-D); STL/PLY/VTU/... (3-D)
    # oct = { file = "data/scan.npy", voxel_size = [0.005, 0.01, 0.01], threshold = 0.6 }
    #   or an OCT scan (fbia.studies.study_oct), segmented on reading: voxel_size (dz, dy, dx) mm,
    #   height_axis = "y" for ale_fsi 3-D (checked against the model's up_axis), options of
    #   fbia.imaging.oct; run and forward write the figures and segmentation.json to oct/ of
    #   the output folder they use
    points = "data/points_100.csv"           # optional: x, y[, z][, dx, dy[, dz]]
    noise_std = 0.01                         # optional, mm
    name = "Q100"                            # optional label

    [synthetic]                 # ... or made here: the model at `truth` plus Gaussian noise
    truth = { E = 400.0, nu = 0.3 }
    coordinates = [ { inflow_rate = 100.0 } ]
    noise_std = 0.005           # mm (0: exact data)
    noise = "normal"            # along the normals (Paper A) | "isotropic" (Paper B eq. 16)
    points = 12                 # optional number of measurement points (for "ray"), put
    placement = "displacement"  # where |u.n| >= significant (0.5) x max, or "even" (default)
    seed = 7                    # optional; default: derived from [study] seed
    draws = 20                  # optional: run once per noise draw, judge over the draws

    [measure]                   # ray | cpp | rkhs (or a plugin's)
    name = "cpp"
    options = {}

    [likelihood]                # sigma_N in mm (Paper B eq. 5), or a noise_prior (inferred)
    noise_std = 0.01            # noise_prior = { distribution = "lognormal", mu_ln = -4.6, ... }

    [iterator]                  # optional; without it `fbia run` does one forward run
    name = "levenberg_marquardt"
    options = { x0 = [ { E = 200.0, nu = 0.4 }, { E = 700.0, nu = -0.5 } ] }

    [executor]
    kind = "processes"          # serial | processes | dask (default processes)
    workers = 2                 # default: the number of cores
    keep_runs = false           # keep successful runs' folders in <output>/runs (failed: always)
    timeout = 3600.0            # optional limit of a run's wall time [s]; past it: failed
    isolate = true              # each run in a child process of its own (default: with a
                                # timeout, and always for dask); a crash costs that child only
    address = "tcp://10.0.0.5:8786"   # dask: a running scheduler ...
    cluster = "slurm"           # ... or "local" (default) | slurm | pbs | sge | lsf | htcondor
                                # | moab | oar (dask-jobqueue) with `workers` workers
    cluster_options = { cores = 8, memory = "16GB", walltime = "04:00:00" }  # passed through

    [paper]                     # published numbers beside the result (fbia.studies.paper)
    source = "Paper A, Table 2" # [[paper.values]]: quantity, kind (its rule), paper, unit, ...

Resume: every finished run is stored in ``<output>/store.sqlite`` the moment it ends.  Running
the study again on the same output folder reuses every stored forward run of the same model
(options, fixed inputs) at the same inputs and runs only the others; a new likelihood noise
reuses them as they are, a new measure or other observations compare the stored interfaces
anew (:mod:`fbia.storage.store`).  Since the iterators are deterministic given the seed, the result
is the one an uninterrupted run gives.  A store made for another model is an error that says
what changed; ``fresh=True`` (``fbia run --fresh``) starts over, ``retry_failed=True`` runs
stored failures again.

Seeds: the synthetic noise uses ``numpy.random.SeedSequence(seed, spawn_key=(0,))`` and an
iterator whose options have a ``seed`` the file does not set gets the state of
``SeedSequence(seed, spawn_key=(1,))``; nothing else draws random numbers.  An iterator with an
``x0`` option that the file does not set starts from the parameters' ``initial`` values when
all of them have one.

Every mistake in a study file raises :class:`~fbia.core.errors.ConfigError` with one line that
names the file and the key, e.g. ``study.toml: [model.options]: unknown option 'mesh_sise';
valid options: ...``.  Paths in the file are relative to the file's folder, plugin options
declared as paths (``Path`` fields of a plugin's ``Options``, e.g. a forward model's
``mesh_file``) included.
"""

from __future__ import annotations

import math
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from ..core.errors import ConfigError
from ..core.interface import Interface
from ..core.observation import MeasurementPoints, Observation, check_coordinate
from ..core.parameters import Parameter, Prior
from ..core.registry import Registry, default_registry
from ..execution.executors import ExecutorSpec, check_scheduler_address
from .paper import read_paper
from .study import (
    ITERATOR_STREAM,
    SYNTHETIC_STREAM,
    Study,
    SyntheticSpec,
    derived_seed,
    store_file,
)
from .study_schema import (
    ExecutorSection,
    LikelihoodSection,
    ObservationSection,
    ParameterSection,
    PluginSection,
    StudySection,
    SyntheticSection,
    UncertainSection,
    as_number,
    as_table,
    checked,
    is_path_type,
    kind_of,
    parse_section,
)
from .study_sources import StudySources, read_sources

if TYPE_CHECKING:
    from .study_oct import OctRecord

__all__ = ["SECTIONS", "load_study"]

T = TypeVar("T")

#: Top-level sections of a study file and what each holds.
SECTIONS: dict[str, str] = {
    "study": "name, seed, output folder, store",
    "model": "forward model name and options",
    "parameters": "calibration parameters (array of tables)",
    "uncertain": "uncertain inputs with priors (array of tables)",
    "fixed": "inputs held fixed",
    "observations": "observed states from files (array of tables)",
    "synthetic": "observations made from the model at a ground truth",
    "measure": "discrepancy measure name and options",
    "likelihood": "noise_std, or noise_prior (sigma_N inferred)",
    "iterator": "iterator name and options",
    "executor": "serial, processes or dask; workers, time-out, cluster",
    "paper": "published numbers to put beside the result (fbia.studies.paper)",
}


# -- reading -----------------------------------------------------------------------------------
def load_study(
    path: str | Path,
    registry: Registry | None = None,
    build: bool = True,
    overrides: Sequence[str] = (),
) -> Study:
    """Read and check a study file.

    Parameters
    ----------
    path
        The TOML file.
    registry
        Where plugin names are looked up (default: the installed plugins).
    build
        Also build :attr:`Study.problem` now (runs the model for ``[synthetic]`` data).
        ``False`` checks everything that needs no forward run.
    overrides
        ``section.key=value`` changes after the file and the bases it extends are merged
        (``fbia run --set``; :mod:`fbia.studies.study_sources`).

    Raises
    ------
    ConfigError
        For any mistake, with one line naming the file and the key.
    """
    path = Path(path)
    sources = read_sources(path, overrides)
    study_table = sources.raw.get("study")
    if isinstance(study_table, dict) and study_table.get("base_only") is True:
        raise ConfigError(
            "a base that variants extend, not a study of its own: run a study file that extends it",
            f"{path}: [study] base_only",
        )
    try:
        study = _Reader(path, sources.raw, registry or default_registry()).read(sources)
    except ConfigError as err:
        if not overrides:
            raise
        # the fault may be a change's: the line says which study was read
        changes = " ".join(f"--set {change}" for change in overrides)
        raise ConfigError(f"{err.reason} (the study as changed by {changes})", err.where) from None
    if build:
        _ = study.problem
    return study


class _Reader:
    """Turns the parsed TOML into a :class:`Study`, one precise error per rule."""

    def __init__(self, path: Path, raw: dict[str, Any], registry: Registry) -> None:
        self.path = path
        self.file = str(path)
        self.folder = path.parent
        self.raw = raw
        self.registry = registry
        self.oct_records: list[OctRecord] = []  # written by the runner, never while reading

    # -- small checks --------------------------------------------------------------------
    def where(self, section: str, key: str = "") -> str:
        return f"{self.file}: {section}" + (f" {key}" if key else "")

    def table(self, value: Any, where: str) -> dict[str, Any]:
        return checked(as_table, value, where)

    def tables(self, value: Any, where: str) -> list[dict[str, Any]]:
        if isinstance(value, dict):
            return [value]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise ConfigError(f"expected an array of tables, got {kind_of(value)}", where)
        return value

    def number(self, value: Any, where: str) -> float:
        return checked(as_number, value, where)

    def numbers(self, value: Any, where: str) -> dict[str, float]:
        table = self.table(value, where)
        return {str(k): self.number(v, f"{where}.{k}") for k, v in table.items()}

    def known(self, names: Sequence[str], where: str, what: str = "parameter") -> None:
        unknown = [n for n in names if n not in self.model_names]
        if unknown:
            plural = "s" if len(unknown) > 1 else ""
            raise ConfigError(
                f"the forward model {self.model_name!r} has no {what}{plural} "
                f"{', '.join(map(repr, unknown))}; it knows: {', '.join(self.model_names)}",
                where,
            )

    def plugin(self, kind: str, section: str) -> tuple[str, Any]:
        spec = parse_section(PluginSection, self.raw[section], f"{self.file}: [{section}]")
        self.registry.get(kind, spec.name, where=self.where(f"[{section}]", "name"))
        options = self.prepare_options(kind, spec.name, dict(spec.options), section)
        where = self.where(f"[{section}.options]")
        return spec.name, self.registry.create(kind, spec.name, options, where=where)

    def prepare_options(
        self, kind: str, name: str, options: dict[str, Any], section: str = ""
    ) -> dict[str, Any]:
        """Seed and start values that iterators take from the study, and path options
        relative to the study file's folder (see the module doc)."""
        options = self.resolve_paths(kind, name, options, section or kind)
        if kind != "iterator":
            return options
        fields = self.registry.get(kind, name).factory.Options.model_fields
        where = self.where("[iterator.options]")
        if "seed" in fields and "seed" not in options:
            options["seed"] = derived_seed(self.seed, ITERATOR_STREAM)
        if "x0" in fields:
            if "x0" in options:
                options["x0"] = self.starts(options["x0"], f"{where} x0")
            elif options.get("x0_from") is None and all(
                p.initial is not None for p in self.parameters
            ):  # x0_from (a posterior to start from) replaces the initial values
                options["x0"] = {p.name: p.initial for p in self.parameters}
        return options

    def resolve_paths(
        self, kind: str, name: str, options: dict[str, Any], section: str
    ) -> dict[str, Any]:
        """Relative paths given for ``Path`` options, made relative to the study's folder;
        they name input files (meshes), so a missing one is an error before any run."""
        fields = self.registry.get(kind, name).factory.Options.model_fields
        for key, value in options.items():
            spec = fields.get(key)
            if spec is None or not isinstance(value, str) or not is_path_type(spec.annotation):
                continue
            path = Path(value).expanduser()
            path = path if path.is_absolute() else (self.folder / path).resolve()
            if not path.is_file():
                problem = "file not found" if not path.exists() else "not a regular file"
                raise ConfigError(f"{problem}: {path}", self.where(f"[{section}.options]", key))
            options[key] = path
        return options

    def starts(self, x0: Any, where: str) -> Any:
        """Check initial guesses (a table or an array of tables): names and bounds."""
        if isinstance(x0, dict):
            return self.start(x0, where)
        if isinstance(x0, list) and x0 and all(isinstance(s, dict) for s in x0):
            return [self.start(s, f"{where}[{k}]") for k, s in enumerate(x0)]
        return x0  # other forms (a plain vector, ...) are the iterator's to check

    def check_x0_from(self, iterator: Any) -> None:
        """The starts an iterator read from its option ``x0_from`` (a posterior's MAP and
        mean, ``options.x0_from_starts``) against the calibration parameters: each names all
        of them and no other, inside their bounds."""
        starts = getattr(iterator.options, "x0_from_starts", None)
        if not starts:
            return
        where = self.where("[iterator.options]", "x0_from")
        labels = ("posterior MAP", "posterior mean")
        for k, start in enumerate(starts):
            at = f"{where} ({labels[k] if k < len(labels) else f'start {k + 1}'})"
            names = [p.name for p in self.parameters]
            if sorted(start) != sorted(names):
                raise ConfigError(
                    f"the posterior is of the parameters {', '.join(start)}; the study "
                    f"calibrates {', '.join(names)}",
                    at,
                )
            self.start(start, at)

    def start(self, x0: dict[str, Any], where: str) -> dict[str, float]:
        by_name = {p.name: p for p in self.parameters}
        unknown = [k for k in x0 if k not in by_name]
        if unknown:
            raise ConfigError(
                f"unknown parameter(s) {', '.join(map(repr, unknown))}; "
                f"valid: {', '.join(by_name)}",
                where,
            )
        out: dict[str, float] = {}
        for p in self.parameters:
            if p.name in x0:
                v = self.number(x0[p.name], f"{where}.{p.name}")
                if p.bounds is not None and not p.bounds[0] <= v <= p.bounds[1]:
                    raise ConfigError(
                        f"initial guess {v:g} lies outside bounds "
                        f"[{p.bounds[0]:g}, {p.bounds[1]:g}]",
                        f"{where}.{p.name}",
                    )
                out[p.name] = v
            elif p.initial is not None:
                out[p.name] = p.initial
            else:
                raise ConfigError(
                    f"no value for parameter {p.name!r} (and it has no 'initial')", where
                )
        return out

    # -- sections ------------------------------------------------------------------------
    def read(self, sources: StudySources) -> Study:
        raw = self.raw
        unknown = [k for k in raw if k not in SECTIONS]
        if unknown:
            plural = "s" if len(unknown) > 1 else ""
            raise ConfigError(
                f"unknown section{plural} {', '.join(f'[{k}]' for k in unknown)}; "
                f"valid sections: {', '.join(f'[{k}]' for k in SECTIONS)}",
                self.file,
            )
        for required in ("model", "parameters", "measure"):
            if required not in raw:
                brackets = "[[parameters]]" if required == "parameters" else f"[{required}]"
                raise ConfigError(f"missing section {brackets}", self.file)
        if "observations" not in raw and "synthetic" not in raw:
            raise ConfigError(
                "no observations: give [[observations]] (data files) or [synthetic]", self.file
            )

        meta = parse_section(StudySection, raw.get("study", {}), self.where("[study]"))
        name = meta.name or self.path.stem
        self.seed = meta.seed
        output = self.folder / meta.output
        store = store_file(self.folder, meta.store, self.where("[study]", "store"))
        if store is not None and store.exists() and not store.is_file():
            raise ConfigError(
                f"{meta.store!r} is not a regular file ({_file_kind(store)}): name the "
                "store's file, e.g. 'runs.sqlite'",
                self.where("[study]", "store"),
            )

        self.model_name, model = self.plugin("forward_model", "model")
        try:
            self.model_names = [str(n) for n in model.parameter_names()]
        except ConfigError as exc:  # a file the model reads to know them (a mesh's regions)
            raise ConfigError(str(exc), self.where("[model.options]")) from None
        except Exception as exc:  # a plugin bug, reported where it shows
            raise ConfigError(
                f"forward model {self.model_name!r} failed to list its parameters: "
                f"{type(exc).__name__}: {exc}",
                self.where("[model]"),
            ) from None
        self.model_dim = _model_dim(model)
        self.model_up = model.up_axis

        self.parameters = self.read_parameters("parameters")
        uncertain = self.read_parameters("uncertain") if "uncertain" in raw else []
        fixed = self.numbers(raw.get("fixed", {}), self.where("[fixed]"))
        self.known(list(fixed), self.where("[fixed]"), "input")
        taken = {p.name: "[[parameters]]" for p in self.parameters}
        for p in uncertain:
            if p.name in taken:
                raise ConfigError(
                    f"{p.name!r} is both a calibration parameter and uncertain",
                    self.where("[[uncertain]]", repr(p.name)),
                )
            taken[p.name] = "[[uncertain]]"
        for k in fixed:
            if k in taken:
                raise ConfigError(
                    f"{k!r} is fixed here and also listed in {taken[k]}",
                    self.where("[fixed]", k),
                )

        observations = self.read_observations() if "observations" in raw else []
        synthetic = self.read_synthetic() if "synthetic" in raw else None

        measure_name, measure = self.plugin("measure", "measure")

        likelihood = parse_section(
            LikelihoodSection, raw.get("likelihood", {}), self.where("[likelihood]")
        )
        noise_std = likelihood.noise_std
        noise_prior = None
        if likelihood.noise_prior is not None:
            where = self.where("[likelihood]", "noise_prior")
            if noise_std is not None:
                raise ConfigError(
                    "sigma_N is either known (noise_std) or inferred (noise_prior), not both",
                    where,
                )
            try:
                noise_prior = Prior.from_spec(likelihood.noise_prior)
            except ConfigError as err:
                raise err.located(where) from None

        iterator_name, iterator = (
            self.plugin("iterator", "iterator") if "iterator" in raw else (None, None)
        )
        if iterator is not None:
            self.check_x0_from(iterator)
        executor = self.read_executor()
        paper = (
            read_paper(raw["paper"], self.file, iterator is not None) if "paper" in raw else None
        )

        study = Study(
            path=self.path,
            name=name,
            seed=self.seed,
            output=output,
            store=store,
            model=model,
            model_name=self.model_name,
            measure=measure,
            measure_name=measure_name,
            parameters=self.parameters,
            uncertain=uncertain,
            fixed=fixed,
            observations=observations,
            synthetic=synthetic,
            noise_std=noise_std,
            noise_prior=noise_prior,
            iterator=iterator,
            iterator_name=iterator_name,
            executor=executor,
            raw=raw,
            text=sources.text,
            sha256=sources.sha256,
            bases=sources.bases,
            overrides=sources.overrides,
            paper=paper,
            oct_records=tuple(self.oct_records),
        )
        if synthetic is None:
            _ = study.problem  # no forward run needed: check the whole problem now
        return study

    def read_parameters(self, section: str) -> list[Parameter]:
        model: type[ParameterSection | UncertainSection] = (
            ParameterSection if section == "parameters" else UncertainSection
        )
        out: list[Parameter] = []
        for k, raw in enumerate(self.tables(self.raw[section], self.where(f"[[{section}]]"))):
            label = repr(raw["name"]) if isinstance(raw.get("name"), str) else f"#{k + 1}"
            where = self.where(f"[[{section}]]", label)
            spec = parse_section(model, raw, where)
            name = spec.name
            self.known([name], f"{where} name")
            if any(p.name == name for p in out):
                raise ConfigError(f"parameter {name!r} is listed twice", where)
            bounds = spec.bounds
            if bounds is not None and not bounds[0] < bounds[1]:
                raise ConfigError(
                    f"lower bound {bounds[0]:g} is not below upper bound {bounds[1]:g}",
                    f"{where} bounds",
                )
            prior: Prior | None = None
            if spec.prior is not None:
                try:
                    prior = Prior.from_spec(spec.prior, bounds)
                except ConfigError as err:
                    raise err.located(f"{where} prior") from None
            elif section == "uncertain":
                raise ConfigError("an uncertain input needs a prior", where)
            if bounds is None and (prior is None or not all(map(math.isfinite, prior.support))):
                raise ConfigError(
                    "needs bounds = [lower, upper] (or a prior with finite support)", where
                )
            initial = getattr(spec, "initial", None)
            if initial is not None:
                lo, hi = bounds if bounds is not None else prior.support  # type: ignore[union-attr]
                if not lo <= initial <= hi:
                    raise ConfigError(
                        f"initial guess {initial:g} lies outside bounds [{lo:g}, {hi:g}]",
                        f"{where} initial",
                    )
            try:
                out.append(Parameter(name, bounds, prior, spec.unit, initial))
            except ConfigError as err:
                raise ConfigError(err.reason, where) from None
        if not out:
            raise ConfigError("no parameters", self.where(f"[[{section}]]"))
        return out

    def read_observations(self) -> list[Observation]:
        out: list[Observation] = []
        specs = self.tables(self.raw["observations"], self.where("[[observations]]"))
        for k, raw in enumerate(specs):
            where = self.where("[[observations]]", f"#{k + 1}")
            spec = parse_section(ObservationSection, raw, where)
            coordinate = check_coordinate(spec.coordinate, f"{where} coordinate")
            if spec.interface is None and spec.points is None and spec.oct is None:
                raise ConfigError("needs 'interface' or 'oct', 'points' (a file) or both", where)
            gamma = None if spec.oct is None else self.oct_scan(spec.oct, k, f"{where} oct")
            if spec.interface is not None:
                try:
                    gamma = Interface.read(self.folder / spec.interface)
                except ConfigError as err:
                    raise err.located(f"{where} interface") from None
                self.dimension(gamma.dim, f"{where} interface")
            points = None
            if spec.points is not None:
                try:
                    points = MeasurementPoints.read(self.folder / spec.points)
                except ConfigError as err:
                    raise err.located(f"{where} points") from None
                self.dimension(points.dim, f"{where} points")
            try:
                out.append(
                    Observation(gamma, coordinate, points, noise_std=spec.noise_std, name=spec.name)
                )
            except ConfigError as err:
                raise ConfigError(err.reason, where) from None
        dims = {o.dim for o in out}
        if len(dims) > 1:
            raise ConfigError(
                f"observations mix dimensions {sorted(dims)}", self.where("[[observations]]")
            )
        return out

    def oct_scan(self, value: Any, k: int, where: str) -> Interface:
        from .study_oct import OctRecord, read_oct_scan

        self.dimension(3, where)
        self.height_axis(value, where)
        scan = read_oct_scan(value, self.folder, where)
        self.oct_records.append(OctRecord(k + 1, scan))
        return scan.interface

    def height_axis(self, value: Any, where: str) -> None:
        """An OCT scan's ``height_axis`` against the axis the forward model declares up
        (``up_axis``, optional in its contract), before the scan is segmented."""
        up = self.model_up
        given = value.get("height_axis", "z") if isinstance(value, dict) else "z"
        if up in ("z", "y") and given in ("z", "y") and given != up:
            raise ConfigError(
                f"height_axis = {given!r}, but the forward model {self.model_name!r} has the "
                f"height above the substratum along {up}: give height_axis = {up!r}",
                f"{where} height_axis",
            )

    def dimension(self, dim: int, where: str) -> None:
        if isinstance(self.model_dim, int) and dim != self.model_dim:
            raise ConfigError(
                f"{dim}-D data for the {self.model_dim}-D forward model {self.model_name!r}",
                where,
            )

    def read_synthetic(self) -> SyntheticSpec:
        where = self.where("[synthetic]")
        spec = parse_section(SyntheticSection, self.raw["synthetic"], where)
        truth = self.numbers(spec.truth, f"{where} truth")
        self.known(list(truth), f"{where} truth")
        missing = [p.name for p in self.parameters if p.name not in truth]
        if missing:
            raise ConfigError(
                f"no true value for parameter(s) {', '.join(map(repr, missing))}",
                f"{where} truth",
            )
        coords = [
            check_coordinate(c, f"{where} coordinates[{k}]")
            for k, c in enumerate(self.tables(spec.coordinates, f"{where} coordinates"))
        ]
        if not coords:
            raise ConfigError("needs at least one coordinate", f"{where} coordinates")
        seed = spec.seed if spec.seed is not None else derived_seed(self.seed, SYNTHETIC_STREAM)
        extra = (spec.placement, spec.significant, spec.draws)
        return SyntheticSpec(truth, coords, spec.noise_std, spec.points, seed, spec.noise, *extra)

    def read_executor(self) -> ExecutorSpec:
        where = self.where("[executor]")
        spec = parse_section(ExecutorSection, self.raw.get("executor", {}), where)
        if spec.address is not None:
            check_scheduler_address(spec.address, f"{where} address")
        return ExecutorSpec(
            spec.kind,
            spec.workers,
            bool(spec.keep_runs),
            spec.timeout,
            spec.isolate,
            spec.address,
            spec.cluster,
            dict(spec.cluster_options),
        )


def _file_kind(path: Path) -> str:
    """What a path that is no regular file is, in words."""
    mode = path.stat().st_mode
    kinds = [(stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a folder")]
    return next((name for test, name in kinds if test(mode)), "a device")


def _model_dim(model: Any) -> int | None:
    """The spatial dimension of a model's interfaces, when it tells (a ``dim`` attribute, or
    an ``undeformed()`` interface); None otherwise (then checked on the first run)."""
    dim = model.dim
    if isinstance(dim, int) and not isinstance(dim, bool):
        return dim
    try:
        gamma = model.undeformed()
    except Exception:  # an optional extra that failed: the first run will tell
        return None
    return gamma.dim if isinstance(gamma, Interface) else None
