"""Map file v2: interpolation against direct evaluation, physics of the interpolated field,
bias force and sensor fields against CoilArray, bad files, CLI, and the numpy-only reader.

The fast tests use air coils (no iron: the coupled model is exact superposition and cheap);
the coupled iron-core array is in the slow tests (its array-level solve takes seconds)."""

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from designkit import default_design, fieldmap
from designkit.array import CoilArray
from designkit.cli import main
from designkit.design import design_to_toml
from designkit.errors import BadInputError

SMALL = default_design().replace(**{"core": None, "workspace.half_width_m": 0.03,
                                     "workspace.z_min_m": 0.01, "workspace.z_max_m": 0.04})


@pytest.fixture(scope="module")
def mapfile(tmp_path_factory):
    path = tmp_path_factory.mktemp("map") / "small.npz"
    fieldmap.write(path, fieldmap.build(SMALL, n_check=20, progress=False))
    return path


@pytest.fixture(scope="module")
def fm(mapfile):
    return fieldmap.load(mapfile, SMALL)


@pytest.fixture(scope="module")
def sample(fm):
    rng = np.random.default_rng(7)
    lo, hi = fm.bounds
    p = rng.uniform(lo, hi, (2000, 3))
    p[:300, 2] = rng.uniform(lo[2], lo[2] + 0.003, 300)  # the bottom, where fields vary fastest
    return p, CoilArray.from_design(SMALL).actuation_matrix(p)


def test_bounds_and_meta(fm):
    lo, hi = fm.bounds
    np.testing.assert_allclose(lo, [-0.03, -0.03, 0.01])
    np.testing.assert_allclose(hi, [0.03, 0.03, 0.04])
    assert fm.design_sha256 == SMALL.spec_hash()
    assert fm.max_current_a == SMALL.drive.max_current_a
    assert fm.total_current_a == SMALL.drive.total_current_a
    np.testing.assert_allclose(fm.moment_a_m2, [0, 0, SMALL.magnet.moment_a_m2])
    assert fm.meta["version"] == 3 and fm.n_coils == 9


def test_interpolation_error_against_direct(fm, sample):
    # per row, relative to the row's largest |A| over the box: the 1e-3 target
    p, a = sample
    err = np.abs(fm.actuation(p) - a).max(axis=(0, 2)) / np.abs(a).max(axis=(0, 2))
    assert np.all(err < 1e-3), err


def test_single_point_shapes_agree_with_batch(fm, sample):
    p, a = sample
    batch = fm.actuation(p[:40])
    one = np.array([fm.actuation(q) for q in p[:40]])
    np.testing.assert_allclose(one, batch, rtol=1e-5, atol=1e-6 * np.abs(batch).max())
    assert fm.actuation(p[0]).shape == (8, 9)
    assert fm.actuation(p[:1]).shape == (1, 8, 9)
    assert fm.actuation(tuple(p[0])).shape == (8, 9)
    np.testing.assert_array_equal(fm.actuation(p[:1])[0], fm.actuation(p[0]))


def test_interpolated_gradient_is_the_derivative_of_interpolated_b(fm):
    # central differences of the interpolated B rows (interpolated independently of the
    # gradient rows): symmetric and traceless, and equal to the interpolated gradient rows
    rng = np.random.default_rng(2)
    lo, hi = fm.bounds
    p = rng.uniform(lo + 0.002, hi - 0.002, (200, 3))
    h = 2e-4
    jac = np.stack([(fm.actuation(p + h * e)[:, :3] - fm.actuation(p - h * e)[:, :3]) / (2 * h)
                    for e in np.eye(3)], axis=2)  # (n, 3 [B_i], 3 [x_j], 9)
    scale = np.abs(jac).max()
    np.testing.assert_allclose(jac, np.swapaxes(jac, 1, 2), atol=1e-3 * scale)
    np.testing.assert_allclose(np.trace(jac, axis1=1, axis2=2), 0, atol=1e-3 * scale)
    g = fm.actuation(p)[:, 3:]
    rows = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2)]
    for r, (i, j) in enumerate(rows):
        np.testing.assert_allclose(jac[:, i, j], g[:, r], atol=2e-3 * scale)


def test_air_coils_have_no_bias_and_no_induced_field(fm, sample):
    p, _ = sample
    assert np.all(fm.bias_force(p[:50]) == 0)
    assert np.all(fm.sensor_induced_field(p[0]) == 0)
    assert fm.sensor_induced_field(p[0]).shape == (2, 9, 3)


