"""Thorlabs .oct files read directly (issue 45 item 4): the linear power of the dB volume, depth
first; the voxel size from the header; one B-scan; every bad file one ConfigError line naming it.

The files are built here as ThorImage OCT writes them, after the public readers' expectations:
a ZIP archive of ``Header.xml`` (root ``Ocity``, one ``<DataFile>`` per raw file, with the
attributes ``Type``, ``SizeZ``, ``SizeX``, ``SizeY``, ``RangeZ``, ``RangeX``, ``RangeY`` [mm] and
``BytesPerPixel``, the text ``data\\Intensity.data``) and ``data\\Intensity.data``, float32 dB
with depth fastest, then x, then y.  Sources: ``OCTFileGetRealData.m`` of the MATLAB reader for
ThorImage OCT 4.x/5.x (github.com/Brian-Frost-LaPlante/OrientingGUI, ``ThorlabsFiles/``: float32
reshaped to [SizeZ SizeX SizeY], column-major), ``OCT_reader.py`` of
github.com/kai-neuhaus/OCT_file_tools (``np.fromfile(..., dtype=(float32, [SizeX, SizeZ]))``,
one record per y), ``ReadOCTfile.py`` of github.com/bram859/Bachelors_Thesis (opens the member
``data\\Intensity.data``, named with a backslash) and the header of
github.com/WinetraubLab/myOCT ``LoadSave/test_yOCTUnzipTiledScan.m`` (the attributes of
``<DataFile>``).
"""

from __future__ import annotations

import struct
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fbia.core.errors import ConfigError
from fbia.imaging import oct_reader
from fbia.imaging.oct import segment_oct
from fbia.imaging.oct_reader import (
    OCT_SUFFIXES,
    oct_file_voxel_size,
    read_oct_decibels,
    read_oct_volume,
)
from fbia.testing.oct import oct_phantom

INTENSITY = "data\\Intensity.data"


def header_xml(
    size: tuple[int, int, int],
    ranges: tuple[float, float | None, float],
    *,
    intensity: str | None = INTENSITY,
    attributes: str | None = None,
    prologue: str = '<?xml version="1.0" encoding="utf-8"?>',
) -> str:
    """A Header.xml like ThorImage's for an intensity volume of (SizeZ, SizeY, SizeX) pixels
    over (RangeZ, RangeY, RangeX) mm; SizeY/RangeY are left out for one B-scan (SizeY 1 and
    RangeY None), as a Mode2D file has them."""
    nz, ny, nx = size
    rz, ry, rx = ranges
    y = "" if ny == 1 and ry is None else f' SizeY="{ny}" RangeY="{ry}"'
    if attributes is None:
        attributes = (
            f'Type="Real" SizeZ="{nz}" SizeX="{nx}"{y} RangeZ="{rz}" RangeX="{rx}" '
            'BytesPerPixel="4"'
        )
    entry = "" if intensity is None else f"    <DataFile {attributes}>{intensity}</DataFile>\n"
    return (
        f"{prologue}\n"
        '<Ocity version="1.0">\n'
        "  <Instrument><Model>Ganymede</Model></Instrument>\n"
        f"  <MetaInfo><AcquisitionMode>{'Mode2D' if ny == 1 else 'Mode3D'}</AcquisitionMode>"
        "<Comment/></MetaInfo>\n"
        "  <DataFiles>\n"
        '    <DataFile Type="Colored" SizeZ="16" SizeX="12" BytesPerPixel="4">'
        "data\\VideoImage.data</DataFile>\n"
        f"{entry}"
        "  </DataFiles>\n"
        "</Ocity>\n"
    )


