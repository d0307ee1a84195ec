"""examples/oct_3d at a quick size: a synthetic OCT scan of a 3-D ale_fsi run at E = 400 Pa,
nu = 0.3 (coarser voxels than the example's: 10 um x 20 um x 20 um), segmented, and the
example's own LM study (one start) on the segmented surface recovers E.

Tolerance: the LM standard error of E at the example's voxels is 30 Pa (sigma = 4 um) and the
example's estimate is 415 Pa; voxels twice as large double the segmentation error (RMS
~ 8 um), so the error grows to ~ 60 Pa; E within 25 % (100 Pa) of the truth still tells the
dome's stiffness from the ends of the prior box [100, 800] Pa, and a sign or axis mistake in
the scan <-> model mapping, or a segmentation off by a voxel, puts E at a bound.
``make test-slow``; ~ 60 s on two cores."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

import fbia

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "oct_3d"


def _make_scan_module():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("oct_3d_make_scan", EXAMPLE / "make_scan.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_lm_recovers_E_from_a_coarse_synthetic_oct_scan(tmp_path: Path) -> None:
    make_scan = _make_scan_module()
    seg = make_scan.make_scan(tmp_path / "data", voxel_size=(0.01, 0.02, 0.02), shape=(50, 50, 80))
    assert seg.substratum_row == 46  # d_s = 45.5 dz: the reflection starts at row 46
    text = (EXAMPLE / "study_lm.toml").read_text()
    text = text.replace("{ E = 200.0 }, { E = 700.0 }", "{ E = 200.0 }")
    text = text.replace("0.004", "0.008")  # the segmentation error of twice larger voxels
    study = tmp_path / "study_lm.toml"
    study.write_text(text)
    result = fbia.run_study(fbia.load_study(study), echo=[].append)
    E = result.x["E"]
    assert abs(E - make_scan.TRUTH["E"]) < 100.0, E
