"""``cutfem_fpi`` on a user mesh file, the same file ``ale_fsi`` reads (``mesh_file``).

The file is the default flow cell written by ``ale_fsi``'s own writer (straight-sided, coarse:
interface and solid elements 0.08 mm); ``cutfem_fpi`` takes its solid as the skeleton mesh,
the solid's interface edges as the biofilm outline and the bounding box as the channel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("xfem")

import meshio  # noqa: E402
import shapely  # noqa: E402

import fbia  # noqa: E402
from fbia.plugins.cutfem_fpi import CutFemFpiForwardModel  # noqa: E402
from fbia.plugins.cutfem_fpi.model import POROELASTIC_OUTLINE  # noqa: E402
from fbia.plugins.fem.outlines import NAMED_OUTLINES  # noqa: E402
from fbia.studies.cli import main  # noqa: E402

LEVEL = {"inflow_rate": 100.0}
COMMON = {"background_mesh_size": 0.1, "coupling_tol": 1e-7}
H = 0.08  # interface and solid element size of the file [mm]


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from fbia.plugins.fem.flow_cell import build_flow_cell, write_mesh

    mesh = build_flow_cell(
        outline=NAMED_OUTLINES[POROELASTIC_OUTLINE],  # cutfem_fpi's default mound
        mesh_size=0.2,
        interface_mesh_size=H,
        solid_mesh_size=H,
        curve_order=1,
    )
    return write_mesh(mesh, tmp_path_factory.mktemp("mesh") / "cell.msh")


@pytest.fixture(scope="module")
def from_file(cell: Path, tmp_path_factory: pytest.TempPathFactory):
    model = CutFemFpiForwardModel(mesh_file=cell, **COMMON)
    return model, model.solve({}, [LEVEL], tmp_path_factory.mktemp("run")).interface(LEVEL)


def _edit(src: Path, dst: Path, **renames: str | None) -> Path:
    """A copy of a gmsh file with physical names renamed (``None``: the name dropped)."""
    data = meshio.read(src)
    for old, new in renames.items():
        tag = data.field_data.pop(old)
        if new is not None:
            data.field_data[new] = tag
    meshio.write(dst, data, file_format="gmsh22", binary=False)
    return dst


def test_mesh_file_gives_the_builders_answer_for_the_same_outline(from_file, tmp_path) -> None:
    """File and builder (polygon of the file's interface vertices, straight P2 elements of the
    same size) share the background grid, the channel and the reference interface exactly;
    only the netgen triangulations of the solid differ (74 vs 76 triangles).  The deformed
    interfaces then differ by the skeleton's discretisation error: measured 0.54 um of 72 um
    at h = 0.08 mm and 0.066 um at h = 0.04 mm (x 8.2, the O(h^3) of P2), so 1.5 % of the
    displacement bounds it here with a 2x margin."""
    model, a = from_file
    solver = model.solver
    assert (solver.length, solver.height, solver.origin) == (2.0, pytest.approx(1.0), (0.0, 0.0))
    outline = solver.sampler.reference[:: solver.coupling.samples_per_edge]  # the vertices
    builder = CutFemFpiForwardModel(
        outline=outline.tolist(),
        smooth_outline=False,
        skeleton_curve_order=1,
        interface_mesh_size=H,
        **COMMON,
    )
    b = builder.solve({}, [LEVEL], tmp_path).interface(LEVEL)
    np.testing.assert_allclose(
        builder.solver.sampler.reference, solver.sampler.reference, atol=1e-12
    )
    disp = float(np.max(np.linalg.norm(a.vertices - solver.sampler.reference, axis=1)))
    gap = shapely.hausdorff_distance(shapely.LineString(a.vertices), shapely.LineString(b.vertices))
    assert disp > 0.05  # mm: the mound bends
    assert gap < 0.015 * disp


def test_a_moved_mesh_gives_the_moved_interface(cell, from_file, tmp_path) -> None:
    """The channel is the file's bounding box wherever it lies; the background grid is moved
    with it, so the answer is the same to round-off."""
    shift = np.array([0.3, -0.2])
    data = meshio.read(cell)
    data.points[:, :2] += shift
    moved = tmp_path / "moved.msh"
    meshio.write(moved, data, file_format="gmsh22", binary=False)
    model = CutFemFpiForwardModel(mesh_file=moved, **COMMON)
    b = model.solve({}, [LEVEL], tmp_path).interface(LEVEL)
    assert model.solver.origin == pytest.approx(tuple(shift))
    np.testing.assert_allclose(b.vertices - shift, from_file[1].vertices, rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    ("renames", "message"),
    [
        ({"interface": None}, "missing boundary name(s) ['interface']"),
        ({"solid_fixed": None}, "missing boundary name(s) ['solid_fixed']"),
        ({"solid": None}, "no region named 'solid' or 'solid_<k>' (regions: ['fluid'])"),
        ({"walls": "obstacle"}, "cutfem_fpi has no rigid obstacles"),
    ],
)
def test_a_mesh_without_the_names_is_a_one_line_config_error(cell, tmp_path, renames, message):
    bad = _edit(cell, tmp_path / "bad.msh", **renames)
    model = CutFemFpiForwardModel(mesh_file=bad, **COMMON)
    with pytest.raises(fbia.ConfigError) as info:
        model.solve({}, [LEVEL], tmp_path)
    text = str(info.value)
    assert text.startswith(f"{bad}: ") and message in text and "\n" not in text


def test_solid_subdomains_merge_into_one_skeleton(tmp_path) -> None:
    """An ale_fsi file with regions solid_1, solid_2 (Paper A Fig. 9 layers): cutfem_fpi has one
    skeleton material, so the regions become one skeleton mesh, their 'internal' edges dropped."""
    from fbia.plugins.fem.flow_cell import build_flow_cell, mesh_arrays, write_mesh

    layer = [(0.0, -0.1), (2.0, -0.1), (2.0, 0.08), (0.0, 0.08)]
    mesh = build_flow_cell(
        outline=NAMED_OUTLINES[POROELASTIC_OUTLINE],
        mesh_size=0.2,
        interface_mesh_size=H,
        subdomains=[layer],
        curve_order=1,
    )
    _, regions, boundaries = mesh_arrays(mesh)
    assert set(regions) == {"fluid", "solid_1", "solid_2"} and "internal" in boundaries
    model = CutFemFpiForwardModel(mesh_file=write_mesh(mesh, tmp_path / "layers.msh"), **COMMON)
    skeleton = model.solver.skeleton.mesh
    assert skeleton.GetMaterials() == ("solid",)
    assert set(skeleton.GetBoundaries()) == {"interface", "solid_fixed"}
    assert skeleton.ne == len(regions["solid_1"]) + len(regions["solid_2"])


def test_mesh_file_excludes_the_builder_options() -> None:
    with pytest.raises(fbia.ConfigError, match="mesh_file or outline, not both"):
        CutFemFpiForwardModel(mesh_file="x.msh", outline=[(0.5, 0.0), (0.8, 0.3), (1.1, 0.0)])
    with pytest.raises(fbia.ConfigError, match="mesh_file or channel_length"):
        CutFemFpiForwardModel(mesh_file="x.msh", channel_length=3.0)


STUDY = """\
[model]
name = "cutfem_fpi"
options = {{ mesh_file = "{mesh}", background_mesh_size = 0.1, coupling_tol = 1e-7 }}

