"""Numeric CSV tables of observed data (interfaces, measurement points): a strict reader.

Every problem with a data file is a :class:`ConfigError` of one line that names the file and
the line, never a traceback and never a row dropped in silence:

* The file is UTF-8 text (a UTF-8 byte-order mark is accepted and ignored).  Another encoding
  (Latin-1, UTF-16, ...), NUL bytes (binary content) or a line longer than
  :data:`MAX_LINE_CHARS` characters is an error.
* Columns are separated by commas; blank lines and lines starting with ``#`` are skipped.
* The first row is a header only if every cell is one of the file kind's column names
  (case-insensitive), and then it must be one of the kind's layouts, e.g. ``x, y`` or
  ``x, y, curve``, with as many columns as the data.  A first row with some column names
  and another cell (``x, y, weight``) is an error naming that cell; so is any other row that
  is not all numbers, the first one included (``l.0, 2.0``): a header is never guessed.
* Every value is finite and its magnitude below :data:`MAX_COORDINATE`.

>>> from pathlib import Path
>>> path = Path("doctest_points.csv")
>>> _ = path.write_bytes(b"\\xef\\xbb\\xbf0.0,1.0\\n2.0,3.0\\n")      # UTF-8 with a BOM, no header
>>> read_csv_table(path, [("x", "y")]).tolist()
[[0.0, 1.0], [2.0, 3.0]]
>>> _ = path.write_text("x,y\\nl.0,2.0\\n")
>>> read_csv_table(path, [("x", "y")])
Traceback (most recent call last):
...
fbia.core.errors.ConfigError: doctest_points.csv: line 2: 'l.0' is not a number
>>> path.unlink()
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import os
import re
import stat
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import ConfigError

#: Largest magnitude of a coordinate (or any other value) in a data file [mm].  No flow cell
#: is a kilometre (1e6 mm) long; far below it, squares and products of coordinates stay
#: finite in float64, which closest-point searches and KD-trees rely on.
MAX_COORDINATE = 1e9

#: Longest line a data file may have [characters]; a row of six floats written with
#: ``repr`` has about 150.
MAX_LINE_CHARS = 10_000

_BOM_UTF8 = b"\xef\xbb\xbf"
_BOMS_UTF16_32 = {
    b"\xff\xfe\x00\x00": "UTF-32",
    b"\x00\x00\xfe\xff": "UTF-32",
    b"\xff\xfe": "UTF-16",
    b"\xfe\xff": "UTF-16",
}


def read_csv_table(path: str | Path, layouts: Sequence[Sequence[str]]) -> NDArray[np.float64]:
    """The numbers of a CSV data file, one row per data line, shape (n, columns).

    Parameters
    ----------
    path
        The file; every error message starts with it.
    layouts
        The column layouts the file kind allows, e.g. ``[("x", "y"), ("x", "y", "curve")]``:
        the data must have as many columns as one of them, and a header (a first row whose
        cells are all column names of the layouts, case-insensitive) must be one of them.

    The rules (see the module docstring): strict UTF-8 with an optional BOM; no NUL bytes;
    lines of at most :data:`MAX_LINE_CHARS` characters; comma-separated; blank lines and
    ``#`` comments skipped; a header only if every cell is a column name; every other cell a
    finite number of magnitude below :data:`MAX_COORDINATE`; all rows of one width.
    """
    path = Path(path)
    where = str(path)
    lines = _text_lines(path, where)
    names = {n.lower() for layout in layouts for n in layout}
    widths = sorted({len(layout) for layout in layouts})
    expect = _layouts_text(layouts)
    header: tuple[str, ...] | None = None
    header_line = 0
    rows: list[list[float]] = []
    width = 0
    for lineno, line in enumerate(lines, start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        cells = _cells(line, lineno, where)
        if not cells:  # only commas
            continue
        if not rows and header is None and any(c.lower() in names for c in cells):
            for cell in cells:
                if cell.lower() not in names:
                    raise ConfigError(
                        f"line {lineno}: {cell[:40]!r} is not a column name; expected {expect}",
                        where,
                    )
            header = tuple(c.lower() for c in cells)
            header_line = lineno
            if header not in {tuple(n.lower() for n in layout) for layout in layouts}:
                raise ConfigError(
                    f"line {lineno}: header {', '.join(cells)!s} is not a layout of this file; "
                    f"expected {expect}",
                    where,
                )
            width = len(header)
            continue
        values = [_number(c, k, lineno, where, header) for k, c in enumerate(cells)]
        if not width:
            if len(values) not in widths:
                raise ConfigError(
                    f"line {lineno}: expected {_or(widths)} columns ({expect}), got {len(values)}",
                    where,
                )
            width = len(values)
        elif len(values) != width:
            what = f"the header on line {header_line} has" if header else "the rows above have"
            raise ConfigError(f"line {lineno}: {len(values)} columns, but {what} {width}", where)
        rows.append(values)
    if not rows:
        after = f" after the header on line {header_line}" if header else ""
        raise ConfigError(f"no data rows{after}", where)
    return np.asarray(rows, dtype=float)


def check_coordinates(values: NDArray[np.float64], what: str, where: str | None = None) -> None:
    """Raise :class:`ConfigError` unless every value is finite and below MAX_COORDINATE."""
    if not np.all(np.isfinite(values)):
        raise ConfigError(f"{what} contain NaN or infinite values", where)
    if values.size and float(np.max(np.abs(values))) >= MAX_COORDINATE:
        raise ConfigError(
            f"{what} reach {float(np.max(np.abs(values))):.3g}, beyond the bound "
            f"{MAX_COORDINATE:.0e} mm of any flow cell",
            where,
        )


def _text_lines(path: Path, where: str) -> list[str]:
    """The file's lines, decoded strictly as UTF-8 (a leading BOM dropped)."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read: {exc.strerror or exc}", where) from None
    for bom, name in _BOMS_UTF16_32.items():
        if data.startswith(bom):
            raise ConfigError(f"line 1: {name} text, not UTF-8; save the file as UTF-8", where)
    if data.startswith(_BOM_UTF8):
        data = data[len(_BOM_UTF8) :]
    nul = data.find(b"\x00")
    try:
        text = data.decode("utf-8")
        bad = -1
    except UnicodeDecodeError as exc:
        bad = exc.start
    if nul >= 0 and (bad < 0 or nul < bad):
        raise ConfigError(
            f"line {_line_of(data, nul)}: NUL byte: a binary file, not CSV text", where
        )
    if bad >= 0:
        at = f"line {_line_of(data, bad)}"
        raise ConfigError(
            f"{at}: not UTF-8 text (byte 0x{data[bad]:02x}); save the file as UTF-8", where
        )
    lines = re.split(r"\r\n|\r|\n", text)  # as _line_of counts; not str.splitlines's \f etc.
    for lineno, line in enumerate(lines, start=1):
        if len(line) > MAX_LINE_CHARS:
            raise ConfigError(
                f"line {lineno}: longer than {MAX_LINE_CHARS} characters; not a table of numbers",
                where,
            )
    return lines


