"""Reading OCT volumes: arrays and ``.npy``, ``.npz``, multi-page TIFF and NRRD files.

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
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.errors import ConfigError
from ..core.extras import require

__all__ = ["OCT_SUFFIXES", "read_oct_volume"]

#: File types :func:`read_oct_volume` reads.
OCT_SUFFIXES = (".npy", ".npz", ".tif", ".tiff", ".nrrd", ".nhdr")


def read_oct_volume(source: str | Path | ArrayLike, depth_axis: int = 0) -> NDArray[Any]:
    """A 3-D intensity volume with depth first, in its own dtype, from an array or a file of
    one of the ``OCT_SUFFIXES`` types (see the module docstring); ``depth_axis`` is the array
    axis that runs along depth, from the probe towards the substratum."""
    where = str(source) if isinstance(source, str | Path) else "oct volume"
    if isinstance(source, str | Path):
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


#: what a file of each NumPy type starts with (``np.load`` takes any other start for a pickle)
_MAGIC = {".npy": (b"\x93NUMPY", "a NumPy .npy file"), ".npz": (b"PK", "a NumPy .npz (zip) file")}


def _read_file(path: Path) -> NDArray[Any]:
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
