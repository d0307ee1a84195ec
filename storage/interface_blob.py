"""A run's interfaces as bytes for the store: an ``.npz`` without pickles.

Per coordinate k: ``vertices_k``, ``cells_k`` and, for a run asked for tangents, one
``tangent_k_<name>`` per input (d vertices / d input, :attr:`fbia.Interface.tangents`), so a
resumed study has them without running the model again.  ``coordinates`` is the JSON list of
the coordinates, in the order of k.
"""

from __future__ import annotations

import io
import json
from collections.abc import Mapping

import numpy as np

from ..core.interface import Interface
from ..core.observation import CoordinateKey, Solution, coordinate_key

__all__ = ["pack_interfaces", "unpack_interfaces"]

_TANGENT = "tangent_{k}_{name}"


def pack_interfaces(interfaces: Mapping[CoordinateKey, Interface]) -> bytes:
    """The interfaces of a run (with their tangents, if any) as an ``.npz``."""
    arrays: dict[str, np.ndarray] = {}
    keys = []
    for k, (coordinate, gamma) in enumerate(sorted(interfaces.items())):
        keys.append([[name, value] for name, value in coordinate])
        arrays[f"vertices_{k}"] = np.asarray(gamma.vertices, dtype="<f8")
        arrays[f"cells_{k}"] = np.asarray(gamma.cells, dtype="<i8")
        for name, tangent in gamma.tangents.items():
            arrays[_TANGENT.format(k=k, name=name)] = np.asarray(tangent, dtype="<f8")
    arrays["coordinates"] = np.array(json.dumps(keys))
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # type: ignore[arg-type]
    return buffer.getvalue()


def unpack_interfaces(blob: bytes) -> Solution:
    """The :class:`Solution` (interfaces and their tangents) of :func:`pack_interfaces`."""
    with np.load(io.BytesIO(blob), allow_pickle=False) as data:
        keys = json.loads(str(data["coordinates"]))
        interfaces = {}
        for k, pairs in enumerate(keys):
            gamma = Interface(data[f"vertices_{k}"], data[f"cells_{k}"])
            prefix = _TANGENT.format(k=k, name="")
            gamma.tangents = {f[len(prefix) :]: data[f] for f in data.files if f.startswith(prefix)}
            interfaces[coordinate_key(dict(pairs))] = gamma
    return Solution(interfaces)
