"""Issue 31 item 1: 3-D geometry files are checked where they are read, at ``fbia validate``
time: a colony surface or a 3-D mesh that no run could use is one line naming the file and
what is wrong, exit status 2, never a study whose every run fails; a garbage netgen ``.vol``
file no longer hangs the reader."""

from __future__ import annotations

import numpy as np
import pytest
from _studies import one_error_line

from fbia.studies.cli import main

STUDY = """\
[study]
name = "geometry"
output = "out"
[model]
name = "ale_fsi"
options = {{ {options}, mesh_size = 0.4 }}
[[parameters]]
name = "E"
unit = "Pa"
bounds = [100.0, 800.0]
[synthetic]
truth = {{ E = 400.0 }}
coordinates = [ {{ inflow_rate = 1.0 }} ]
[measure]
name = "cpp"
[iterator]
name = "levenberg_marquardt"
"""

#: a cap of three triangles on the floor of the default duct (2 x 1 x 1 mm)
CAP = [
    [(0.8, 0.0, 0.3), (1.2, 0.0, 0.3), (1.0, 0.2, 0.5)],
    [(1.2, 0.0, 0.3), (1.0, 0.0, 0.7), (1.0, 0.2, 0.5)],
    [(1.0, 0.0, 0.7), (0.8, 0.0, 0.3), (1.0, 0.2, 0.5)],
]


def _stl(triangles) -> str:
    facets = "".join(
        "facet normal 0 0 1\nouter loop\n"
        + "".join(f"vertex {x} {y} {z}\n" for x, y, z in t)
        + "endloop\nendfacet\n"
        for t in triangles
    )
    return f"solid colony\n{facets}endsolid colony\n"


def _validate(tmp_path, capsys, options: str) -> tuple[int, str]:
    (tmp_path / "study.toml").write_text(STUDY.format(options=options))
    code = main(["validate", str(tmp_path / "study.toml")])
    return code, (one_error_line(capsys) if code else capsys.readouterr().out)


