"""Reading OCT volumes: arrays and ``.npy``, ``.npz``, multi-page TIFF and NRRD files.

>>> import numpy as np
>>> bscans = np.zeros((5, 8, 6), dtype=np.uint16)    # 5 B-scans (y), 8 rows deep, 6 wide (x)
>>> read_oct_volume(bscans, depth_axis=1).shape      # depth first: (z, y, x)
(8, 5, 6)

The intensities come back as float32 with the depth axis first and the two other axes in
their array order (y, x); :mod:`fbia.imaging.oct` segments them.  TIFF stacks are read by
``tifffile`` (one page per array index of the first axis), NRRD files by ``pynrrd`` in C index
order, like NumPy and TIFF (the axis that varies fastest in the file is the last).  An
``.npz`` file holds one array, or several of which one is named ``volume``.
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


def read_oct_volume(source: str | Path | ArrayLike, depth_axis: int = 0) -> NDArray[np.float32]:
    """A 3-D intensity volume as float32 with depth first, from an array or a file of one of
    the ``OCT_SUFFIXES`` types (see the module docstring); ``depth_axis`` is the array axis
    that runs along depth, from the probe towards the substratum."""
    where = str(source) if isinstance(source, str | Path) else "oct volume"
    if isinstance(source, str | Path):
        data = _read_file(Path(source))
    else:
        data = np.asarray(source)
    if data.ndim != 3:
        raise ConfigError(f"an OCT volume must be a 3-D array, got shape {data.shape}", where)
    if not (np.issubdtype(data.dtype, np.integer) or np.issubdtype(data.dtype, np.floating)):
        raise ConfigError(f"OCT intensities must be real numbers, got dtype {data.dtype}", where)
    volume = np.moveaxis(data, depth_axis, 0).astype(np.float32, copy=False)
    bad = volume.size - int(np.count_nonzero(np.isfinite(volume)))
    if bad:
        raise ConfigError(f"volume has {bad} NaN or infinite voxel(s)", where)
    return volume


def _read_file(path: Path) -> NDArray[Any]:
    suffix = path.suffix.lower()
    if not path.is_file():
        raise ConfigError("file not found", str(path))
    if suffix not in OCT_SUFFIXES:
        raise ConfigError(
            f"unknown OCT file type {suffix!r}; readable: {', '.join(OCT_SUFFIXES)}", str(path)
        )
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
        raise ConfigError(f"cannot read OCT volume: {exc}", str(path)) from None
