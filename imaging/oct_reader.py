"""Reading OCT volumes: arrays and ``.npy``, ``.npz``, multi-page TIFF, NRRD and Thorlabs
``.oct`` files.

>>> import numpy as np
>>> bscans = np.zeros((5, 8, 6), dtype=np.uint16)    # 5 B-scans (y), 8 rows deep, 6 wide (x)
>>> read_oct_volume(bscans, depth_axis=1).shape      # depth first: (z, y, x)
(8, 5, 6)

The intensities come back in the array's own dtype (integer or floating: an int64 scan keeps
its exact values, a float64 one its range) with the depth axis first and the two other axes
in their array order (y, x); :mod:`fbia.imaging.oct` normalises and segments them.  TIFF
stacks are read by ``tifffile`` (one page per array index of the first axis), NRRD files by
``pynrrd`` in C index order, like NumPy and TIFF (the axis that varies fastest in the file is
the last).  An ``.npz`` file holds one array, or several of which one is named ``volume``.
An empty, ragged or non-numeric array, a non-finite value and a file that is not of its
suffix's type are each one :class:`~fbia.core.errors.ConfigError` line that says so.

Thorlabs ``.oct`` files, which ThorImage OCT 4.x and 5.x write for Thorlabs' spectral-domain
scanners, are read directly.  Such a file is a ZIP archive of ``Header.xml`` (root element
``Ocity``) and raw files named ``data\\<name>.data``; the processed intensity is the
``<DataFile>`` of the header whose name is ``Intensity.data``: ``Type="Real"`` and
``BytesPerPixel="4"`` (little-endian float32), ``SizeZ``, ``SizeX``, ``SizeY`` (absent or 1
for a single B-scan) and ``RangeZ``, ``RangeX``, ``RangeY`` in mm.  Its values are in dB
(10 log10 of the power), and its A-scans follow one another: depth varies fastest, then x,
then y (NumPy shape (SizeY, SizeX, SizeZ) in C order).  :func:`read_oct_volume` returns the
linear power ``10**(dB/10)``, since every step of the segmentation assumes linear
intensities (speckle statistics, Otsu's threshold, the decay ``exp(-mu d)``), as float32
(the file's own precision; the power is computed in double precision and rounded once), with
depth first (z, y, x) like the other readers; the file carries its own axis order, so a
``depth_axis`` other than 0 is refused.  :func:`read_oct_decibels` gives the dB values in
the same order and :func:`oct_file_voxel_size` the voxel size (dz, dy, dx) [mm] from the
header.  The format is taken from the MATLAB reader distributed for ThorImage OCT
(``OCTFileGetRealData.m``: ``reshape(data, [SizeZ SizeX SizeY])`` in MATLAB's column-major
order; a copy in github.com/Brian-Frost-LaPlante/OrientingGUI, ``ThorlabsFiles/``) and from
public readers that agree with it (github.com/kai-neuhaus/OCT_file_tools ``OCT_reader.py``,
github.com/ybnd/vis3d ``ML/cube/thorCube.m``); no file written by ThorImage itself was at
hand to check it.

A scan file is data, never code: a ``Header.xml`` that declares a DOCTYPE or entities is
refused before it is parsed (no entity is ever expanded), and so is an ``Intensity.data``
larger than :data:`THORLABS_MAX_BYTES` (4 GiB) by its header or by the archive's directory
(a zip bomb is refused unread); the data are then read B-scan by B-scan and must be exactly
SizeZ x SizeX x SizeY x 4 bytes (counted as they are read, not taken from the directory)
and finite.  Each refusal is one ConfigError line naming the file.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import ConfigError
from ..core.extras import require

__all__ = [
    "OCT_SUFFIXES",
    "THORLABS_MAX_BYTES",
    "oct_file_voxel_size",
    "read_oct_decibels",
    "read_oct_volume",
]

#: File types :func:`read_oct_volume` reads.
OCT_SUFFIXES = (".npy", ".npz", ".tif", ".tiff", ".nrrd", ".nhdr", ".oct")

#: The largest ``Intensity.data`` of a Thorlabs ``.oct`` file fbia reads [bytes]: 4 GiB, a
#: 1024 x 1024 x 1024 volume of float32 (its linear power takes as much again in memory).
#: Its size by the header and by the archive's directory are both checked before a byte is
#: read, so that a file whose data unpack to far more than it holds (a zip bomb) is refused.
THORLABS_MAX_BYTES = 4 * 2**30

#: the largest ``Header.xml`` read [bytes], far more than a header's text needs
_MAX_HEADER_BYTES = 16 * 2**20
#: dB values above this have a linear power 10^(dB/10) beyond float32's range (3.4e38)
_MAX_DB = 385.0
#: what reading a damaged, encrypted or foreign archive raises
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError, RuntimeError)


def read_oct_volume(source: str | Path | ArrayLike, depth_axis: int = 0) -> NDArray[Any]:
    """A 3-D intensity volume with depth first, in its own dtype, from an array or a file of
    one of the ``OCT_SUFFIXES`` types (see the module docstring); ``depth_axis`` is the array
    axis that runs along depth, from the probe towards the substratum.  A Thorlabs ``.oct``
    file gives its linear power (float32, from its dB values) in (z, y, x) order, which the
    file states, so its ``depth_axis`` must be 0."""
    where = str(source) if isinstance(source, str | Path) else "oct volume"
    if isinstance(source, str | Path):
        if Path(source).suffix.lower() == ".oct" and depth_axis != 0:
            raise ConfigError(
                f"depth_axis = {depth_axis}: a Thorlabs .oct file carries its own axis order "
                "(read depth first); leave depth_axis at 0",
                where,
            )
        data = _read_file(Path(source))
    else:
        try:
            data = np.asarray(source)
        except (TypeError, ValueError):
            raise ConfigError(
                "not an array of numbers (nested lists of unequal lengths?)", where
            ) from None
    if data.ndim != 3:
        raise ConfigError(f"an OCT volume must be a 3-D array, got shape {data.shape}", where)
    if data.size == 0:
        raise ConfigError(f"the volume is empty (shape {data.shape})", where)
    if not (np.issubdtype(data.dtype, np.integer) or np.issubdtype(data.dtype, np.floating)):
        raise ConfigError(f"OCT intensities must be real numbers, got dtype {data.dtype}", where)
    if np.issubdtype(data.dtype, np.floating):
        bad = data.size - int(np.count_nonzero(np.isfinite(data)))
        if bad:
            raise ConfigError(f"volume has {bad} NaN or infinite voxel(s)", where)
    return np.moveaxis(data, depth_axis, 0)


def read_oct_decibels(path: str | Path) -> NDArray[np.float32]:
    """The intensities of a Thorlabs ``.oct`` file as its header stores them, in dB (10 log10
    of the power), float32 with depth first (z, y, x), the scale OCT images are shown on;
    :func:`read_oct_volume` gives the linear power that segmentation needs."""
    return _read_thorlabs(Path(path), linear=False)


def oct_file_voxel_size(path: str | Path) -> tuple[float, float, float]:
    """The voxel size (dz, dy, dx) [mm] of a Thorlabs ``.oct`` file's intensity volume, from
    its header: ``RangeZ / SizeZ``, ``RangeY / SizeY`` and ``RangeX / SizeX`` of the
    ``Intensity.data`` entry (the ranges are in mm; the pixels split them evenly, as in the
    public readers named in the module docstring).

    A single B-scan (``SizeY`` 1 or absent, ``RangeY`` then ignored) is read as a volume of
    one y row, and its dy is taken equal to dx, so that the voxel size is complete (a 3-D
    segmentation needs more than one row).  ``SizeY`` above 1 with ``RangeY`` 0 or absent is
    B-scans repeated at one place (averaging), not a volume, and is refused.  ``RangeZ`` is
    taken as the header states it and fbia applies no refractive index of its own (whether
    ThorImage's depth range already holds the one set at acquisition, ``Acquisition/
    RefractiveIndex`` of Header.xml, was not checked against a ThorImage file).

    :func:`fbia.imaging.oct.segment_oct` takes this as its ``voxel_size``; a study's scan
    (:func:`fbia.studies.study_oct.read_oct_scan`) without ``voxel_size`` could take it from
    here for a ``.oct`` file, before it looks for a JSON file beside the scan."""
    p = Path(path)
    with _thorlabs_archive(p) as (_, entry):
        nz, ny, nx = entry.size
        rz, ry, rx = entry.ranges
    where = str(path)
    if rz is None or rz <= 0 or rx is None or rx <= 0:
        name, value = ("RangeZ", rz) if rz is None or rz <= 0 else ("RangeX", rx)
        raise ConfigError(
            f"Header.xml gives Intensity.data no positive {name} ({value}): the voxel size "
            "is unknown; give voxel_size (dz, dy, dx) in mm",
            where,
        )
    dz, dx = rz / nz, rx / nx
    if ny == 1:
        return (dz, dx, dx)
    if ry is None or ry <= 0:
        raise ConfigError(
            f"Header.xml gives Intensity.data {ny} B-scans (SizeY) over RangeY = {ry} mm: "
            "B-scans repeated at one place (averaging?), not a volume; average them into one",
            where,
        )
    return (dz, ry / ny, dx)


#: what a file of each NumPy type starts with (``np.load`` takes any other start for a pickle)
_MAGIC = {".npy": (b"\x93NUMPY", "a NumPy .npy file"), ".npz": (b"PK", "a NumPy .npz (zip) file")}


def _check_path(path: Path) -> None:
    """A readable regular file of one of the ``OCT_SUFFIXES`` types, not empty."""
    suffix = path.suffix.lower()
    if path.is_dir():
        raise ConfigError("is a folder, not a scan file", str(path))
    if not path.is_file():
        raise ConfigError("file not found", str(path))
    if suffix not in OCT_SUFFIXES:
        raise ConfigError(
            f"unknown OCT file type {suffix!r}; readable: {', '.join(OCT_SUFFIXES)}", str(path)
        )
    if path.stat().st_size == 0:
        raise ConfigError("the file is empty", str(path))


def _read_file(path: Path) -> NDArray[Any]:
    suffix = path.suffix.lower()
    if suffix == ".oct":
        return _read_thorlabs(path, linear=True)
    _check_path(path)
    if suffix in _MAGIC:
        magic, kind = _MAGIC[suffix]
        with path.open("rb") as f:
            if f.read(len(magic)) != magic:
                raise ConfigError(f"not {kind} (it does not start as one)", str(path))
    try:
        if suffix == ".npy":
            return np.load(path, allow_pickle=False)
        if suffix == ".npz":
            with np.load(path, allow_pickle=False) as npz:
                names = list(npz.files)
                if "volume" in names:
                    return npz["volume"]
                if len(names) != 1:
                    raise ConfigError(
                        f"npz file holds {len(names)} arrays ({', '.join(names)}); name one "
                        "'volume'",
                        str(path),
                    )
                return npz[names[0]]
        if suffix in (".tif", ".tiff"):
            require(("tifffile",), "reading a TIFF stack")
            import tifffile

            return np.asarray(tifffile.imread(path))
        require(("nrrd",), "reading an NRRD file")
        import nrrd

        data, _ = nrrd.read(str(path), index_order="C")
        return np.asarray(data)
    except ConfigError:
        raise
    except Exception as exc:
        if "allow_pickle" in str(exc):  # NumPy's advice to unpickle, which fbia never does
            raise ConfigError("holds Python objects, not intensities", str(path)) from None
        raise ConfigError(f"cannot read OCT volume: {exc}", str(path)) from None


# -- Thorlabs .oct ---------------------------------------------------------------------------
@dataclass(frozen=True)
class _Intensity:
    """The ``Intensity.data`` entry of a ``Header.xml``: its archive member, (SizeZ, SizeY,
    SizeX) and (RangeZ, RangeY, RangeX) [mm] (None where the header gives none)."""

    member: zipfile.ZipInfo
    size: tuple[int, int, int]
    ranges: tuple[float | None, float | None, float | None]

    @property
    def nbytes(self) -> int:
        nz, ny, nx = self.size
        return nz * ny * nx * 4


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


@contextmanager
def _thorlabs_archive(path: Path) -> Iterator[tuple[zipfile.ZipFile, _Intensity]]:
    """The open archive of a Thorlabs ``.oct`` file and its header's intensity entry."""
    where = str(path)
    _check_path(path)
    if path.suffix.lower() != ".oct":
        raise ConfigError("not a Thorlabs .oct file (its suffix is not .oct)", where)
    try:
        archive = zipfile.ZipFile(path)
    except (*_ZIP_ERRORS, OSError, ValueError) as exc:
        raise ConfigError(
            f"not a Thorlabs .oct file: not a ZIP archive ({_one_line(exc)})", where
        ) from None
    with archive:
        # ThorImage names its members with Windows separators (data\Intensity.data)
        members = {info.filename.replace("\\", "/"): info for info in archive.infolist()}
        yield archive, _intensity_entry(archive, members, where)