SURFACES = [
    ("ascii.stl", "solid x\ngarbage here\nendsolid\n", "meshio cannot read the surface: "),
    ("binary.stl", np.random.default_rng(0).bytes(300), "meshio cannot read the surface: "),
    ("garbage.ply", "ply\nformat ascii 1.0\ngarbage\n", "meshio cannot read the surface: "),
    ("garbage.obj", "v 1 2\nf 1 2 x\n", "meshio cannot read the surface: "),
    ("empty.stl", "", "mesh file has no triangle cells"),
    (
        "nan.stl",
        _stl([[(float("nan"), 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]]),
        "vertex coordinates contain NaN or infinite values",
    ),
    (
        "huge.stl",
        _stl([[(1e300, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]]),
        "vertex coordinates reach 1e+300, beyond the bound 1e+09 mm of any flow cell",
    ),
    (
        "flat.stl",
        _stl([[(0.8, 0.0, 0.3), (1.2, 0.0, 0.3), (1.0, 0.0, 0.7)]]),
        "the colony surface lies on or below the floor y = 0: empty",
    ),
    ("polyline.csv", "x,y\n0,0\n1,0.1\n2,0\n", "a colony surface must be a 3-D triangle surface"),
    (
        "in_um.stl",
        _stl([[(1e3 * x, 1e3 * y, 1e3 * z) for x, y, z in t] for t in CAP]),
        "the colony spans 400 x 400 mm: its height field at colony_resolution 0.02 mm would "
        "have 4.01e+08 nodes (at most 4e+06); is the surface in mm (fbia's unit)?",
    ),
]


@pytest.mark.parametrize(("name", "content", "message"), SURFACES, ids=[s[0] for s in SURFACES])
def test_a_colony_surface_no_run_could_use_is_refused_at_validate(
    tmp_path, capsys, name, content, message
):
    path = tmp_path / name
    path.write_bytes(content) if isinstance(content, bytes) else path.write_text(content)
    code, line = _validate(tmp_path, capsys, f'geometry = "colony_3d", colony_surface = "{name}"')
    assert code == 2
    assert line.startswith(f"{tmp_path / 'study.toml'}: [model.options]: colony_surface {path}: ")
    assert message in line


def test_a_usable_colony_surface_validates(tmp_path, capsys):
    (tmp_path / "cap.stl").write_text(_stl(CAP))
    code, out = _validate(tmp_path, capsys, 'geometry = "colony_3d", colony_surface = "cap.stl"')
    assert code == 0 and out.rstrip().endswith("ok")


@pytest.fixture(scope="module")
def dome_msh(tmp_path_factory):
    """A valid named 3-D mesh (the dome duct, coarse) as gmsh 2.2."""
    from fbia.plugins.ale_fsi.geometry3d import build_dome_cell
    from fbia.plugins.ale_fsi.mesh_file3d import write_mesh_3d

    mesh = build_dome_cell(mesh_size=0.5, interface_mesh_size=0.3)
    folder = tmp_path_factory.mktemp("dome")
    mesh.ngmesh.Save(str(folder / "dome.vol"))
    return write_mesh_3d(mesh, folder / "dome.msh")


def _edited_msh(dome_msh, tmp_path, name, edit) -> str:
    import meshio

    mesh = meshio.read(dome_msh)
    edit(mesh)
    mesh.write(tmp_path / name, file_format="gmsh22", binary=False)
    return name


def test_a_3d_mesh_with_a_nan_coordinate_is_refused_at_validate(tmp_path, capsys, dome_msh):
    def nan(mesh):
        mesh.points[5, 1] = np.nan

    name = _edited_msh(dome_msh, tmp_path, "nan.msh", nan)
    code, line = _validate(tmp_path, capsys, f'mesh_file = "{name}"')
    assert code == 2
    assert line.endswith(f"{tmp_path / name}: point 5 of the mesh has a NaN or infinite coordinate")


def test_a_flat_3d_mesh_is_refused_at_validate(tmp_path, capsys, dome_msh):
    def flat(mesh):
        mesh.points[:, 2] = 0.0  # one layer: every tetrahedron flat

    name = _edited_msh(dome_msh, tmp_path, "flat.msh", flat)
    code, line = _validate(tmp_path, capsys, f'mesh_file = "{name}"')
    assert code == 2
    assert line.endswith(
        f"{tmp_path / name}: the mesh has no volume: all its tetrahedra are flat (its points "
        "in one plane?)"
    )


def test_a_3d_mesh_without_its_named_boundaries_is_refused_at_validate(tmp_path, capsys, dome_msh):
    def unnamed(mesh):
        mesh.field_data = {k: v for k, v in mesh.field_data.items() if k != "outflow"}

    name = _edited_msh(dome_msh, tmp_path, "unnamed.msh", unnamed)
    code, line = _validate(tmp_path, capsys, f'mesh_file = "{name}"')
    assert code == 2
    assert "the 3-D mesh lacks the named region(s)/boundary(ies) ['outflow']" in line


def test_a_valid_3d_mesh_validates_and_a_netgen_vol_reads(tmp_path, capsys, dome_msh):
    assert _validate(tmp_path, capsys, f'mesh_file = "{dome_msh}"')[0] == 0
    vol = dome_msh.with_suffix(".vol")
    assert _validate(tmp_path, capsys, f'mesh_file = "{vol}"')[0] == 0


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("hello\nnot a mesh\n1 2 3\n", "not a netgen .vol mesh: it does not begin with 'mesh3d'"),
        (
            "mesh3d\ndimension\n3\npoints\n99999999\n0 0 0\n",
            "section 'points' announces 99999999 entries, but only 1 lines follow: a truncated "
            "or damaged .vol file",
        ),
        (
            "mesh3d\nsurfaceelements\n1000000000\n",
            "section 'surfaceelements' announces 1000000000 entries, but only 0 lines follow: a "
            "truncated or damaged .vol file",
        ),
    ],
)
def test_a_garbage_netgen_vol_file_is_one_line_not_a_hang(tmp_path, capsys, content, message):
    """netgen reads an announced count of lines past the end of the file forever (measured:
    still reading after 15 s with 2.4 GB); fbia checks the counts first."""
    (tmp_path / "bad.vol").write_text(content)
    code, line = _validate(tmp_path, capsys, 'mesh_file = "bad.vol"')
    assert code == 2
    assert line.endswith(f"{tmp_path / 'bad.vol'}: {message}")