def write_oct(
    path: Path,
    db_yxz: np.ndarray,
    ranges: tuple[float, float | None, float] = (1.4, 0.6, 2.0),
    *,
    header: str | None = None,
    members: dict[str, bytes] | None = None,
    sep: str = "\\",
    compression: int = zipfile.ZIP_DEFLATED,
) -> Path:
    """A .oct file of the dB volume ``db_yxz`` (shape (SizeY, SizeX, SizeZ), the order of the
    bytes on disk); ``members`` replace or add archive members."""
    ny, nx, nz = db_yxz.shape
    files = {
        "Header.xml": (header or header_xml((nz, ny, nx), ranges)).encode("utf-8"),
        f"data{sep}Intensity.data": db_yxz.astype("<f4").tobytes(),
        f"data{sep}VideoImage.data": bytes(16 * 12 * 4),
    }
    files.update(members or {})
    with zipfile.ZipFile(path, "w", compression=compression) as zf:
        for name, data in files.items():
            zf.writestr(name, data)
    return path


def coded_db(ny: int = 3, nx: int = 5, nz: int = 7) -> np.ndarray:
    """dB values on disk order (y, x, z) that tell every voxel's indices apart."""
    y, x, z = np.meshgrid(np.arange(ny), np.arange(nx), np.arange(nz), indexing="ij")
    return (40.0 + 10.0 * y + 1.0 * x + 0.1 * z).astype(np.float32)


def patch_directory_size(path: Path, member: str, size: int) -> None:
    """Make the archive's central directory state ``size`` uncompressed bytes for ``member``."""
    data = bytearray(path.read_bytes())
    start = 0
    while (i := data.find(b"PK\x01\x02", start)) >= 0:
        (length,) = struct.unpack_from("<H", data, i + 28)
        if data[i + 46 : i + 46 + length] == member.encode():
            struct.pack_into("<I", data, i + 24, size)
        start = i + 4
    path.write_bytes(bytes(data))


# -- reading -----------------------------------------------------------------------------------
@pytest.mark.parametrize("sep", ["\\", "/"], ids=["windows-names", "posix-names"])
def test_reads_the_linear_power_depth_first(tmp_path: Path, sep: str) -> None:
    assert ".oct" in OCT_SUFFIXES
    db = coded_db()  # (y, x, z) = (3, 5, 7): a transposition changes the shape or the values
    path = write_oct(tmp_path / "scan.oct", db, sep=sep)
    volume = read_oct_volume(path)
    expected = (10.0 ** (db.astype(np.float64) / 10.0)).astype(np.float32).transpose(2, 0, 1)
    assert volume.shape == (7, 3, 5) and volume.dtype == np.float32
    np.testing.assert_array_equal(volume, expected)
    z, y, x = 6, 2, 4  # the voxel of depth 6 on B-scan 2, A-scan 4
    assert volume[z, y, x] == pytest.approx(10 ** ((40 + 10 * y + x + 0.1 * z) / 10), rel=1e-6)
    decibels = read_oct_decibels(str(path))
    assert decibels.shape == (7, 3, 5) and decibels[z, y, x] == db[y, x, z]
    np.testing.assert_array_equal(decibels, db.transpose(2, 0, 1))
    assert read_oct_volume(str(path), depth_axis=0).shape == (7, 3, 5)


def test_voxel_size_from_the_header_ranges(tmp_path: Path) -> None:
    path = write_oct(tmp_path / "scan.oct", coded_db(), ranges=(1.4, 0.6, 2.0))
    assert oct_file_voxel_size(path) == pytest.approx((1.4 / 7, 0.6 / 3, 2.0 / 5))


@pytest.mark.parametrize("ranges", [(1.4, None, 2.0), (1.4, 0.0, 2.0)], ids=["no-y", "y-1"])
def test_one_bscan_is_a_volume_of_one_y_row(tmp_path: Path, ranges) -> None:
    db = coded_db(ny=1)
    nz, nx = db.shape[2], db.shape[1]
    header = header_xml((nz, 1, nx), ranges)  # "no-y": no SizeY, RangeY; "y-1": SizeY="1"
    assert ('SizeY="1" RangeY="0.0"' in header) == (ranges[1] is not None)
    path = write_oct(tmp_path / "bscan.oct", db, ranges, header=header)
    volume = read_oct_volume(path)
    assert volume.shape == (7, 1, 5)
    np.testing.assert_allclose(volume[:, 0, :], 10.0 ** (db[0].T.astype(np.float64) / 10), 1e-7)
    dz, dy, dx = oct_file_voxel_size(path)
    assert (dz, dy, dx) == pytest.approx((1.4 / 7, 2.0 / 5, 2.0 / 5)) and dy == dx