def test_sensor_positions_and_coil_field_against_direct(fm):
    arr = CoilArray.from_design(SMALL)
    s = fm.sensor_positions_m
    np.testing.assert_allclose(s, arr.sensor_positions_m())
    np.testing.assert_allclose(s[0, :, 2], SMALL.sensors.offset_m)  # above the tops (z = 0)
    direct = arr.actuation_matrix(s.reshape(-1, 3))[:, :3, :].reshape(2, 9, 3, 9)
    np.testing.assert_allclose(fm.sensor_coil_field(), direct, rtol=1e-12, atol=0)
    i = np.linspace(-3, 3, 9)
    np.testing.assert_allclose(fm.sensor_coil_field(i), direct @ i, rtol=1e-12,
                               atol=1e-15)
    np.testing.assert_array_equal(fm.saturation_factor(i), np.ones(9))


def test_outside_points(fm):
    lo, hi = fm.bounds
    out = hi + [0, 0, 0.002]
    for pts in (out, np.array([lo, out]), out[None]):
        with pytest.raises(BadInputError, match="inside the map box"):
            fm.actuation(pts)
    assert np.all(np.isfinite(fm.actuation(out, outside="extrapolate")))
    with pytest.raises(BadInputError, match="finite"):
        fm.actuation([np.nan, 0, 0.02])
    with pytest.raises(BadInputError, match="outside"):
        fm.actuation(out, outside="clip")


def _resave(path, arrays, meta):
    np.savez(path, **arrays, meta=np.array(json.dumps(meta)))


