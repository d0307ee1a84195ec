"""Malformed data files (issue 14, defects 7, 8, 16): one-line errors, never a traceback or
a row lost in silence.

Every file is generated here in ``tmp_path``: other encodings, binary content, absurd field
sizes, headers that are not headers, values that are not finite or not of a sane size.  Each
goes through the readers (``Interface.read`` for ``x, y[, curve]``, ``MeasurementPoints.read``
for ``x, y[, z][, dx, dy[, dz]]``) and must give a ``ConfigError`` naming the file and the
line; a representative subset goes through ``fbia run`` on a small study, which must exit
with status 2 and print exactly one line.  Coordinates around 1e300 handed to the measures
through the Python API give ``MeasureError``/``ConfigError``, not ``IndexError``.
"""

from __future__ import annotations

import re
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from _studies import edit, write_study

import fbia
from fbia.core.data_files import MAX_COORDINATE, MAX_LINE_CHARS, read_csv_table
from fbia.measures._geometry import ElementGeometry, closest_points
from fbia.studies.cli import main

FBIA = Path(sys.executable).parent / "fbia"

GOOD = "x,y,curve\n0.0,0.0,0\n0.5,0.25,0\n1.0,0.0,0\n"

#: (id, file content, the error after "<file>: ") for interface files (x, y[, curve])
BAD_FILES: list[tuple[str, bytes, str]] = [
    (
        "latin-1",
        "x,y\n0.0,0.0\n# mesur\u00e9\n1.0,0.0\n".encode("latin-1"),
        "line 3: not UTF-8 text (byte 0xe9); save the file as UTF-8",
    ),
    ("utf-16", "x,y\n0.0,0.0\n1.0,0.0\n".encode("utf-16"), "line 1: UTF-16 text, not UTF-8"),
    ("utf-16-no-bom", "x,y\n0.0,0.0\n1.0,0.0\n".encode("utf-16-le"), "line 1: NUL byte"),
    ("binary", bytes(np.random.default_rng(7).integers(0, 256, 4096, dtype=np.uint8)), "line "),
    ("nul-byte", b"x,y\n0.0,0.0\n1.0,\x000.5\n", "line 3: NUL byte: a binary file, not CSV text"),
    (
        "huge-field",
        b"x,y\n0.0,0.0\n1.0," + b"1" * 1_000_000 + b"\n",
        f"line 3: longer than {MAX_LINE_CHARS} characters",
    ),
    ("typo-0x", b"1.0,2,0x\n2.0,3.0,0\n3.0,2.0,0\n", "line 1: '0x' is not a number"),
    ("typo-l", b"l.0,2.0\n2.0,3.0\n3.0,2.0\n", "line 1: 'l.0' is not a number"),
    ("typo-bom", b"\xef\xbb\xbfl.0,2.0\n2.0,3.0\n3.0,2.0\n", "line 1: 'l.0' is not a number"),
    (
        "unknown-column",
        b"x,y,weight\n0,0,1\n1,0,1\n",
        "line 1: 'weight' is not a column name; expected x, y or x, y, curve",
    ),
    ("header-not-a-layout", b"y,x\n0,0\n1,0\n", "line 1: header y, x is not a layout"),
    ("header-width", b"x,y\n0,0,0\n1,0,0\n", "line 2: 3 columns, but the header on line 1 has 2"),
    ("second-header", b"x,y\n0,0\nx,y\n1,0\n", "line 3: 'x' is not a number"),
    (
        "semicolons",
        b"0.0;0.0\n1.0;0.0\n",
        "line 1: '0.0;0.0' is not a number (columns are separated by commas)",
    ),
    ("empty-cell", b"0.0,,0\n1.0,0.0,0\n", "line 1: column 2 is empty"),
    ("ragged", b"0.0,0.0\n1.0,0.0,0\n", "line 2: 3 columns, but the rows above have 2"),
    ("nan", b"x,y\n0,0\n1,nan\n", "line 3: NaN or infinite value"),
    ("inf", b"x,y\n0,0\n1,-inf\n", "line 3: NaN or infinite value"),
    ("overflow", b"x,y\n0,0\n1,1e999\n", "line 3: NaN or infinite value"),
    ("1e300", b"x,y\n0,0\n1e300,1\n", "line 3: column 1 (x) is 1e300, beyond the bound 1e+09"),
    ("1e10-no-header", b"0,0\n1,-1e10\n", "line 2: column 2 is -1e10, beyond the bound 1e+09"),
    ("empty", b"", "no data rows"),
    ("only-blank", b"\n  \n# a comment\n", "no data rows"),
    ("only-header", b"\xef\xbb\xbfx,y,curve\r\n", "no data rows after the header on line 1"),
]