[[parameters]]
name = "E"
unit = "Pa"
bounds = [100.0, 800.0]
initial = 300.0

[synthetic]
truth = {{ E = 300.0 }}
coordinates = [ {{ inflow_rate = 100.0 }} ]
noise_std = 0.0

[measure]
name = "cpp"

[likelihood]
noise_std = 0.001

[executor]
kind = "serial"
"""


def test_study_reads_mesh_file_relative_to_the_study_file(cell, from_file, tmp_path, monkeypatch):
    """``fbia forward`` on a study whose mesh_file is relative to the study's folder, run from
    another working directory."""
    folder = tmp_path / "study"
    (folder / "meshes").mkdir(parents=True)
    (folder / "meshes" / "cell.msh").write_bytes(cell.read_bytes())
    (folder / "study.toml").write_text(STUDY.format(mesh="meshes/cell.msh"))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    study = fbia.load_study(Path("..") / "study" / "study.toml", build=False)
    assert study.model.options.mesh_file == folder.resolve() / "meshes" / "cell.msh"
    assert main(["forward", "../study/study.toml", "--output", "f"]) == 0
    simulated = fbia.Interface.read(
        elsewhere / "f" / "interfaces" / "simulated_inflow_rate_100.csv"
    )
    np.testing.assert_allclose(simulated.vertices, from_file[1].vertices, rtol=0, atol=1e-12)


def test_missing_or_unreadable_mesh_file_is_one_line_exit_2(tmp_path, monkeypatch, capsys):
    """Checked by `fbia validate` before any run; meshio's sys.exit on a garbage .msh is caught."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "study.toml").write_text(STUDY.format(mesh="meshes/cell.msh"))
    assert main(["validate", "study.toml"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "[model.options] mesh_file: file not found" in err
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "cell.msh").write_text("not a mesh")
    with pytest.raises(fbia.ConfigError, match=r"cell.msh: meshio cannot read the mesh"):
        fbia.forward_model("cutfem_fpi", mesh_file=tmp_path / "meshes" / "cell.msh").solve(
            {"E": 300.0}, [{"inflow_rate": 100.0}], tmp_path / "run"
        )