def _intensity_entry(
    archive: zipfile.ZipFile, members: dict[str, zipfile.ZipInfo], where: str
) -> _Intensity:
    """Parse ``Header.xml`` (no DOCTYPE, no entities) and find its ``Intensity.data``."""
    info = members.get("Header.xml")
    if info is None:
        raise ConfigError("no Header.xml in the archive: not a Thorlabs .oct file", where)
    if info.file_size > _MAX_HEADER_BYTES:
        raise ConfigError(
            f"Header.xml unpacks to {info.file_size} bytes, more than the "
            f"{_MAX_HEADER_BYTES} fbia reads",
            where,
        )
    try:
        with archive.open(info) as f:
            raw = f.read(_MAX_HEADER_BYTES + 1)
    except _ZIP_ERRORS as exc:
        raise ConfigError(f"cannot read Header.xml: {_one_line(exc)}", where) from None
    if len(raw) > _MAX_HEADER_BYTES:
        raise ConfigError(f"Header.xml holds more than {_MAX_HEADER_BYTES} bytes", where)
    utf16 = raw[:2] in (b"\xff\xfe", b"\xfe\xff")
    try:
        text = raw.decode("utf-16" if utf16 else "utf-8-sig")
    except UnicodeDecodeError:
        raise ConfigError("Header.xml is not UTF-8 (or UTF-16) text", where) from None
    # xml.etree would expand the entities a DOCTYPE declares (fbia does not depend on
    # defusedxml): a header that declares any is refused before it is parsed
    upper = text.upper()
    if "<!DOCTYPE" in upper or "<!ENTITY" in upper:
        raise ConfigError(
            "Header.xml declares a DOCTYPE or entities, which fbia refuses: a scan header is "
            "data, and entities are never expanded",
            where,
        )
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ConfigError(f"Header.xml is not well-formed XML ({_one_line(exc)})", where) from None
    if root.tag != "Ocity":
        raise ConfigError(
            f"Header.xml's root element is <{root.tag}>, not <Ocity>: not a Thorlabs .oct file",
            where,
        )
    entries = root.findall("./DataFiles/DataFile")
    names = [(e.text or "").strip().replace("\\", "/") for e in entries]
    found = [
        (e, n) for e, n in zip(entries, names, strict=True) if n.split("/")[-1] == "Intensity.data"
    ]
    if not found:
        listed = ", ".join(n.split("/")[-1] for n in names) or "none"
        raise ConfigError(
            f"Header.xml lists no Intensity.data (its data files: {listed}): store the "
            "processed data with the scan in ThorImage",
            where,
        )
    if len(found) > 1:
        raise ConfigError(f"Header.xml lists {len(found)} Intensity.data files", where)
    element, name = found[0]
    kind, nbytes = element.get("Type"), element.get("BytesPerPixel")
    if kind != "Real" or nbytes != "4":
        raise ConfigError(
            f"Header.xml gives Intensity.data Type={kind!r}, BytesPerPixel={nbytes!r}; fbia "
            "reads Type='Real', BytesPerPixel='4' (float32 dB)",
            where,
        )
    size = (
        _whole(element, "SizeZ", where),
        _whole(element, "SizeY", where, default=1),
        _whole(element, "SizeX", where),
    )
    ranges = (
        _length(element, "RangeZ", where),
        _length(element, "RangeY", where),
        _length(element, "RangeX", where),
    )
    member = members.get(name)
    if member is None:
        raise ConfigError(f"Header.xml names {name}, which the archive does not hold", where)
    return _Intensity(member, size, ranges)


