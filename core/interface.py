"""The fluid–biofilm interface of one state: polylines in 2-D, triangle surfaces in 3-D.

>>> import numpy as np, fbia
>>> x = np.linspace(0.0, 1.0, 5)
>>> gamma = fbia.Interface.polyline(np.c_[x, np.zeros_like(x)])
>>> gamma.normals[0]          # the tangent turned by +90 degrees (Paper B eq. 24b)
array([0., 1.])
>>> float(gamma.sizes.sum())
1.0

Orientation (docs/architecture.md): a 2-D polyline is ordered so that the solid lies on its right;
its normal, the tangent turned by +90°, points into the fluid.  3-D triangles are ordered so
that their right-hand normal points into the fluid.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .data_files import check_coordinates, read_csv_table, read_meshio
from .errors import ConfigError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: The columns of an interface CSV file (2-D), with or without a header row.
CSV_LAYOUTS = (("x", "y"), ("x", "y", "curve"))

_SURFACE_SUFFIXES = {".stl", ".ply", ".obj", ".vtk", ".vtu", ".off", ".msh", ".xdmf", ".glb"}


class Interface:
    """A discretised interface: vertices and elements (segments in 2-D, triangles in 3-D).

    A forward model asked for tangents (``solve(..., tangents=names)``) sets ``tangents``:
    per input name, d vertices / d input (the shape of ``vertices``).

    Parameters
    ----------
    vertices
        Vertex coordinates, shape (n, 2) or (n, 3), in mm.
    cells
        Element connectivity, shape (m, 2) for segments or (m, 3) for triangles; the column
        count must equal the spatial dimension.
    """

    __slots__ = ("_vertices", "_cells", "_cache", "tangents")

    def __init__(self, vertices: ArrayLike, cells: ArrayLike) -> None:
        v = np.array(vertices, dtype=float)
        c = np.array(cells, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] not in (2, 3):
            raise ConfigError(f"interface vertices must have shape (n, 2) or (n, 3), got {v.shape}")
        if c.ndim != 2 or c.shape[1] != v.shape[1]:
            raise ConfigError(
                f"a {v.shape[1]}-D interface needs cells of shape (m, {v.shape[1]}), got {c.shape}"
            )
        if len(c) == 0:
            raise ConfigError("interface has no elements")
        if not np.all(np.isfinite(v)):
            raise NonFiniteInterfaceError("interface vertices contain NaN or infinite coordinates")
        if c.min() < 0 or c.max() >= len(v):
            raise ConfigError("interface cells refer to vertices that do not exist")
        v.setflags(write=False)
        c.setflags(write=False)
        self._vertices: FloatArray = v
        self._cells: IntArray = c
        self._cache: dict[str, FloatArray] = {}
        self.tangents: dict[str, FloatArray] = {}
        if np.any(self.sizes <= 0.0):
            n = int(np.count_nonzero(self.sizes <= 0.0))
            kind = "length" if self.dim == 2 else "area"
            raise ConfigError(f"interface has {n} element(s) of zero {kind}")

    # -- construction ------------------------------------------------------------------------
    @classmethod
    def polyline(cls, points: ArrayLike, closed: bool = False) -> Interface:
        """One 2-D polyline through ``points`` (n, 2), in order (solid on the right)."""
        return cls.polylines([points], closed=closed)

    @classmethod
    def polylines(cls, curves: Sequence[ArrayLike], closed: bool = False) -> Interface:
        """Several 2-D polylines, each an (n_k, 2) array of points in order."""
        vertices, cells, offset = [], [], 0
        for k, pts in enumerate(curves):
            p = np.asarray(pts, dtype=float)
            if p.ndim != 2 or p.shape[1] != 2 or len(p) < 2:
                raise ConfigError(f"polyline {k} needs at least two points of shape (n, 2)")
            idx = np.arange(len(p)) + offset
            seg = np.c_[idx[:-1], idx[1:]]
            if closed:
                seg = np.vstack([seg, [idx[-1], idx[0]]])
            vertices.append(p)
            cells.append(seg)
            offset += len(p)
        if not vertices:
            raise ConfigError("an interface needs at least one polyline")
        return cls(np.vstack(vertices), np.vstack(cells))

    @classmethod
    def surface(cls, vertices: ArrayLike, triangles: ArrayLike) -> Interface:
        """A 3-D triangle surface; each triangle's right-hand normal points into the fluid."""
        v = np.asarray(vertices, dtype=float)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ConfigError(f"surface vertices must have shape (n, 3), got {v.shape}")
        return cls(v, triangles)

    # -- geometry ----------------------------------------------------------------------------
    @property
    def vertices(self) -> FloatArray:
        return self._vertices

    @property
    def cells(self) -> IntArray:
        return self._cells

    @property
    def dim(self) -> int:
        """Spatial dimension, 2 or 3."""
        return int(self._vertices.shape[1])

    @property
    def element_points(self) -> FloatArray:
        """Vertex coordinates of every element, shape (m, dim, dim)."""
        return self._vertices[self._cells]

    def _cached(self, key: str) -> FloatArray:
        if key not in self._cache:
            p = self.element_points
            if key == "centres":
                val = p.mean(axis=1)
            elif key == "area_vectors":
                if self.dim == 2:
                    t = p[:, 1] - p[:, 0]
                    # tangent turned by +90° (eq. 24b); + 0.0 turns -0.0 into 0.0
                    val = np.c_[-t[:, 1], t[:, 0]] + 0.0
                else:
                    val = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            else:  # pragma: no cover - internal misuse
                raise KeyError(key)
            val.setflags(write=False)
            self._cache[key] = val
        return self._cache[key]

    @property
    def centres(self) -> FloatArray:
        """Element centres, shape (m, dim)."""
        return self._cached("centres")

    @property
    def area_vectors(self) -> FloatArray:
        """Normals scaled by element length (2-D) or area (3-D), shape (m, dim)."""
        return self._cached("area_vectors")

    @property
    def sizes(self) -> FloatArray:
        """Element lengths (2-D) or areas (3-D), shape (m,)."""
        if "sizes" not in self._cache:
            s = np.linalg.norm(self.area_vectors, axis=1)
            s.setflags(write=False)
            self._cache["sizes"] = s
        return self._cache["sizes"]

    @property
    def normals(self) -> FloatArray:
        """Unit element normals pointing from the solid into the fluid, shape (m, dim)."""
        return self.area_vectors / self.sizes[:, None]

    @property
    def vertex_normals(self) -> FloatArray:
        """Unit vertex normals: size-weighted average of the adjacent element normals."""
        acc = np.zeros_like(self._vertices)
        for j in range(self._cells.shape[1]):
            np.add.at(acc, self._cells[:, j], self.area_vectors)
        norm = np.linalg.norm(acc, axis=1)
        norm[norm == 0.0] = 1.0
        return acc / norm[:, None]

    @property
    def measure(self) -> float:
        """Total length (2-D) or area (3-D)."""
        return float(self.sizes.sum())

    @property
    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper corner of the axis-aligned bounding box."""
        return self._vertices.min(axis=0), self._vertices.max(axis=0)

    def __len__(self) -> int:
        return len(self._cells)

    def __repr__(self) -> str:
        kind = "segments" if self.dim == 2 else "triangles"
        return f"Interface({len(self._vertices)} vertices, {len(self._cells)} {kind}, {self.dim}-D)"

    # -- derived interfaces -----------------------------------------------------------------
    def with_vertices(self, vertices: ArrayLike) -> Interface:
        """The same connectivity with new vertex positions (a deformed interface)."""
        return Interface(vertices, self._cells)

    def translated(self, shift: ArrayLike) -> Interface:
        return self.with_vertices(self._vertices + np.asarray(shift, dtype=float))

    def refined(self, times: int = 1) -> Interface:
        """The same geometry with every element split ``times`` times (2-D: in two; 3-D: in four).

        The geometry is unchanged; only the discretisation is finer.
        """
        out = self
        for _ in range(times):
            v, c = out._vertices, out._cells
            if out.dim == 2:
                mid = 0.5 * (v[c[:, 0]] + v[c[:, 1]])
                m_idx = np.arange(len(c)) + len(v)
                cells = np.vstack([np.c_[c[:, 0], m_idx], np.c_[m_idx, c[:, 1]]])
                out = Interface(np.vstack([v, mid]), cells)
            else:
                edges = np.vstack([c[:, [0, 1]], c[:, [1, 2]], c[:, [2, 0]]])
                key = np.sort(edges, axis=1)
                uniq, inv = np.unique(key, axis=0, return_inverse=True)
                inv = inv.reshape(3, len(c)).T + len(v)
                mid = 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])
                a, b, cc = c[:, 0], c[:, 1], c[:, 2]
                ab, bc, ca = inv[:, 0], inv[:, 1], inv[:, 2]
                cells = np.vstack(
                    [np.c_[a, ab, ca], np.c_[ab, b, bc], np.c_[ca, bc, cc], np.c_[ab, bc, ca]]
                )
                out = Interface(np.vstack([v, mid]), cells)
        return out

    def curves(self) -> list[FloatArray]:
        """The 2-D polylines as ordered point arrays (closed curves repeat their first point)."""
        if self.dim != 2:
            raise ValueError("curves() is defined for 2-D interfaces only")
        succ = {int(a): int(b) for a, b in self._cells}
        has_pred = {int(b) for b in self._cells[:, 1]}
        starts = [a for a in succ if a not in has_pred]
        out: list[FloatArray] = []
        seen: set[int] = set()
        for start in starts + [a for a in succ if a in has_pred]:
            if start in seen:
                continue
            chain = [start]
            seen.add(start)
            nxt = succ.get(start)
            while nxt is not None:
                chain.append(nxt)
                if nxt in seen:
                    break
                seen.add(nxt)
                nxt = succ.get(nxt)
            out.append(self._vertices[chain])
        return out

    # -- conversion --------------------------------------------------------------------------
    def to_shapely(self):  # -> shapely.MultiLineString
        """The 2-D interface as a ``shapely.MultiLineString``."""
        import shapely

        return shapely.MultiLineString([c for c in self.curves()])

    def to_trimesh(self):  # -> trimesh.Trimesh
        """The 3-D interface as a ``trimesh.Trimesh`` (no vertex merging or reordering)."""
        import trimesh

        if self.dim != 3:
            raise ValueError("to_trimesh() is defined for 3-D interfaces only")
        return trimesh.Trimesh(self._vertices, self._cells, process=False)

    # -- files -------------------------------------------------------------------------------
    @classmethod
    def read(cls, path: str | Path) -> Interface:
        """Read an interface: CSV for 2-D, any meshio/trimesh surface format for 3-D.

        CSV: one point per row, columns ``x, y`` and an optional third column ``curve`` (an
        integer id that separates several polylines); a header row is optional and, if there,
        is ``x, y`` or ``x, y, curve``.  The file is read by
        :func:`fbia.core.data_files.read_csv_table`: strict UTF-8, no row skipped in silence,
        every coordinate finite and below ``MAX_COORDINATE`` (1e9 mm) in magnitude; the same
        bound holds for the vertices of a surface file.
        """
        path = Path(path)
        if not path.is_file():
            raise ConfigError("file not found", str(path))
        try:
            if path.suffix.lower() in (".csv", ".txt"):
                return cls._read_csv(path)
            if path.suffix.lower() in _SURFACE_SUFFIXES:
                return cls._read_surface(path)
        except ConfigError as err:  # e.g. zero-length elements: say which file
            if err.where is not None:
                raise
            raise err.located(str(path)) from None
        raise ConfigError(
            f"unknown interface file type {path.suffix!r} (CSV for 2-D; "
            f"{', '.join(sorted(_SURFACE_SUFFIXES))} for 3-D)",
            str(path),
        )

    @classmethod
    def _read_csv(cls, path: Path) -> Interface:
        rows = read_csv_table(path, CSV_LAYOUTS)
        if rows.shape[1] == 2:
            curves = [rows]
        else:
            ids = rows[:, 2]
            if not np.all(ids == np.round(ids)):
                raise ConfigError("third CSV column (curve id) must hold integers", str(path))
            curves = [rows[ids == k, :2] for k in dict.fromkeys(ids.tolist())]
        # a curve whose last point repeats its first is closed (as curves() and write() give it)
        vertices, cells, offset = [], [], 0
        for k, pts in enumerate(curves):
            closed = len(pts) > 3 and np.array_equal(pts[0], pts[-1])
            if len(pts) < 2:
                raise ConfigError(f"curve {k} has fewer than two points", str(path))
            part = cls.polylines([pts[:-1] if closed else pts], closed=closed)
            vertices.append(part.vertices)
            cells.append(part.cells + offset)
            offset += len(part.vertices)
        return cls(np.vstack(vertices), np.vstack(cells))

    @classmethod
    def _read_surface(cls, path: Path) -> Interface:
        """A triangle surface read by meshio, else by trimesh (formats meshio lacks)."""
        try:
            mesh = read_meshio(path, "surface")
        except ConfigError as meshio_error:
            import trimesh

            try:
                tm: Any = trimesh.load(path, force="mesh", process=False)
                vertices, faces = np.asarray(tm.vertices, dtype=float), np.asarray(tm.faces)
            except Exception:  # noqa: BLE001 - trimesh raises many types: meshio's reason
                raise meshio_error from None
            if len(faces) == 0:  # trimesh reads garbage as an empty mesh: meshio's reason
                raise meshio_error from None
            check_coordinates(vertices, "vertex coordinates", str(path))
            return cls.surface(vertices, faces)
        tris = [b.data for b in mesh.cells if b.type == "triangle"]
        if not tris:
            raise ConfigError("mesh file has no triangle cells", str(path))
        points = np.asarray(mesh.points, dtype=float)
        check_coordinates(points, "vertex coordinates", str(path))
        return cls.surface(points[:, :3], np.vstack(tris))

    def write(self, path: str | Path) -> Path:
        """Write as CSV (2-D: x, y, curve) or any meshio format chosen by suffix (2-D or 3-D)."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() == ".csv":
            if self.dim != 2:
                raise ConfigError(
                    "CSV output is for 2-D interfaces; use .vtu/.stl/.ply for 3-D", str(path)
                )
            with path.open("w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(["x", "y", "curve"])
                for k, curve in enumerate(self.curves()):
                    for x, y in curve:
                        w.writerow([repr(float(x)), repr(float(y)), k])
            return path
        import meshio

        kind = "line" if self.dim == 2 else "triangle"
        pts = (
            self._vertices
            if self.dim == 3
            else np.c_[self._vertices, np.zeros(len(self._vertices))]
        )
        # int32 cells: PLY has no 64-bit integers (meshio would warn and cast)
        meshio.Mesh(pts, [(kind, self._cells.astype(np.int32))]).write(path)
        return path


class NonFiniteInterfaceError(ConfigError):
    """Interface vertices with NaN or infinite coordinates: bad data when read from a file,
    a failed (diverged) run when a forward model makes them."""