def test_segment_oct_on_a_thorlabs_file_finds_the_phantoms_substratum(tmp_path: Path) -> None:
    """The phantom of imaging/oct.py's doctest, stored as ThorImage stores it (dB, A-scans
    depth fastest), segments as the phantom does: the linear conversion and the axis order
    are right.  Its dB values themselves, read as intensities, are refused."""
    ph = oct_phantom(shape=(24, 20, 20), seed=0)
    nz, ny, nx = ph.volume.shape
    dz, dy, dx = ph.voxel_size
    db_zyx = (10.0 * np.log10(ph.volume.astype(np.float64))).astype(np.float32)
    path = write_oct(
        tmp_path / "phantom.oct", db_zyx.transpose(1, 2, 0), ranges=(nz * dz, ny * dy, nx * dx)
    )
    voxel = oct_file_voxel_size(path)
    assert voxel == pytest.approx(ph.voxel_size)
    seg = segment_oct(path, voxel)
    assert seg.substratum_row == 20 and round(seg.substratum_depth, 4) == 0.195
    direct = segment_oct(ph.volume, ph.voxel_size)
    assert seg.interface.cells.shape == direct.interface.cells.shape
    np.testing.assert_allclose(seg.interface.vertices, direct.interface.vertices, atol=1e-4)
    with pytest.raises(ConfigError, match=r"must be >= 0 \(linear, not log or dB\)"):
        segment_oct(read_oct_decibels(path), voxel)


def test_a_study_reads_a_thorlabs_file_with_the_voxel_size_of_its_header(tmp_path: Path) -> None:
    """``[[observations]] oct = "scan.oct"`` needs no voxel_size: the header has it."""
    from fbia.studies.study_oct import read_oct_scan

    ph = oct_phantom(shape=(24, 20, 20), seed=0)
    nz, ny, nx = ph.volume.shape
    dz, dy, dx = ph.voxel_size
    db_zyx = (10.0 * np.log10(ph.volume.astype(np.float64))).astype(np.float32)
    write_oct(tmp_path / "scan.oct", db_zyx.transpose(1, 2, 0), ranges=(nz * dz, ny * dy, nx * dx))
    scan = read_oct_scan("scan.oct", tmp_path, "study.toml: [[observations]] #1 oct")
    assert scan.voxel_size == pytest.approx(ph.voxel_size)
    assert scan.segmentation.substratum_row == 20