#: a representative subset for the command line
CLI_CASES = ["latin-1", "utf-16", "binary", "huge-field", "typo-l", "unknown-column", "1e300"]


def _write(folder: Path, name: str, content: bytes) -> Path:
    path = folder / name
    path.write_bytes(content)
    return path


def test_the_good_file_reads(tmp_path):
    """The baseline the bad files differ from (guards the cases against a broken reader)."""
    gamma = fbia.Interface.read(_write(tmp_path, "good.csv", GOOD.encode()))
    assert len(gamma.vertices) == 3


@pytest.mark.parametrize(("case", "content", "message"), BAD_FILES, ids=[c[0] for c in BAD_FILES])
def test_bad_interface_files_give_one_line_naming_file_and_line(tmp_path, case, content, message):
    path = _write(tmp_path, f"{case}.csv", content)
    with pytest.raises(fbia.ConfigError) as info:
        fbia.Interface.read(path)
    text = str(info.value)
    assert "\n" not in text
    assert text.startswith(f"{path}: {message}"), text
    if message.startswith("line"):
        assert re.match(rf"^{re.escape(str(path))}: line \d+: ", text)


@pytest.mark.parametrize(
    ("case", "content", "message"),
    [
        ("latin-1", "x,y\n0.5,0.5\n# \u00e9\n".encode("latin-1"), "line 3: not UTF-8 text"),
        ("utf-16", "x,y,dx,dy\n0,0,0,1\n".encode("utf-16"), "line 1: UTF-16 text"),
        ("typo", b"x,y,dx,dy\n0,0,0,1\n1,0,O,1\n", "line 3: 'O' is not a number"),
        (
            "unknown-column",
            b"x,y,nx,ny\n0,0,0,1\n",
            "line 1: 'nx' is not a column name; expected x, y or ",
        ),
        ("header-not-a-layout", b"x,y,dx\n0,0,0\n", "line 1: header x, y, dx is not a layout"),
        ("five-columns", b"0,0,0,0,1\n", "line 1: expected 2, 3, 4 or 6 columns"),
        ("1e300-direction", b"x,y,dx,dy\n0,0,1e300,1\n", "line 2: column 3 (dx) is 1e300"),
        ("only-header", b"x,y,z,dx,dy,dz\n", "no data rows after the header on line 1"),
    ],
)
def test_bad_measurement_point_files(tmp_path, case, content, message):
    path = _write(tmp_path, f"{case}.csv", content)
    with pytest.raises(fbia.ConfigError) as info:
        fbia.MeasurementPoints.read(path)
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


@pytest.mark.parametrize(
    "content",
    [
        b"\xef\xbb\xbf" + b"".join(b"%d.0,%d.5\n" % (k, k % 3) for k in range(81)),  # BOM
        b"".join(b"%d.0,%d.5\n" % (k, k % 3) for k in range(81)),  # no header, no BOM
        b"\xef\xbb\xbfX,Y\r\n" + b"".join(b"%d.0,%d.5\r\n" % (k, k % 3) for k in range(81)),
        b"# points\n\n" + b"".join(b" %d.0 , %d.5 ,\n" % (k, k % 3) for k in range(81)),
    ],
    ids=["bom-no-header", "no-header", "bom-header-crlf", "comment-spaces-trailing-comma"],
)
def test_no_row_is_lost(tmp_path, content):
    """Defect 8: a BOM before the first number made it a 'header': 80 of 81 points, exit 0."""
    path = _write(tmp_path, "obs.csv", content)
    table = read_csv_table(path, [("x", "y"), ("x", "y", "curve")])
    assert table.shape == (81, 2)
    assert table[0].tolist() == [0.0, 0.5] and table[-1].tolist() == [80.0, 2.5]
    assert len(fbia.Interface.read(path).vertices) == 81
    assert len(fbia.MeasurementPoints.read(path)) == 81


