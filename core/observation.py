"""Observed and simulated states: :class:`Observation`, :class:`Solution`, coordinates.

A *coordinate* says which state of an experiment a snapshot shows, e.g.
``{"inflow_rate": 100.0}`` (mm²/s) or ``{"time": 15.0}`` (s).

>>> import numpy as np, fbia
>>> x = np.linspace(0.0, 1.0, 11)
>>> obs = fbia.Observation(interface=fbia.Interface.polyline(np.c_[x, 0.1 * x]),
...                        coordinate={"inflow_rate": 100.0}, noise_std=0.01)
>>> obs.key
(('inflow_rate', 100.0),)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .data_files import check_coordinates, read_csv_table
from .errors import ConfigError
from .interface import Interface

#: The columns of a measurement-point CSV file, with or without a header row.
POINT_LAYOUTS = (
    ("x", "y"),
    ("x", "y", "z"),
    ("x", "y", "dx", "dy"),
    ("x", "y", "z", "dx", "dy", "dz"),
)

Coordinate = Mapping[str, float]
CoordinateKey = tuple[tuple[str, float], ...]


def coordinate_key(coordinate: Coordinate) -> CoordinateKey:
    """A hashable, order-independent key of a coordinate."""
    return tuple(sorted((str(k), float(v)) for k, v in coordinate.items()))


def check_coordinate(coordinate: Coordinate, where: str = "coordinate") -> dict[str, float]:
    out: dict[str, float] = {}
    for k, v in coordinate.items():
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise ConfigError(f"value of {k!r} must be a number, got {v!r}", where) from None
        if not math.isfinite(fv):
            raise ConfigError(f"value of {k!r} is not finite ({v!r})", where)
        out[str(k)] = fv
    return out


@dataclass(frozen=True)
class MeasurementPoints:
    """Measurement points on an observed interface, each with a search direction (Paper A)."""

    points: NDArray[np.float64]
    directions: NDArray[np.float64] | None = None

    def __post_init__(self) -> None:
        p = np.array(self.points, dtype=float)
        if p.ndim != 2 or p.shape[1] not in (2, 3) or len(p) == 0:
            raise ConfigError(f"measurement points must have shape (n, 2) or (n, 3), got {p.shape}")
        check_coordinates(p, "measurement points")
        object.__setattr__(self, "points", p)
        if self.directions is not None:
            d = np.array(self.directions, dtype=float)
            if d.shape != p.shape:
                raise ConfigError(
                    f"measurement directions must have the points' shape {p.shape}, got {d.shape}"
                )
            if not np.all(np.isfinite(d)):
                raise ConfigError("measurement directions contain NaN or infinite values")
            norm = np.linalg.norm(d, axis=1)
            if np.any(norm == 0.0):
                raise ConfigError(f"measurement direction {int(np.argmin(norm))} is zero")
            object.__setattr__(self, "directions", d / norm[:, None])

    @property
    def dim(self) -> int:
        return int(self.points.shape[1])

    def __len__(self) -> int:
        return len(self.points)

    @classmethod
    def read(cls, path: str | Path) -> MeasurementPoints:
        """CSV with columns ``x, y[, z]`` or ``x, y[, z], dx, dy[, dz]``.

        A header row is optional and, if there, names one of these layouts; the file is read
        by :func:`fbia.core.data_files.read_csv_table` (strict UTF-8, no row skipped in
        silence, values finite and below ``MAX_COORDINATE`` in magnitude).
        """
        path = Path(path)
        if not path.is_file():
            raise ConfigError("file not found", str(path))
        table = read_csv_table(path, POINT_LAYOUTS)  # 2, 3, 4 or 6 columns
        dim = {2: 2, 3: 3, 4: 2, 6: 3}[table.shape[1]]
        try:
            if table.shape[1] == dim:
                return cls(table)
            return cls(table[:, :dim], table[:, dim:])
        except ConfigError as err:
            raise err.located(str(path)) from None

    def write(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        names = ["x", "y", "z"][: self.dim]
        header = names + ([f"d{n}" for n in names] if self.directions is not None else [])
        data = self.points if self.directions is None else np.c_[self.points, self.directions]
        np.savetxt(path, data, delimiter=",", header=",".join(header), comments="", fmt="%.17g")
        return path


@dataclass(frozen=True)
class Observation:
    """One observed state of the experiment.

    Parameters
    ----------
    interface
        The observed (segmented) interface; needed by the ``cpp`` and ``rkhs`` measures.  Its
        coordinates, like the points', must be below ``MAX_COORDINATE`` (1e9 mm) in magnitude.
    coordinate
        Which state it is, e.g. ``{"inflow_rate": 100.0}``.
    points
        Optional measurement points (with optional directions) for the ``ray`` measure; an
        (n, dim) array or :class:`MeasurementPoints`.
    directions
        Search directions of ``points`` if given as an array; default: the observed normal.
    noise_std
        Standard deviation of the observation noise in mm (overrides the problem's default).
    name
        A label for reports.
    """

    interface: Interface | None = None
    coordinate: Coordinate = field(default_factory=dict)
    points: MeasurementPoints | ArrayLike | None = None
    directions: ArrayLike | None = None
    noise_std: float | None = None
    name: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "coordinate", check_coordinate(self.coordinate))
        pts = self.points
        if pts is not None and not isinstance(pts, MeasurementPoints):
            pts = MeasurementPoints(np.asarray(pts, dtype=float), self.directions)  # type: ignore[arg-type]
        elif isinstance(pts, MeasurementPoints) and self.directions is not None:
            pts = MeasurementPoints(pts.points, np.asarray(self.directions, dtype=float))
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "directions", None)
        if self.interface is not None:
            check_coordinates(self.interface.vertices, "observed interface vertices")
        if self.interface is None and pts is None:
            raise ConfigError("an observation needs an interface, measurement points or both")
        if self.interface is not None and pts is not None and self.interface.dim != pts.dim:
            raise ConfigError(
                f"observation mixes a {self.interface.dim}-D interface with {pts.dim}-D points"
            )
        if self.noise_std is not None:
            s = float(self.noise_std)
            if not (math.isfinite(s) and s > 0):
                raise ConfigError(f"noise_std must be a positive number, got {self.noise_std}")
            object.__setattr__(self, "noise_std", s)

    @property
    def key(self) -> CoordinateKey:
        return coordinate_key(self.coordinate)

    @property
    def dim(self) -> int:
        if self.interface is not None:
            return self.interface.dim
        assert isinstance(self.points, MeasurementPoints)
        return self.points.dim

    @property
    def measurement_points(self) -> MeasurementPoints | None:
        return self.points if isinstance(self.points, MeasurementPoints) else None

    def label(self) -> str:
        return self.name or ", ".join(f"{k}={v:g}" for k, v in self.coordinate.items()) or "state"

    @classmethod
    def read(
        cls,
        interface: str | Path | None = None,
        points: str | Path | None = None,
        coordinate: Coordinate | None = None,
        noise_std: float | None = None,
        name: str = "",
    ) -> Observation:
        """Read an observation from files: an interface (CSV 2-D, STL/PLY/OBJ/VTK/VTU 3-D)
        and/or measurement points (CSV)."""
        gamma = Interface.read(interface) if interface is not None else None
        mp = MeasurementPoints.read(points) if points is not None else None
        return cls(gamma, coordinate or {}, mp, noise_std=noise_std, name=name)


@dataclass
class Solution:
    """What a forward run returns: one interface per requested coordinate, plus extras.

    Parameters
    ----------
    interfaces
        ``coordinate_key(c) -> Interface`` for every requested coordinate ``c``.
    fields
        Paths of field files (e.g. VTU for ParaView), by name.
    diagnostics
        Solver facts: Newton iterations, dofs, wall time, ...
    """

    interfaces: dict[CoordinateKey, Interface]
    fields: dict[str, Path] = field(default_factory=dict)
    diagnostics: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_pairs(cls, pairs: Iterable[tuple[Coordinate, Interface]], **kwargs: Any) -> Solution:
        return cls({coordinate_key(c): g for c, g in pairs}, **kwargs)

    def interface(self, coordinate: Coordinate) -> Interface:
        key = coordinate_key(coordinate)
        try:
            return self.interfaces[key]
        except KeyError:
            have = ", ".join(str(dict(k)) for k in self.interfaces) or "none"
            raise KeyError(f"no interface for coordinate {dict(key)}; have {have}") from None

    def covers(self, coordinates: Sequence[Coordinate]) -> bool:
        return all(coordinate_key(c) in self.interfaces for c in coordinates)