# -- bad input ---------------------------------------------------------------------------------
def one_line_error(path: Path, match: str, read=read_oct_volume, **kwargs) -> str:
    """The ConfigError that reading ``path`` raises: one line, naming the file, matching
    ``match``, with no warning and nothing printed before it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ConfigError, match=match) as info:
            read(path, **kwargs)
    message = str(info.value)
    assert message.startswith(f"{path}: ") and "\n" not in message, message
    assert info.value.__traceback__ is not None and info.value.__cause__ is None
    return message


def test_depth_axis_of_a_thorlabs_file_is_its_own(tmp_path: Path) -> None:
    path = write_oct(tmp_path / "scan.oct", coded_db())
    one_line_error(
        path, "depth_axis = 1: a Thorlabs .oct file carries its own axis order", depth_axis=1
    )


def test_not_a_zip_archive(tmp_path: Path, capfd) -> None:
    path = tmp_path / "scan.oct"
    path.write_bytes(b"Thorlabs? no: a text file\n" * 4)
    one_line_error(path, "not a Thorlabs .oct file: not a ZIP archive")
    one_line_error(path, "not a ZIP archive", read=oct_file_voxel_size)
    assert capfd.readouterr() == ("", "")


def test_no_header(tmp_path: Path) -> None:
    path = tmp_path / "scan.oct"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(INTENSITY, coded_db().tobytes())
    one_line_error(path, "no Header.xml in the archive")


def test_no_intensity_data_file_in_the_header(tmp_path: Path) -> None:
    header = header_xml((7, 3, 5), (1.4, 0.6, 2.0), intensity=None)
    path = write_oct(tmp_path / "raw_only.oct", coded_db(), header=header)
    one_line_error(path, r"lists no Intensity.data \(its data files: VideoImage.data\)")
    one_line_error(path, "lists no Intensity.data", read=oct_file_voxel_size)


def test_intensity_data_missing_from_the_archive(tmp_path: Path) -> None:
    header = header_xml((7, 3, 5), (1.4, 0.6, 2.0), intensity="data\\Intensity2\\Intensity.data")
    path = write_oct(tmp_path / "scan.oct", coded_db(), header=header)
    one_line_error(path, "names data/Intensity2/Intensity.data, which the archive does not hold")


@pytest.mark.parametrize(
    ("size", "match"),
    [
        ((8, 3, 5), r"holds 420 bytes, not the SizeZ x SizeX x SizeY x 4 = 8 x 5 x 3 x 4 = 480"),
        ((7, 1, 5), r"holds 420 bytes, not .* = 140 of Header.xml \(3 times that: B-scans"),
    ],
    ids=["other-size", "uncounted-bscans"],
)
def test_byte_size_not_the_headers(tmp_path: Path, size, match) -> None:
    header = header_xml(size, (1.4, 0.6, 2.0))
    path = write_oct(tmp_path / "scan.oct", coded_db(), header=header)
    one_line_error(path, match)


def test_non_finite_values(tmp_path: Path) -> None:
    db = coded_db()
    db[1, 2, 3], db[2, 0, 0] = np.nan, -np.inf
    path = write_oct(tmp_path / "scan.oct", db)
    one_line_error(path, r"Intensity.data holds 2 NaN or infinite value\(s\)")
    one_line_error(path, r"holds 2 NaN or infinite", read=read_oct_decibels)


def test_decibels_beyond_single_precision_power(tmp_path: Path) -> None:
    db = coded_db()
    db[0, 0, 0] = 400.0
    path = write_oct(tmp_path / "scan.oct", db)
    one_line_error(path, r"reaches 400 dB, whose power 10\^\(dB/10\) is beyond single precision")
    assert read_oct_decibels(path)[0, 0, 0] == 400.0


@pytest.mark.parametrize(
    ("header", "match"),
    [
        ("<Ocity><DataFiles><DataFile>", r"Header.xml is not well-formed XML \(.*line 1"),
        (
            '<?xml version="1.0"?>\n<!DOCTYPE Ocity [<!ENTITY a "aaaaaaaaaa">'
            '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>\n<Ocity>&b;</Ocity>',
            "Header.xml declares a DOCTYPE or entities, which fbia refuses",
        ),
        (
            '<!DOCTYPE Ocity SYSTEM "file:///etc/passwd"><Ocity/>',
            "declares a DOCTYPE or entities",
        ),
        ('<?xml version="1.0"?><Scan/>', r"root element is <Scan>, not <Ocity>"),
    ],
    ids=["malformed", "entities", "external-doctype", "not-ocity"],
)
def test_header_xml_that_is_not_a_plain_thorlabs_header(tmp_path: Path, header, match) -> None:
    path = write_oct(tmp_path / "scan.oct", coded_db(), header=header)
    one_line_error(path, match)


@pytest.mark.parametrize(
    ("attributes", "match"),
    [
        (
            'Type="Raw" SizeZ="7" SizeX="5" SizeY="3" BytesPerPixel="2"',
            r"Type='Raw', BytesPerPixel='2'; fbia reads Type='Real', BytesPerPixel='4'",
        ),
        (
            'Type="Real" SizeZ="7" SizeX="five" SizeY="3" BytesPerPixel="4"',
            r"SizeX='five', not a whole number of pixels",
        ),
        (
            'Type="Real" SizeZ="7" SizeX="5" SizeY="3" RangeZ="nan" BytesPerPixel="4"',
            r"RangeZ='nan', not a length in mm",
        ),
    ],
    ids=["raw-uint16", "size-text", "range-nan"],
)
def test_intensity_entry_fbia_cannot_read(tmp_path: Path, attributes, match) -> None:
    header = header_xml((7, 3, 5), (1.4, 0.6, 2.0), attributes=attributes)
    path = write_oct(tmp_path / "scan.oct", coded_db(), header=header)
    one_line_error(path, match)


def test_voxel_size_needs_the_ranges_and_distinct_bscans(tmp_path: Path) -> None:
    attributes = 'Type="Real" SizeZ="7" SizeX="5" SizeY="3" RangeX="2.0" BytesPerPixel="4"'
    header = header_xml((7, 3, 5), (1.4, 0.6, 2.0), attributes=attributes)
    path = write_oct(tmp_path / "no_range.oct", coded_db(), header=header)
    assert read_oct_volume(path).shape == (7, 3, 5)  # the volume needs no ranges
    one_line_error(
        path, r"no positive RangeZ \(None\): the voxel size is unknown", read=oct_file_voxel_size
    )
    path = write_oct(tmp_path / "averaged.oct", coded_db(), ranges=(1.4, 0.0, 2.0))
    one_line_error(
        path,
        r"3 B-scans \(SizeY\) over RangeY = 0.0 mm: B-scans repeated at one",
        read=oct_file_voxel_size,
    )


def test_a_header_larger_than_the_bound_is_not_read(tmp_path: Path) -> None:
    header = header_xml((2048, 2048, 2048), (1.4, 0.6, 2.0))
    path = write_oct(tmp_path / "huge.oct", coded_db(), header=header)
    one_line_error(path, r"2048 x 2048 x 2048 float32 \(32 GiB\), more than the 4 GiB fbia reads")


def test_zip_bomb_by_the_archive_directory_is_not_read(tmp_path: Path, monkeypatch) -> None:
    """The header's 480 bytes are within the bound (lowered to 1 KiB here); the archive's
    directory says the data unpack to 4 GB: refused before a byte is inflated."""
    monkeypatch.setattr(oct_reader, "THORLABS_MAX_BYTES", 1024)
    path = write_oct(tmp_path / "bomb.oct", coded_db())
    patch_directory_size(path, INTENSITY, 0xFFFFFF00)
    one_line_error(path, r"unpacks to 4294967040 bytes by the archive's directory, .* zip bomb")


def test_a_stream_shorter_than_the_directory_says(tmp_path: Path) -> None:
    """The directory and the header agree on 420 bytes, the data hold 140: the bytes are
    counted as they are read, not taken from the directory."""
    db = coded_db()
    short = {INTENSITY: db[:1].astype("<f4").tobytes()}
    path = write_oct(tmp_path / "short.oct", db, members=short)
    patch_directory_size(path, INTENSITY, db.size * 4)
    one_line_error(path, "Intensity.data ends after 140 of its 420 bytes")


def test_damaged_data(tmp_path: Path) -> None:
    path = write_oct(tmp_path / "damaged.oct", coded_db(), compression=zipfile.ZIP_STORED)
    with zipfile.ZipFile(path) as zf:
        info = zf.getinfo(INTENSITY)
    data = bytearray(path.read_bytes())
    (name_length, extra_length) = struct.unpack_from("<HH", data, info.header_offset + 26)
    data[info.header_offset + 30 + name_length + extra_length + 100] ^= 0x01
    path.write_bytes(bytes(data))
    one_line_error(path, r"cannot read Intensity.data: Bad CRC-32")
