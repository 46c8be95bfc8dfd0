"""gmsh meshing and meshio export of the FEM model, without GetDP: the regions' areas against
the closed-form areas of the axisymmetric cross-section, the exported files read back."""

from __future__ import annotations

import meshio
import numpy as np
import pytest

from designkit.fem.mesh import AIR, CORE, WINDING, MeshSpec, build_mesh, export_meshio


def _areas(points, triangles, regions):
    p = points[:, :2]
    a, b, c = p[triangles[:, 0]], p[triangles[:, 1]], p[triangles[:, 2]]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                        - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
    return {int(r): float(area[regions == r].sum()) for r in np.unique(regions)}


@pytest.mark.parametrize("seed", [0, 1])
def test_mesh_regions_have_the_cross_section_areas(tmp_path, seed):
    rng = np.random.default_rng(seed)
    ri = rng.uniform(0.006, 0.012)
    ro = ri + rng.uniform(0.004, 0.01)
    length = rng.uniform(0.03, 0.08)
    rc = ri * rng.uniform(0.6, 1.0)
    lc = length + rng.uniform(0.0, 0.02)
    off = rng.uniform(-0.003, 0.003)
    spec = MeshSpec(ri, ro, length, rc, lc, off, length / 2 + 0.004, length / 2 + 0.06,
                    0.008, level=0)
    stats = build_mesh(spec, tmp_path / "m.msh")
    assert stats["nodes"] > 500 and stats["triangles"] > 900
    files = export_meshio(tmp_path / "m.msh", tmp_path / "m")
    assert sorted(f.suffix for f in files) == [".vtu", ".xdmf"]
    for f in files:
        mesh = meshio.read(f)
        tri = mesh.get_cells_type("triangle")
        regions = np.concatenate(mesh.cell_data["region"])
        assert len(tri) == len(regions) == stats["triangles"]
        areas = _areas(mesh.points, tri, regions)
        # straight-sided regions: the triangles tile them exactly
        assert areas[CORE] == pytest.approx(rc * lc, rel=1e-9)
        assert areas[WINDING] == pytest.approx((ro - ri) * length, rel=1e-9)
        assert areas[AIR] > 0
        assert mesh.points[:, 0].min() >= -1e-12  # the half-plane r >= 0


def test_air_coil_mesh_has_no_core_region(tmp_path):
    spec = MeshSpec(0.012, 0.019, 0.1, None, None, 0.0, 0.054, 0.11, 0.008, level=0)
    build_mesh(spec, tmp_path / "a.msh")
    mesh = meshio.read(export_meshio(tmp_path / "a.msh", tmp_path / "a")[0])
    regions = set(np.concatenate(mesh.cell_data["region"]).tolist())
    assert CORE not in regions and WINDING in regions