def test_huge_3d_surface_is_rejected_on_read(tmp_path):
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]) * 1e300
    path = tmp_path / "huge.vtu"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # the sizes of 1e300 triangles
        fbia.Interface.surface(v, [[0, 1, 2]]).write(path)
    with pytest.raises(fbia.ConfigError, match=rf"^{path}: vertex coordinates reach 1e\+300"):
        fbia.Interface.read(path)


# -- the measures, through the Python API (defect 16) ----------------------------------------


def _curve(scale: float, lift: float = 0.0) -> fbia.Interface:
    x = np.linspace(0.0, 1.0, 5)
    return fbia.Interface.polyline(np.c_[x * scale, 0.1 * x + lift])


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("scale", [1e300, 1e160, 10 * MAX_COORDINATE])
@pytest.mark.parametrize("measure", ["cpp", "ray", "rkhs"])
def test_huge_simulated_interfaces_give_measure_error(measure, scale):
    x = np.linspace(0.2, 0.8, 3)
    observation = fbia.Observation(_curve(1.0), points=np.c_[x, 0.1 * x])
    with pytest.raises(fbia.MeasureError, match=f"^{measure} measure: .* beyond the bound"):
        fbia.measure(measure).residuals(_curve(scale, lift=0.5), observation)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_huge_observed_interfaces_are_config_errors():
    with pytest.raises(fbia.ConfigError, match="observed interface vertices reach 1e\\+300"):
        fbia.Observation(_curve(1e300))
    with pytest.raises(fbia.ConfigError, match="measurement points reach 1e\\+300"):
        fbia.Observation(_curve(1.0), points=[[0.5, 1e300]])


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
def test_closest_points_guards_the_kd_tree_no_neighbour_index():
    """cKDTree answers 'no neighbour' with index n when squared distances overflow: this was
    the IndexError of defect 16; below the measures' bound it cannot happen, so guard it."""
    geometry = ElementGeometry(_curve(1e300))
    with pytest.raises(fbia.MeasureError, match="no closest point found"):
        closest_points(geometry, np.array([[1e300, -1e300]]))


# -- the command line --------------------------------------------------------------------------


@pytest.fixture
def study(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return write_study(tmp_path)


@pytest.mark.parametrize("case", CLI_CASES)
def test_fbia_run_on_a_bad_data_file_prints_one_line(study, capsys, case):
    content, message = next((c, m) for k, c, m in BAD_FILES if k == case)
    _write(study.parent / "data", "bad.csv", content)
    study.write_text(edit("data/observed_100.csv", "data/bad.csv"))
    assert main(["run", "study.toml"]) == 2
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(
        f"fbia: error: study.toml: [[observations]] #1 interface: data/bad.csv: {message}"
    )
    assert not (study.parent / "out").exists()  # nothing ran


def test_a_real_fbia_run_on_binary_points_has_no_traceback(study):
    _write(study.parent / "data", "bad.csv", BAD_FILES[3][1])
    study.write_text(edit("data/points_100.csv", "data/bad.csv"))
    proc = subprocess.run(
        [str(FBIA), "run", "study.toml"], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert "Traceback" not in proc.stderr
    assert re.fullmatch(
        r"fbia: error: study.toml: \[\[observations\]\] #1 points: data/bad.csv: line \d+: "
        r"(not UTF-8 text \(byte 0x[0-9a-f]{2}\); save the file as UTF-8|NUL byte: .*)\n",
        proc.stderr,
    ), proc.stderr