def _whole(element: ET.Element, name: str, where: str, default: int | None = None) -> int:
    text = element.get(name)
    if text is None and default is not None:
        return default
    try:
        value = int(text or "")
    except ValueError:
        value = 0
    if value < 1:
        raise ConfigError(
            f"Header.xml gives Intensity.data {name}={text!r}, not a whole number of pixels",
            where,
        )
    return value


def _length(element: ET.Element, name: str, where: str) -> float | None:
    text = element.get(name)
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0 <= value < float("inf"):
        raise ConfigError(
            f"Header.xml gives Intensity.data {name}={text!r}, not a length in mm", where
        )
    return value


def _read_thorlabs(path: Path, linear: bool) -> NDArray[np.float32]:
    """The intensity volume of a Thorlabs ``.oct`` file, (z, y, x) float32: its linear power
    (``linear``) or its dB values; read one B-scan (x, z) at a time into the result, so that
    no second copy of the volume is made and the bytes are counted as they come (``zipfile``
    stops at the directory's size, checked before, and a shorter stream is an error)."""
    where = str(path)
    with _thorlabs_archive(path) as (archive, entry):
        nz, ny, nx = entry.size
        gib = 2**30
        if entry.nbytes > THORLABS_MAX_BYTES:
            raise ConfigError(
                f"Header.xml makes Intensity.data {nz} x {nx} x {ny} float32 "
                f"({entry.nbytes / gib:.3g} GiB), more than the {THORLABS_MAX_BYTES / gib:g} "
                "GiB fbia reads",
                where,
            )
        stated = entry.member.file_size
        if stated > THORLABS_MAX_BYTES:
            raise ConfigError(
                f"Intensity.data unpacks to {stated} bytes by the archive's directory, more "
                f"than the {THORLABS_MAX_BYTES / gib:g} GiB fbia reads (a zip bomb?); not read",
                where,
            )
        if stated != entry.nbytes:
            times, rest = divmod(stated, entry.nbytes)
            hint = (
                f" ({times} times that: B-scans it does not count?)"
                if times > 1 and not rest
                else ""
            )
            raise ConfigError(
                f"Intensity.data holds {stated} bytes, not the SizeZ x SizeX x SizeY x 4 = "
                f"{nz} x {nx} x {ny} x 4 = {entry.nbytes} of Header.xml{hint}",
                where,
            )
        out = np.empty((nz, ny, nx), dtype=np.float32)
        bscan = nx * nz * 4
        bad, top = 0, -np.inf
        try:
            with archive.open(entry.member) as f:
                for y in range(ny):
                    chunk = f.read(bscan)
                    if len(chunk) != bscan:
                        raise ConfigError(
                            f"Intensity.data ends after {y * bscan + len(chunk)} of its "
                            f"{entry.nbytes} bytes",
                            where,
                        )
                    db = np.frombuffer(chunk, dtype="<f4").reshape(nx, nz)
                    finite = np.isfinite(db)
                    if not finite.all():
                        bad += db.size - int(np.count_nonzero(finite))
                        continue
                    top = max(top, float(db.max()))
                    if not linear:
                        out[:, y, :] = db.T
                    elif top <= _MAX_DB:
                        out[:, y, :] = (10.0 ** (db.astype(np.float64) / 10.0)).T
        except _ZIP_ERRORS as exc:
            raise ConfigError(f"cannot read Intensity.data: {_one_line(exc)}", where) from None
    if bad:
        raise ConfigError(f"Intensity.data holds {bad} NaN or infinite value(s)", where)
    if linear and top > _MAX_DB:
        raise ConfigError(
            f"Intensity.data reaches {top:.6g} dB, whose power 10^(dB/10) is beyond single "
            f"precision (above {_MAX_DB:g} dB): not intensities in dB?",
            where,
        )
    return out
