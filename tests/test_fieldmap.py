"""Force-current map: file round trip, interpolation accuracy and physics, bad files, CLI,
the numpy-only reader in firmware_io (air coils: the core model is owned elsewhere)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from designkit import default_design
from designkit.array import CoilArray, gradient_from_g5
from designkit.cli import main
from designkit.design import design_to_toml
from designkit.errors import BadInputError
from designkit import fieldmap

SMALL = default_design().replace(**{"core": None, "workspace.half_width_m": 0.03,
                                     "workspace.z_min_m": 0.01, "workspace.z_max_m": 0.04})


@pytest.fixture(scope="module")
def mapfile(tmp_path_factory):
    path = tmp_path_factory.mktemp("map") / "small.npz"
    fieldmap.write(path, fieldmap.build(SMALL, spacing=0.003, progress=False))
    return path


@pytest.fixture(scope="module")
def fm(mapfile):
    return fieldmap.load(mapfile, SMALL)


@pytest.fixture(scope="module")
def sample(fm):
    rng = np.random.default_rng(7)
    lo, hi = fm.bounds
    p = rng.uniform(lo, hi, (400, 3))
    return p, CoilArray.from_design(SMALL).actuation_matrix(p)


def test_bounds_and_meta(fm):
    lo, hi = fm.bounds
    np.testing.assert_allclose(lo, [-0.03, -0.03, 0.01])
    np.testing.assert_allclose(hi, [0.03, 0.03, 0.04])
    assert fm.meta["design_sha256"] == SMALL.spec_hash()
    assert fm.meta["units"]["A_rows_0_2"] == "T/A"
    assert len(fm.meta["coil_positions_m"]) == 9


def test_interpolation_error_against_direct(fm, sample):
    p, a = sample
    scale = np.abs(a).max(axis=(0, 2))
    quad = np.abs(fm.actuation(p) - a).max(axis=(0, 2)) / scale
    lin = np.abs(fm.actuation(p, order="linear") - a).max(axis=(0, 2)) / scale
    assert np.all(quad < 2e-3)
    # the quadratic-exact correction must beat trilinear clearly (O(h^3) vs O(h^2))
    assert np.max(quad) < 0.3 * np.max(lin)


def test_nodes_are_reproduced_and_gradient_is_symmetric_traceless(fm):
    g = fm.meta["grid"]
    node = np.asarray(g["lower_m"]) + np.asarray(g["spacing_m"]) * [2, 3, 1]
    a_direct = CoilArray.from_design(SMALL).actuation_matrix(node)
    # at a node only the (rho, z) table error remains (build tolerance 4e-4 -> <= 1e-4)
    err = np.abs(fm.actuation(node) - a_direct).max(axis=1)
    assert np.all(err <= 1e-4 * np.abs(a_direct).max(axis=1))
    full = gradient_from_g5(np.moveaxis(fm.actuation(node + 1e-3)[3:], 0, -1))
    np.testing.assert_allclose(np.trace(full, axis1=-2, axis2=-1), 0, atol=1e-12)
    np.testing.assert_allclose(full, np.swapaxes(full, -1, -2))


def test_fine_slab_is_used_and_continuous(fm):
    g = fm.meta["fine_grid"]
    assert g["upper_m"][2] == pytest.approx(0.014) and g["spacing_m"][0] == pytest.approx(0.0015)
    # just below and above the slab top the two grids agree to interpolation accuracy
    p = np.array([[0.004, -0.007, 0.014 - 1e-9], [0.004, -0.007, 0.014 + 1e-9]])
    a = fm.actuation(p)
    assert np.abs(a[0] - a[1]).max() < 2e-3 * np.abs(a).max()


def test_single_point_equals_batch(fm, sample):
    p, _ = sample
    one = np.array([fm.actuation(q) for q in p[:20]])
    np.testing.assert_allclose(one, fm.actuation(p[:20]), rtol=1e-6, atol=1e-9)
    assert fm.actuation(tuple(p[0])).shape == (8, 9)


def test_outside_points(fm):
    lo, hi = fm.bounds
    out = hi + [0, 0, 0.002]
    with pytest.raises(BadInputError, match="inside the map box"):
        fm.actuation(out)
    with pytest.raises(BadInputError, match="inside the map box"):
        fm.actuation(np.array([lo, out]))
    a = fm.actuation(out, outside="extrapolate")
    assert np.all(np.isfinite(a))
    with pytest.raises(BadInputError):
        fm.actuation([np.nan, 0, 0.02])


def test_bad_files(mapfile, tmp_path):
    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(mapfile.read_bytes()[: mapfile.stat().st_size // 2])
    with pytest.raises(BadInputError, match="truncated"):
        fieldmap.load(trunc)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    with pytest.raises(BadInputError, match="foreign"):
        fieldmap.load(foreign)
    text = tmp_path / "text.npz"
    text.write_text("hello")
    with pytest.raises(BadInputError):
        fieldmap.load(text)
    with pytest.raises(BadInputError, match="built from design"):
        fieldmap.load(mapfile, default_design())
    # corrupted values (and a NaN) are caught
    arrays, meta = fieldmap.read_arrays(mapfile)
    assert set(arrays) == {"A", "dG", "A_fine", "dG_fine", "RZ0"}
    bad = tmp_path / "nan.npz"
    for name in ("A", "dG_fine", "RZ0"):
        a2 = arrays[name].copy()
        a2.reshape(-1)[0] = np.nan
        np.savez(bad, **{**arrays, name: a2}, meta=np.array(json.dumps(meta)))
        with pytest.raises(BadInputError, match="finite"):
            fieldmap.load(bad)
        a2.reshape(-1)[0] = 1.0
        np.savez(bad, **{**arrays, name: a2}, meta=np.array(json.dumps(meta)))
        with pytest.raises(BadInputError, match="SHA-256"):
            fieldmap.load(bad)
    meta2 = dict(meta, units={**meta["units"], "grid": "mm"})
    np.savez(bad, **arrays, meta=np.array(json.dumps(meta2)))
    with pytest.raises(BadInputError, match="units"):
        fieldmap.load(bad)
    short = {k: v for k, v in arrays.items() if k != "dG_fine"}
    np.savez(bad, **short, meta=np.array(json.dumps(meta)))
    with pytest.raises(BadInputError, match="dG_fine"):
        fieldmap.load(bad)
    # a table that does not match its description, or a description without its table
    np.savez(bad, **{**arrays, "RZ0": arrays["RZ0"][:-1]}, meta=np.array(json.dumps(meta)))
    with pytest.raises(BadInputError, match="RZ0"):
        fieldmap.load(bad)
    meta3 = dict(meta, rz_tables=[dict(meta["rz_tables"][0], coils=[0, 99])])
    np.savez(bad, **arrays, meta=np.array(json.dumps(meta3)))
    with pytest.raises(BadInputError, match="rz_tables"):
        fieldmap.load(bad)
    old = dict(meta, version=1)
    np.savez(bad, **arrays, meta=np.array(json.dumps(old)))
    with pytest.raises(BadInputError, match="version"):
        fieldmap.load(bad)


def test_firmware_reader_numpy_only(mapfile, fm, sample):
    p, _ = sample
    code = (
        "import sys, numpy as np\n"
        "from firmware_io.mapfile import MapFile\n"
        f"m = MapFile.load({str(mapfile)!r})\n"
        f"p = np.array({p[:10].tolist()!r})\n"
        "np.save(sys.argv[1], m.actuation(p))\n"
        f"q = np.array({p[:200].tolist()!r})\n"
        "np.save(sys.argv[1][:-4] + '_batch.npy', m.actuation(q))\n"
        "np.save(sys.argv[1][:-4] + '_one.npy', m.actuation(q[7]))\n"
        "assert not any(k.startswith(('designkit', 'scipy')) for k in sys.modules), "
        "sorted(k for k in sys.modules if k.startswith(('designkit', 'scipy')))\n"
    )
    out = mapfile.parent / "fw.npy"
    root = Path(__file__).resolve().parents[1]
    subprocess.run([sys.executable, "-c", code, str(out)], check=True, cwd=root,
                   env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"})
    np.testing.assert_allclose(np.load(out), fm.actuation(p[:10]), rtol=1e-6, atol=1e-12)
    # the batch path (rho, z tables) and the single-point path agree with designkit's
    batch = np.load(out.with_name("fw_batch.npy"))
    assert fm.batch_uses_tables
    np.testing.assert_allclose(batch, fm.actuation(p[:200]), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(np.load(out.with_name("fw_one.npy")), fm.actuation(p[7]),
                               rtol=1e-6, atol=1e-12)


def test_cli_map_writes_one_file(tmp_path):
    toml = tmp_path / "d.toml"
    toml.write_text(design_to_toml(SMALL.replace(**{"workspace.half_width_m": 0.01,
                                                    "workspace.z_max_m": 0.02})))
    out = tmp_path / "m.npz"
    assert main(["map", "--design", str(toml), "--spacing", "5", "--out", str(out),
                 "--quiet"]) == 0
    assert [f.name for f in tmp_path.iterdir() if f.suffix == ".npz"] == ["m.npz"]
    loaded = fieldmap.load(out)
    assert loaded.meta["grid"]["shape"] == [5, 5, 3]
    assert loaded.meta["fine_grid"]["shape"] == [9, 9, 3]  # 4 mm slab at 2.5 mm
    assert main(["map", "--spacing", "-1", "--out", str(out), "--quiet"]) == 1


def test_third_derivatives_from_tables_match_differences_of_direct_gradients():
    # rotated and shifted coil, so the frame change of T is exercised too
    from designkit import Coil, Pose
    from designkit.fieldmap import _t_full, compute_grid

    c = Coil.from_design(SMALL)
    c = c.replace(pose=Pose.from_axis((0.01, -0.02, -0.06), (0.3, 0.2, 1.0)))
    arr = CoilArray((c,))
    axes = [np.array([0.0, 0.01]), np.array([0.0, 0.012]), np.array([0.02, 0.03])]
    _, t, _ = compute_grid(arr, axes, tolerance=1e-6, progress=False)
    p = np.array([0.01, 0.0, 0.03])
    h = 1e-5
    fd = np.stack([(c.field(p + h * e, 1.0, gradient=True)[1]
                    - c.field(p - h * e, 1.0, gradient=True)[1]) / (2 * h) for e in np.eye(3)],
                  -1)  # fd[i, j, k] = d G_ij / dx_k
    np.testing.assert_allclose(_t_full(t[1, 0, 1, :, 0][None])[0], fd, rtol=0,
                               atol=1e-4 * np.abs(fd).max())


# ---------------------------------------------------------------------------- (rho, z) batch path
def _rz_only(array, lower, upper, **kw):
    """The batch interpolator of ``array`` over the box, without the 3-D grid (fast)."""
    from designkit.fieldmap import _prepare_rz, _union_spec, compute_rz_table, rz_table_spec

    tables, metas = [], []
    for proto, idx in array.coil_types().items():
        spec = _union_spec([rz_table_spec(array.coils[k], lower, upper, 7.5e-5, 0.025, 0.05,
                                          **kw) for k in idx])
        tables.append(compute_rz_table(proto, spec, progress=False).astype(np.float32))
        metas.append({"name": f"RZ{len(metas)}", "coils": idx, **spec})
    rot = [c.pose.rotation for c in array.coils]
    return _prepare_rz(tables, metas, array.positions(), rot)


def _rel_err(a, ref):
    return np.abs(a - ref).max(axis=(0, 2)) / np.abs(ref).max(axis=(0, 2))


def test_batch_path_is_used_and_agrees_with_direct(fm, sample):
    p, a = sample
    assert fm.batch_uses_tables and len(p) >= fieldmap.BATCH_MIN
    batch = fm.actuation(p)
    assert np.all(_rel_err(batch, a) < 1e-3)
    # the 3-D path (small batches) agrees with it to the same accuracy
    small = np.concatenate([fm.actuation(p[k:k + 40]) for k in range(0, len(p), 40)])
    assert np.all(_rel_err(small, a) < 2e-3)
    # the physics the 5 rows do not impose: dBz/dz = -dBx/dx - dBy/dy matches direct Gzz
    c = CoilArray.from_design(SMALL)
    _, g = c.coils[4].field(p, 1.0, gradient=True)
    gzz = -batch[:, 3, 4] - batch[:, 6, 4]
    assert np.abs(gzz - g[:, 2, 2]).max() < 1e-3 * np.abs(g[:, 2, 2]).max()
    full = gradient_from_g5(np.moveaxis(batch[:, 3:], 1, -1))
    np.testing.assert_allclose(np.trace(full, axis1=-2, axis2=-1), 0, atol=1e-15)
    np.testing.assert_array_equal(full, np.swapaxes(full, -1, -2))


def test_batch_path_with_core_near_the_rim():
    # thesis coil with its iron core: the bottom of the workspace is 5 mm above the core's rim
    from designkit.fieldmap import interpolate_rz

    d = default_design()
    arr = CoilArray.from_design(d).coils[4:5]  # the centre coil (keeps the test fast)
    arr = CoilArray(arr)
    lo, hi = np.array([-0.03, -0.03, 0.01]), np.array([0.03, 0.03, 0.03])
    prep = _rz_only(arr, lo, hi)
    rng = np.random.default_rng(3)
    p = rng.uniform(lo, hi, (600, 3))
    p[:300, 2] = rng.uniform(0.01, 0.012, 300)  # just above the rim
    ref = arr.actuation_matrix(p)
    assert np.all(_rel_err(interpolate_rz(prep, p, 1), ref) < 1e-3)


def test_batch_path_tilted_and_shifted_coils():
    from designkit import Coil, Pose
    from designkit.fieldmap import interpolate_rz

    c = Coil.from_design(SMALL)
    coils = (c.replace(pose=Pose.from_axis((0.06, 0.0, -0.07), (-0.3, -0.1, 1.0))),
             c.replace(pose=Pose((-0.05, 0.0, -0.07))),
             c.replace(pose=Pose.from_axis((0.0, 0.09, -0.08), (0.0, -0.3, 1.0))))
    arr = CoilArray(coils)
    lo, hi = np.array([-0.02, -0.02, 0.02]), np.array([0.02, 0.02, 0.04])
    prep = _rz_only(arr, lo, hi)
    assert len(prep) == 1 and prep[0]["rot"] is not None and not prep[0]["shared_z"]
    p = np.random.default_rng(5).uniform(lo, hi, (300, 3))
    assert np.all(_rel_err(interpolate_rz(prep, p, 3), arr.actuation_matrix(p)) < 1e-3)


def test_rz_table_refuses_points_beside_the_sources():
    from designkit.fieldmap import rz_table_spec

    c = CoilArray.from_design(SMALL).coils[0]
    # the box reaches below the top of the winding: no table (batches use the 3-D grid)
    assert rz_table_spec(c, np.array([-0.1, -0.1, -0.01]), np.array([0.1, 0.1, 0.05]),
                         7.5e-5, 0.025) is None
