"""OCT segmentation on realistic scans (issue 45): fully developed speckle, pores and
sub-resolution channels, shadowing, a window reflection, a tilted glass or a membrane
substratum (``fbia.testing.oct.realistic_oct_scan`` and its family).

The rule, written before the runs (issue 45's "done when"): on every member of the family the
segmented interface lies within one axial resolution cell (5 um) RMS of the true outer
boundary (the closest-point distance of its vertices to the true surface, the cpp measure)
and at most 5 % of its vertices lie more than 20 um under the true top of their A-scan; a
membrane scan without ``substratum_depth`` is refused with a reason that names the
substratum.
"""

from __future__ import annotations

import numpy as np
import pytest

from fbia.core.errors import ConfigError
from fbia.core.observation import Observation
from fbia.imaging.oct import OctSegmentation, segment_oct
from fbia.imaging.oct_structure import MAX_DEEP_SHARE
from fbia.measures import CppMeasure
from fbia.testing.oct import RealisticScan, realistic_oct_scan, scan_family

FAMILY = scan_family()
GLASS = [name for name, kw in FAMILY.items() if kw.get("substratum", "glass") == "glass"]
MEMBRANE = [name for name in FAMILY if name not in GLASS]


def segmented(sc: RealisticScan, **options) -> OctSegmentation:
    """The scan segmented with its resolution, the substratum given on a membrane."""
    if sc.substratum == "membrane" and "substratum_depth" not in options:
        options = {"substratum_depth": sc.substratum_depth, "substratum_tilt": sc.tilt, **options}
    return segment_oct(sc.volume, sc.voxel_size, resolution=sc.resolution, **options)


def height_errors(seg: OctSegmentation, sc: RealisticScan) -> np.ndarray:
    """Segmented minus true height at every vertex (the truth at the vertex's A-scan) [mm]."""
    return sc.height_errors(seg.interface)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("name", list(FAMILY))
def test_the_interface_of_every_realistic_scan_is_within_a_resolution_cell(name, seed):
    """Measured with the default (surface = "auto": the height map on 25 of the 30 scans
    of seeds 0-2, the outer boundary where it is one surface): 2.3-3.9 um RMS, no vertex 20
    um under the truth (marching cubes on the outer boundary alone: 2.3-23.7 um RMS)."""
    sc = realistic_oct_scan(seed=seed, **FAMILY[name])
    seg = segmented(sc)
    d = CppMeasure().residuals(seg.interface, Observation(sc.surface()))
    assert np.sqrt(np.mean(d**2)) <= sc.resolution[0]
    assert np.mean(height_errors(seg, sc) < -0.020) <= 0.05
    assert seg.quality.one_surface


@pytest.mark.parametrize("name", GLASS)
def test_the_window_and_the_tilted_glass_substratum_are_found_where_they_are(name):
    sc = realistic_oct_scan(seed=0, **FAMILY[name])
    seg = segmented(sc)
    dz, dy, dx = sc.voxel_size
    if sc.window_row is None:
        assert seg.window_row is None
    else:
        assert seg.window_row == pytest.approx(sc.window_row, abs=1.0)
    # the substratum's slope in rows per A-scan, and its surface within a row at the centre
    assert seg.tilt[0] == pytest.approx(sc.tilt[0] * dy / dz, abs=0.01)
    assert seg.tilt[1] == pytest.approx(sc.tilt[1] * dx / dz, abs=0.01)
    assert seg.substratum_depth == pytest.approx(sc.substratum_depth, abs=dz)
    kinds = sorted(r.kind for r in seg.reflections)
    assert kinds.count("substratum") == 1 and kinds.count("window") == (sc.window_row is not None)


@pytest.mark.parametrize("name", MEMBRANE)
def test_a_membrane_scan_without_substratum_depth_is_refused_naming_the_substratum(name):
    sc = realistic_oct_scan(seed=0, **FAMILY[name])
    with pytest.raises(ConfigError) as err:
        segment_oct(sc.volume, sc.voxel_size, resolution=sc.resolution)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("oct volume: substratum not found: no flat reflection")
    assert message.endswith("give substratum_depth (mm below the first row)")
    if sc.window_row is not None:  # the window it did find is named, as the window
        assert "(window; " in message


def test_marching_cubes_around_speckle_voids_is_not_one_surface_and_says_so():
    """The check tells the wrapped voids of marching cubes from a surface the probe sees:
    on this scan the outer boundary has most of its area hidden from the probe by more than
    a resolution cell (28 % of its vertices 20 um under the truth), and surface = "auto"
    takes the height map instead and says why."""
    sc = realistic_oct_scan(seed=1, **FAMILY["glass_typical"])
    outer = segmented(sc, surface="outer")
    assert outer.quality.deep_area_share > MAX_DEEP_SHARE and not outer.quality.one_surface
    assert np.mean(height_errors(outer, sc) < -0.020) > 0.05  # the truth agrees: not one
    assert outer.quality.note().startswith("not one surface: ")
    auto = segmented(sc)
    assert auto.surface_kind == "height_map" and auto.quality.one_surface
    assert auto.quality.rejected is not None and not auto.quality.rejected.one_surface
    assert "the outer boundary was not one surface" in auto.quality.note()


@pytest.mark.parametrize(
    ("name", "seed"), [("glass_clean_compounded", 1), ("membrane_solid_no_window", 0)]
)
def test_where_the_outer_boundary_is_one_surface_auto_keeps_it(name, seed):
    """The other way round: where marching cubes wraps nothing (measured: none of its
    vertices 20 um under the truth), the check passes it and "auto" keeps it."""
    sc = realistic_oct_scan(seed=seed, **FAMILY[name])
    seg = segmented(sc)
    assert seg.surface_kind == "outer" and seg.quality.one_surface
    assert np.mean(height_errors(seg, sc) < -0.020) <= 0.01


def test_the_structure_parameters_agree_with_the_truth():
    """Thickness and roughness within a resolution cell of the true thickness map (measured
    on the family, seeds 0-2, bench_oct_family.py: within 1 um for the mean and Ra); the
    maximum within three cells (the peaks' tips are thinner than a cell); the coverage misses
    the film thinner than a resolution cell at the rims (0.19-0.32 against 0.28-0.35). The
    porosity is reported, not judged: the pores that speckle and the filter fill count as
    biofilm and dark speckle inside solid biofilm as pore (0.02-0.13 against 0.10-0.15)."""
    for name in ("glass_typical", "membrane_typical"):
        sc = realistic_oct_scan(seed=0, **FAMILY[name])
        st = segmented(sc).structure
        h = sc.height
        cell = sc.resolution[0]
        assert st.mean_thickness == pytest.approx(h.mean(), abs=cell)
        assert st.ra == pytest.approx(np.mean(np.abs(h - h.mean())), abs=cell)
        assert st.max_thickness == pytest.approx(h.max(), abs=3 * cell)
        assert st.coverage == pytest.approx(np.mean(h > 0), abs=0.1)
        assert 0.0 <= st.porosity < 1.0
