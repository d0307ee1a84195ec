"""OCT scans in study files: ``[[observations]] oct = ...`` is segmented when the study is read.

>>> from pathlib import Path
>>> import numpy as np
>>> from fbia.testing.oct import oct_phantom
>>> ph = oct_phantom(shape=(24, 20, 20), seed=0)
>>> np.save("scan.npy", ph.volume)
>>> where = "study.toml: [[observations]] #1 oct"
>>> scan = read_oct_scan({"file": "scan.npy", "voxel_size": [0.01, 0.02, 0.02]}, Path("."), where)
>>> scan.interface.dim, scan.segmentation.substratum_row
(3, 20)
>>> record = OctRecord(1, scan)
>>> record.folder, [p.name for p in record.write(Path("output"))]
('oct/observation_1', ['oct_bscan.png', 'oct_surface.png', 'segmented.vtu', 'segmentation.json'])
>>> read_oct_scan({"file": "scan.npy", "voxel_size": [0.01, 0.02]}, Path("."), where)
... # doctest: +ELLIPSIS
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: study.toml: [[observations]] #1 oct: option 'voxel_size': ...

Until now a user segmented a scan in Python (:func:`fbia.imaging.oct.segment_oct`) and wrote a
surface file for ``interface = ...``; ``oct`` does both steps from the study file (issue 18).
Its value is a scan file (``.npy``, ``.npz``, TIFF, NRRD, Thorlabs ``.oct``;
:mod:`fbia.imaging.oct_reader`),
relative to the study file, or a table of the scan and its options (:class:`OctScanOptions`):
``file``; ``voxel_size`` (dz, dy, dx) [mm]; ``height_axis``, the forward model's axis along
the height above the substratum (``"z"``, fbia's frame, or ``"y"`` for ``ale_fsi``'s 3-D
geometries: :func:`fbia.imaging.oct.in_model_axes`); and every option of
:class:`fbia.imaging.oct.OctOptions` (``threshold``, ``attenuation`` [1/mm], ``crop_mm`` [mm],
``denoise``, ...).  Without ``voxel_size`` it is read from a Thorlabs ``.oct`` file's own
header, or from ``voxel_size_mm`` of a JSON file of the scan's stem beside it
(``data/scan.json`` for ``data/scan.npy``, as ``examples/oct_3d/make_scan.py`` writes).

Reading a study writes nothing (``fbia validate`` leaves every folder as it was): the study
keeps one :class:`OctRecord` per scan (:attr:`fbia.studies.study.Study.oct_records`), and the
runner writes them with :func:`write_oct_record` into the output folder the command actually
uses (``--output``), once it holds that folder's lock, so a run refused because another one
is running there changes none of its files (issue 44 item 3).  A record is the figures of
:func:`fbia.studies.oct_figures.write_segmentation_figures`, the surface in the model's axes
(``segmented.vtu``) and ``segmentation.json`` (the scan's SHA-256, the options, threshold,
attenuation, substratum row and tilt, the window and the other flat reflections found, the
kind of surface, whether it is one surface (:class:`fbia.imaging.oct_structure.OctQuality`),
the structure parameters (:class:`fbia.imaging.oct_structure.OctStructure`) and the SHA-256
of the surface), in
``<output>/oct/observation_<k>/``.  Resume: a study's
fingerprint holds the SHA-256 of every observed interface (:mod:`fbia.storage.fingerprints`), so
a new scan or an option that changes the segmented surface makes ``fbia run`` compare its
stored forward runs anew with the new surface, and one that leaves the surface bit-equal
reuses everything.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import Field, field_validator

from ..core.errors import ConfigError
from ..core.interface import Interface
from ..imaging.oct import HeightAxis, OctOptions, OctSegmentation, in_model_axes, segment_oct
from ..imaging.oct_reader import oct_file_voxel_size
from ..storage.fingerprints import interface_digest

__all__ = ["OctRecord", "OctScan", "OctScanOptions", "read_oct_scan", "write_oct_record"]


#: the voxel sizes an OCT scan can have [mm]: 10 nm to 1 mm
VOXEL_MM = (1e-5, 1.0)


class OctScanOptions(OctOptions):
    """``[[observations]] oct``: the scan, its voxels and axes, and how to segment it."""

    file: str = Field(
        min_length=1,
        description="the scan (.npy, .npz, .tif, .nrrd, Thorlabs .oct), relative to the study file",
    )
    voxel_size: tuple[float, float, float] | None = Field(
        None,
        description="(dz, dy, dx) [mm]; None: voxel_size_mm of the JSON file beside the scan",
    )
    height_axis: HeightAxis = Field(
        "z", description="the model's axis along the height above the substratum: z or y"
    )

    @field_validator("voxel_size", mode="before")
    @classmethod
    def _check_voxel_size(cls, value: Any) -> Any:
        ok = isinstance(value, list | tuple) and len(value) == 3
        ok = ok and all(
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and v > 0
            for v in value
        )
        if value is not None and not ok:
            raise ValueError("must be three positive numbers [dz, dy, dx] in mm")
        if value is not None and not all(VOXEL_MM[0] <= v <= VOXEL_MM[1] for v in value):
            raise ValueError(
                f"{list(value)} mm lies outside {VOXEL_MM[0]:g}-{VOXEL_MM[1]:g} mm, where OCT "
                "voxels are (micrometres to a tenth of a millimetre): give it in mm"
            )
        return value


@dataclass(frozen=True)
class OctScan:
    """A scan read for a study: where it came from, how it was segmented, the surface.

    Attributes
    ----------
    file
        The scan file.
    sha256
        SHA-256 of its bytes.
    options
        The options it was segmented with.
    voxel_size
        (dz, dy, dx) [mm] (given or read beside the scan).
    segmentation
        What :func:`fbia.imaging.oct.segment_oct` found (the surface in the scan's axes).
    interface
        The surface in the forward model's axes (``options.height_axis``): the observation.
    """

    file: Path
    sha256: str
    options: OctScanOptions
    voxel_size: tuple[float, float, float]
    segmentation: OctSegmentation
    interface: Interface


@dataclass(frozen=True)
class OctRecord:
    """What a study writes of the scan of its ``observation``-th ``[[observations]]`` table
    (counted from 1, as the study file's messages count them), kept in memory from reading
    until a run writes it into its output folder (:meth:`write`)."""

    observation: int
    scan: OctScan

    @property
    def folder(self) -> str:
        """Where the record goes, relative to the output folder."""
        return f"oct/observation_{self.observation}"

    def write(self, output: Path) -> list[Path]:
        """Write the record into ``output``/:attr:`folder` (the caller holds ``output``'s
        lock: :class:`fbia.storage.output_folder.OutputLock`); returns the paths."""
        return write_oct_record(self.scan, output / self.folder)


def read_oct_scan(value: Any, folder: Path, where: str) -> OctScan:
    """Read and segment the scan of an ``oct`` value (a file name or a table; see the module
    docstring), paths relative to ``folder``; every mistake is one ConfigError at ``where``."""
    if isinstance(value, str):
        table: dict[str, Any] = {"file": value}
    elif isinstance(value, dict):
        table = dict(value)
    else:
        raise ConfigError(
            f"expected a scan file or a table {{ file = ..., voxel_size = [...] }}, got {value!r}",
            where,
        )
    if "file" not in table:
        raise ConfigError("missing key 'file' (the scan)", where)
    options = OctScanOptions.parse(table, where)
    path = Path(options.file).expanduser()
    path = path if path.is_absolute() else folder / path
    if not path.is_file():
        raise ConfigError(f"{options.file}: scan file not found", where)
    voxel_size = options.voxel_size or _voxel_size_of(path, options.file, where)
    try:
        seg = segment_oct(path, voxel_size, options)
    except ConfigError as err:
        raise err.located(where) from None
    sha256 = hashlib.sha256(path.read_bytes()).hexdigest()
    surface = in_model_axes(seg.interface, options.height_axis)
    return OctScan(path, sha256, options, voxel_size, seg, surface)


def _voxel_size_of(path: Path, name: str, where: str) -> tuple[float, float, float]:
    """The voxel size a scan file carries (a Thorlabs ``.oct`` header's ranges), or the one
    of the JSON file beside it."""
    if path.suffix.lower() == ".oct":
        try:
            return oct_file_voxel_size(path)
        except ConfigError as err:
            raise err.located(where) from None
    return _voxel_size_beside(path, name, where)


def _voxel_size_beside(path: Path, name: str, where: str) -> tuple[float, float, float]:
    """``voxel_size_mm`` of the JSON file of the scan's stem beside it."""
    meta = path.with_suffix(".json")
    hint = f"give oct = {{ file = {name!r}, voxel_size = [dz, dy, dx] }} (mm)"
    if not meta.is_file():
        raise ConfigError(f"no voxel size: {hint}, or voxel_size_mm in {meta.name}", where)
    try:
        size = json.loads(meta.read_text(encoding="utf-8"))["voxel_size_mm"]
    except RecursionError:
        raise ConfigError(f"{meta.name}: nested too deeply; {hint}", where) from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        message = f"{meta.name}: no voxel_size_mm ({type(exc).__name__}: {exc}); {hint}"
        raise ConfigError(message, where) from None
    parsed = OctScanOptions.parse({"file": name, "voxel_size": size}, f"{where}: {meta.name}")
    if parsed.voxel_size is None:
        raise ConfigError(f"{meta.name}: voxel_size_mm is null; {hint}", where)
    return parsed.voxel_size


def write_oct_record(scan: OctScan, folder: Path) -> list[Path]:
    """The segmentation's figures, the surface in the model's axes (``segmented.vtu``) and
    ``segmentation.json`` in ``folder``; returns the paths."""
    from .oct_figures import write_segmentation_figures

    paths = write_segmentation_figures(scan.segmentation, folder)
    surface = scan.interface.write(folder / "segmented.vtu")
    seg = scan.segmentation
    options = scan.options.model_dump(exclude={"file", "voxel_size"})
    record = {
        "scan": str(scan.file),
        "scan_sha256": scan.sha256,
        "voxel_size_mm": list(scan.voxel_size),
        "options": options,
        "threshold": seg.threshold,
        "attenuation_per_mm": seg.attenuation,
        "substratum_row": seg.substratum_row,
        "substratum_tilt_rows_per_ascan": list(seg.tilt),
        "window_row": seg.window_row,
        "reflections": [
            {
                "row": r.row + seg.origin[0],
                "slope": list(r.slope),
                "support": r.support,
                "contrast": r.contrast,
                "kind": r.kind,
            }
            for r in seg.reflections
        ],
        "surface_kind": seg.surface_kind,
        "quality": seg.quality.to_dict(),
        "structure_mm": seg.structure.to_dict(),
        "biofilm_voxels": seg.biofilm_voxels,
        "surface": {
            "file": surface.name,
            "vertices": len(scan.interface.vertices),
            "triangles": len(scan.interface.cells),
            "sha256": interface_digest(scan.interface),
        },
    }
    meta = folder / "segmentation.json"
    meta.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return [*paths, surface, meta]