def test_bad_files(mapfile, tmp_path):
    from firmware_io.mapfile import read

    trunc = tmp_path / "trunc.npz"
    trunc.write_bytes(mapfile.read_bytes()[: mapfile.stat().st_size // 2])
    with pytest.raises(BadInputError, match="truncated"):
        fieldmap.load(trunc)
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, x=np.zeros(3))
    with pytest.raises(BadInputError, match="foreign"):
        fieldmap.load(foreign)
    text = tmp_path / "text.npz"
    text.write_text("hello, I am a text file\n")
    with pytest.raises(BadInputError, match="not a map file") as info:
        fieldmap.load(text)
    assert "pickle" not in str(info.value)
    with pytest.raises(BadInputError, match="built from design"):
        fieldmap.load(mapfile, default_design())
    with pytest.raises(BadInputError, match="existing"):
        fieldmap.load(tmp_path / "missing.npz")
    arrays, meta = read(mapfile)
    bad = tmp_path / "bad.npz"
    for name in ("RZ0", "MRZ0", "F0_RES", "SENSOR_COIL"):
        a2 = arrays[name].copy()
        a2.reshape(-1)[0] = np.nan
        _resave(bad, {**arrays, name: a2}, meta)
        with pytest.raises(BadInputError, match="finite"):
            fieldmap.load(bad)
        a2.reshape(-1)[0] = 0.5
        _resave(bad, {**arrays, name: a2}, meta)
        with pytest.raises(BadInputError, match="SHA-256"):
            fieldmap.load(bad)
    _resave(bad, {k: v for k, v in arrays.items() if k != "COEF"}, meta)
    with pytest.raises(BadInputError, match="COEF"):
        fieldmap.load(bad)
    _resave(bad, {**arrays, "RZ0": arrays["RZ0"][:-1]}, meta)
    with pytest.raises(BadInputError, match="RZ0"):
        fieldmap.load(bad)
    _resave(bad, arrays, dict(meta, units={**meta["units"], "grid": "mm"}))
    with pytest.raises(BadInputError, match="units"):
        fieldmap.load(bad)


def test_map_written_before_v2_is_refused_with_the_rebuild_command(mapfile, tmp_path):
    # a v1-era file: the 3-D grid A/dG and meta version 2
    old = tmp_path / "old.npz"
    meta = {"format": "designkit-fieldmap", "version": 2, "units": {}, "rows": []}
    np.savez(old, A=np.zeros((2, 2, 2, 8, 9), np.float32), dG=np.zeros((2, 2, 2, 7, 9)),
             meta=np.array(json.dumps(meta)))
    with pytest.raises(BadInputError, match="before v2") as info:
        fieldmap.load(old)
    assert "designkit map --design" in str(info.value)


def test_write_is_atomic_and_refuses_folders(mapfile, tmp_path):
    data = {"arrays": {}, "meta": {}}  # would fail while writing: nothing may be left behind
    with pytest.raises(Exception):
        fieldmap.write(tmp_path / "x.npz", data)
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(BadInputError, match="existing folder"):
        fieldmap.write(tmp_path, data)
    with pytest.raises(BadInputError, match=".npz"):
        fieldmap.write(tmp_path / "x.txt", data)


def test_firmware_reader_numpy_only(mapfile, fm, sample):
    p, _ = sample
    code = (
        "import sys, numpy as np\n"
        "from firmware_io.mapfile import MapFile\n"
        f"m = MapFile.load({str(mapfile)!r})\n"
        f"q = np.array({p[:100].tolist()!r})\n"
        "np.save(sys.argv[1], m.actuation(q))\n"
        "np.save(sys.argv[1][:-4] + '_one.npy', m.actuation(q[7]))\n"
        "np.save(sys.argv[1][:-4] + '_f0.npy', m.bias_force(q))\n"
        "bad = sorted(k for k in sys.modules if k.split('.')[0] not in "
        "('numpy', 'firmware_io') and k.split('.')[0] in ('designkit', 'scipy', 'tqdm', "
        "'matplotlib', 'h5py', 'pyvista'))\n"
        "assert not bad, bad\n"
    )
    out = mapfile.parent / "fw.npy"
    root = Path(__file__).resolve().parents[1]
    subprocess.run([sys.executable, "-c", code, str(out)], check=True, cwd=root,
                   env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"})
    np.testing.assert_allclose(np.load(out), fm.actuation(p[:100]), rtol=1e-12, atol=0)
    np.testing.assert_allclose(np.load(out.with_name("fw_one.npy")), fm.actuation(p[7]),
                               rtol=1e-12, atol=0)
    np.testing.assert_array_equal(np.load(out.with_name("fw_f0.npy")), fm.bias_force(p[:100]))


def test_one_format_definition():
    # designkit builds, firmware_io defines: no private firmware_io name used in designkit
    import re

    src = (Path(__file__).resolve().parents[1] / "designkit" / "fieldmap.py").read_text()
    assert not re.search(r"\bmf\._\w+", src)
    assert "from firmware_io.mapfile import _" not in src
    assert "savez" not in src and "FORMAT_VERSION =" not in src


def test_cli_map_writes_one_file(tmp_path):
    toml = tmp_path / "d.toml"
    toml.write_text(design_to_toml(SMALL.replace(**{"workspace.half_width_m": 0.01,
                                                    "workspace.z_max_m": 0.02})))
    out = tmp_path / "m.npz"
    assert main(["map", "--design", str(toml), "--spacing", "10", "--out", str(out),
                 "--quiet"]) == 0
    assert sorted(f.name for f in tmp_path.iterdir()) == ["d.toml", "m.npz"]
    loaded = fieldmap.load(out)
    assert loaded.meta["settings"]["spacing_m"] == pytest.approx(0.01)
    assert main(["map", "--spacing", "-1", "--out", str(out), "--quiet"]) == 1


def test_cli_map_refuses_bad_outputs_before_computing(tmp_path, monkeypatch, capsys):
    def boom(*a, **k):
        raise AssertionError("computed before checking the output")

    monkeypatch.setattr(fieldmap, "build", boom)
    assert main(["map", "--out", str(tmp_path), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "existing folder" in err and "Traceback" not in err
    assert main(["map", "--out", str(tmp_path / "m.txt"), "--quiet"]) == 1


# ---------------------------------------------------------------------------- coupled iron cores
TWO = default_design().replace(**{"array.rows": 1, "array.columns": 2,
                                   "workspace.half_width_m": 0.03, "workspace.z_max_m": 0.04})


@pytest.fixture(scope="module")
def coupled(tmp_path_factory):
    path = tmp_path_factory.mktemp("map") / "two.npz"
    data = fieldmap.build(TWO, spacing=0.01, n_check=10, progress=False)
    fieldmap.write(path, data)
    return fieldmap.load(path, TWO), CoilArray.from_design(TWO)


@pytest.mark.slow
def test_coupled_map_against_direct_coupled_model(coupled):
    fm, arr = coupled
    rng = np.random.default_rng(4)
    lo, hi = fm.bounds
    p = rng.uniform(lo, hi, (300, 3))
    a = arr.actuation_matrix(p)
    err = np.abs(fm.actuation(p) - a).max(axis=(0, 2)) / np.abs(a).max(axis=(0, 2))
    # measured 2026-11: what the default settings reach on the coupled model (see the
    # report; the 1e-3 target needs mode tables of the coupled solution, not yet built)
    assert np.all(err < 0.05), err
    m = fm.moment_a_m2
    f = arr.bias_force(p[:20], m)
    assert np.abs(fm.bias_force(p[:20]) - f).max() < 0.1 * np.abs(f).max()
    s = fm.sensor_positions_m
    np.testing.assert_allclose(s, arr.sensor_positions_m())
    direct = arr.actuation_matrix(s.reshape(-1, 3))[:, :3, :].reshape(2, 2, 3, 2)
    np.testing.assert_allclose(fm.sensor_coil_field(), direct, rtol=1e-12)
    q = p[0]
    b = arr.magnet_core_field(s.reshape(-1, 3), q, m).reshape(2, 2, 3)
    assert np.abs(fm.sensor_induced_field(q) - b).max() < 0.6 * np.abs(b).max()
    sat = arr.saturation_correction(currents_a=np.linspace(0, 6, 7))
    np.testing.assert_allclose(fm.saturation_factor([6.0, -3.0]),
                               [sat["saturation_factor"][-1, 0], sat["saturation_factor"][3, 1]])