def _line_of(data: bytes, pos: int) -> int:
    """The line number (from 1) of byte ``pos``; lines end with \\n, \\r\\n or \\r."""
    return len((data[:pos] + b"x").splitlines())


def _cells(line: str, lineno: int, where: str) -> list[str]:
    """The stripped cells of one line; trailing empty cells dropped, inner ones an error."""
    try:
        (raw,) = csv.reader([line], strict=True)
    except (csv.Error, ValueError) as exc:
        raise ConfigError(f"line {lineno}: not CSV: {exc}", where) from None
    cells = [c.strip() for c in raw]
    while cells and not cells[-1]:
        cells.pop()
    if "" in cells:
        raise ConfigError(f"line {lineno}: column {cells.index('') + 1} is empty", where)
    return cells


def _number(cell: str, k: int, lineno: int, where: str, header: tuple[str, ...] | None) -> float:
    try:
        value = float(cell)
    except ValueError:
        hint = ""
        if any(sep in cell for sep in (";", "\t", " ")):
            hint = " (columns are separated by commas)"
        raise ConfigError(f"line {lineno}: {cell[:40]!r} is not a number{hint}", where) from None
    if not math.isfinite(value):
        raise ConfigError(f"line {lineno}: NaN or infinite value", where)
    if abs(value) >= MAX_COORDINATE:
        column = f"column {k + 1}" + (f" ({header[k]})" if header and k < len(header) else "")
        raise ConfigError(
            f"line {lineno}: {column} is {cell[:40]}, beyond the bound {MAX_COORDINATE:.0e} mm "
            "of any flow cell",
            where,
        )
    return value


def _layouts_text(layouts: Sequence[Sequence[str]]) -> str:
    return " or ".join(", ".join(layout) for layout in layouts)


def _or(widths: Sequence[int]) -> str:
    words = [str(w) for w in widths]
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " or " + words[-1]


def regular_file_bytes(path: str | Path, limit: int, where: str, what: str = "") -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them, else a ConfigError at
    ``where`` (``what``: the kind of file, for the size message); FileNotFoundError where there
    is none.  Opened without blocking, so a FIFO is refused, never waited on; a device, a
    folder or a socket is refused unread."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise ConfigError(f"cannot be read ({exc.strerror})", where) from None
    too_large = f"larger than {limit} bytes" + (f": not {what}" if what else "")
    try:
        found = os.fstat(fd)
        if not stat.S_ISREG(found.st_mode):
            raise ConfigError(f"not a regular file ({_file_kind(found.st_mode)}): not read", where)
        if found.st_size > limit:
            raise ConfigError(too_large, where)
        with os.fdopen(os.dup(fd), "rb") as file:
            raw = file.read(limit + 1)
    finally:
        os.close(fd)
    if len(raw) > limit:  # grown since
        raise ConfigError(too_large, where)
    return raw


def _file_kind(mode: int) -> str:
    kinds = [(stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket")]
    return next((name for test, name in kinds if test(mode)), "a device")


def read_meshio(path: Path, what: str = "mesh") -> Any:
    """``meshio.read(path)``, every failure a one-line :class:`ConfigError` naming the file:
    meshio raises many types for unreadable files, and for an extension several formats
    share (.msh: ansys, gmsh; .ply after a failed PLY parse) prints "Couldn't read file ..."
    and calls ``sys.exit(1)``.  What meshio prints is kept out of the terminal and put into
    the message."""
    import meshio

    where = str(path)
    if not path.is_file():
        raise ConfigError(f"{what} file not found", where)
    said = io.StringIO()
    try:
        with (
            contextlib.redirect_stdout(said),
            contextlib.redirect_stderr(said),
            warnings.catch_warnings(),
        ):
            # meshio tells binary from ASCII STL by the file size in int32 arithmetic, which
            # overflows for an ASCII file's triangle count; the reader is right either way
            warnings.filterwarnings("ignore", "overflow encountered", RuntimeWarning)
            return meshio.read(path)
    except (Exception, SystemExit) as exc:
        reason = " ".join(said.getvalue().split()) or str(exc) or type(exc).__name__
        raise ConfigError(f"meshio cannot read the {what}: {reason}", where) from None
