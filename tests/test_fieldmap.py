"""Map file v2: interpolation against direct evaluation, physics of the interpolated field,
bias force and sensor fields against CoilArray, bad files, CLI, and the numpy-only reader.

The fast tests use air coils (no iron: the coupled model is exact superposition and cheap);
the coupled iron-core array is in the slow tests (its array-level solve takes seconds)."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from designkit import default_design, fieldmap
from designkit.model.array import CoilArray
from designkit.cli import main
from designkit.design import design_to_toml
from designkit.errors import BadInputError

SMALL = default_design().replace(**{"core": None, "workspace.shape": "box",
                                     "workspace.half_width_m": 0.03,
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
    np.testing.assert_allclose(fm.moment_a_m2, SMALL.magnet.moment_vector_a_m2)
    assert fm.meta["version"] == 6 and fm.n_coils == 9 and fm.meta["n_sensors"] == 18


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


def test_row_and_coil_subsets(fm, sample):
    # the subsets are the same entries of the direct model's A (independent of the full path)
    p, a = sample
    rng = np.random.default_rng(12)
    for _ in range(5):
        r = rng.choice(8, rng.integers(1, 9), replace=False)
        c = rng.choice(9, rng.integers(1, 10), replace=False)
        got = fm.actuation(p[:300], rows=r, coils=c)
        want = a[:300][:, r][:, :, c]
        assert got.shape == (300, len(r), len(c))
        scale = np.abs(a).max(axis=(0, 2))[r][None, :, None]
        assert np.all(np.abs(got - want) < 1e-3 * scale)
        one = fm.actuation(p[7], rows=list(r), coils=tuple(c))
        assert one.shape == (len(r), len(c))
        np.testing.assert_allclose(one, fm.actuation(p[7])[r][:, c], rtol=1e-12, atol=0)
        assert fm.actuation(p[7:8], rows=r, coils=c).shape == (1, len(r), len(c))
    for bad in ([], [8], [-1], [0.5], "x"):
        with pytest.raises(BadInputError, match="rows"):
            fm.actuation(p[0], rows=bad)
    with pytest.raises(BadInputError, match="coils"):
        fm.actuation(p[:3], coils=[9])


def _general_path(fm):
    """The same map with the one-point kernels of the bias force and the sensor field switched
    off: the per-type tables (mode_rows, magnet_terms) that rotated or mixed coils use."""
    from firmware_io.mapfile import MapFile

    f = fm.file
    return MapFile(f.arrays, f.meta, f.bounds, f.n_coils,
                   dict(f.kernels, sensor_one=None, magnet_one=None))


def test_harmonic_cell_rows_of_a_known_potential():
    # psi = x^3 - 3 x y^2 + z (x^2 + y^2) - 2 z^3 / 3 is harmonic; its free coefficients
    # (x^3: 1, x y^2: -3, x^2 z: 1, y^2 z: 1) must give its 8 rows in closed form
    from firmware_io.mapfile import harmonic_rows, harmonic_terms, monomials

    coef = np.zeros(len(harmonic_terms(3)))
    for term, c in (((3, 0, 0), 1.0), ((1, 2, 0), -3.0), ((2, 0, 1), 1.0), ((0, 2, 1), 1.0)):
        coef[harmonic_terms(3).index(term)] = c
    s = np.random.default_rng(3).uniform(-1, 1, (50, 3))
    x, y, z = s.T
    want = np.stack([3 * x**2 - 3 * y**2 + 2 * x * z, -6 * x * y + 2 * y * z,
                     x**2 + y**2 - 2 * z**2, 6 * x + 2 * z, -6 * y, 2 * x,
                     -6 * x + 2 * z, 2 * y], 1)
    got = np.einsum("mn,rmk,k->nr", monomials(s, 2), harmonic_rows(3), coef)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)


def test_harmonic_cell_basis_against_finite_differences():
    # every free coefficient's potential is harmonic, and the 8 rows the reader evaluates are
    # its first and second derivatives (central differences of the potential itself)
    from firmware_io.mapfile import (harmonic_potential, harmonic_rows, harmonic_terms,
                                     monomial_exponents, monomials)

    rng = np.random.default_rng(5)
    s = rng.uniform(-1, 1, (6, 3))
    for deg in (2, 4, 8):
        e = monomial_exponents(deg)
        assert len(e) == math.comb(deg + 3, 3) and len(harmonic_terms(deg)) == (deg + 1) ** 2 - 1
        np.testing.assert_allclose(monomials(s, deg), np.prod(s[None] ** e[:, None], axis=2),
                                   rtol=1e-14, atol=1e-15)
        pot = harmonic_potential(deg)

        def phi(q):
            return np.prod(q[None] ** e[:, None], axis=2).T @ pot.T  # (n, K)

        h = 1e-3
        u = np.eye(3) * h
        d1 = [(phi(s + u[a]) - phi(s - u[a])) / (2 * h) for a in range(3)]
        d2 = {(a, b): (phi(s + u[a] + u[b]) - phi(s + u[a] - u[b]) - phi(s - u[a] + u[b])
                       + phi(s - u[a] - u[b])) / (4 * h * h) for a in range(3) for b in range(3)}
        lap = sum(d2[(a, a)] for a in range(3))
        scale = max(np.abs(d2[(a, a)]).max() for a in range(3))
        assert np.abs(lap).max() <= 1e-4 * scale  # h^2 truncation: ~3e-5 at degree 8
        want = np.stack(d1 + [d2[(0, 0)], d2[(0, 1)], d2[(0, 2)], d2[(1, 1)], d2[(1, 2)]], 1)
        got = np.einsum("mn,rmk->nrk", monomials(s, deg - 1), harmonic_rows(deg))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-4 * np.abs(want).max())


def test_solid_harmonics_are_legendre_solid_harmonics():
    # the batch lookup's basis: G_l^m = c_lm r^l P_l^m(cos theta) (cos, sin)(m phi), one
    # constant c_lm per (l, m) (scipy's associated Legendre functions, an independent source),
    # and the monomial coefficients the one-point path uses give the same values
    from scipy.special import lpmv

    from firmware_io.mapfile import monomials, solid_harmonic_coefficients, solid_harmonics

    deg = 8
    s = np.random.default_rng(7).uniform(-1, 1, (40, 3))
    got = solid_harmonics(s.T.copy(), deg)
    assert got.shape == ((deg + 1) ** 2, len(s))
    np.testing.assert_allclose(monomials(s, deg).T @ solid_harmonic_coefficients(deg), got.T,
                               rtol=0, atol=1e-12)
    r = np.linalg.norm(s, axis=1)
    phi = np.arctan2(s[:, 1], s[:, 0])
    for ell in range(deg + 1):
        for m in range(ell + 1):
            base = r ** ell * lpmv(m, ell, s[:, 2] / r)
            for row, trig in ((ell * ell + max(2 * m - 1, 0), np.cos),
                              (ell * ell + 2 * m, np.sin)):
                if m == 0 and trig is np.sin:
                    continue
                want = base * trig(m * phi)
                c = got[row] @ want / (want @ want)  # the per-(l, m) constant
                assert abs(c) > 0
                np.testing.assert_allclose(got[row], c * want, rtol=0,
                                           atol=1e-11 * np.abs(c * want).max())


def test_cell_layers_per_layer_ratios():
    # floor 20 mm above sources at 5 mm: d = 15 mm -> a 0.7 d = 10.5 mm first layer of 1.0 d
    # = 15 mm cells; then d = 25.5 mm -> 0.5 d = 12.75 mm with 0.5 d = 12.75 mm cells; one
    # number for layer_ratio serves every layer
    lay = fieldmap.cell_layers([-0.06, -0.06, 0.02], [0.06, 0.06, 0.08], 0.005, (1.0, 0.5),
                               (0.7, 0.5), (12, 7))
    assert [x["degree"] for x in lay[:2]] == [12, 7]
    assert lay[0]["z_hi_m"] == pytest.approx(0.0305) and lay[1]["z_hi_m"] == pytest.approx(0.04325)
    assert (lay[0]["nx"], lay[1]["nx"]) == (math.ceil(0.12 / 0.015), math.ceil(0.12 / 0.01275))
    assert lay[-1]["z_hi_m"] == pytest.approx(0.08)
    one = fieldmap.cell_layers([-0.06, -0.06, 0.02], [0.06, 0.06, 0.08], 0.005, (1.0,), 0.5,
                               (7,))
    assert one[0]["z_hi_m"] == pytest.approx(0.0275)
    for bad in ((), (0.7, "x"), ((0.5, 0.5),), 0.0):
        with pytest.raises(BadInputError):
            fieldmap.build(SMALL, layer_ratio=bad, progress=False)


def test_map_carries_the_drive_data_the_runner_reads(fm):
    from firmware_io.runner import config_from_map

    cfg = config_from_map(fm.file)
    d = SMALL
    # closed forms from the design's numbers: R = rho l / (pi d^2 / 4), l = N 2 pi r_mean
    # (20 C = the reference temperature), Wheeler's multilayer formula for the air-core L
    r_mean = (d.coil.inner_radius_m + d.coil.outer_radius_m) / 2
    r = d.wire.resistivity_ohm_m * d.coil.turns * 2 * math.pi * r_mean / (
        math.pi * d.wire.diameter_m ** 2 / 4)
    drive = cfg.drive
    np.testing.assert_allclose(drive.resistance_ohm, [r] * 9, rtol=1e-9)
    np.testing.assert_allclose(drive.resistance_ref_ohm, [r] * 9, rtol=1e-9)
    # the resistance model: copper's alpha, R at the hot limit (100 C) 1.31 x R(20 C)
    np.testing.assert_allclose(drive.resistance_at(100.0), [r * (1 + 0.00393 * 80)] * 9,
                               rtol=1e-9)
    depth = d.coil.outer_radius_m - d.coil.inner_radius_m
    wheeler = 31.6e-6 * d.coil.turns ** 2 * r_mean ** 2 / (6 * r_mean + 9 * d.coil.length_m
                                                           + 10 * depth)
    np.testing.assert_allclose(drive.inductance_h, [wheeler] * 9, rtol=0.03)
    np.testing.assert_allclose(drive.time_constant_s, np.array(drive.inductance_h) / r,
                               rtol=1e-9)
    # the coils get the design's supply (36 V), not the driver's 30 V rating; the rating is a
    # rule the record reports (the hardware runner refuses it)
    assert drive.supply_voltage_v == d.drive.supply_voltage_v == 36.0
    assert drive.current_limit_a == pytest.approx(min(d.drive.max_current_a, 36.0 / r))
    assert drive.driver.max_voltage_v == d.drive.driver_max_voltage_v == 30.0
    assert drive.driver.name == d.drive.driver and drive.pwm_frequency_hz == 1526.0
    [bad] = drive.violations()
    assert "drive.supply_voltage_v = 36 V" in bad and "drive.driver_max_voltage_v" in bad
    assert drive.total_current_a == d.drive.total_current_a
    assert 0 < drive.thermal_continuous_current_a < drive.current_limit_a
    assert drive.thermal_time_constant_s > 0


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
    assert fm.sensor_induced_field(p[0]).shape == (18, 3)


def test_sensor_positions_and_coil_field_against_direct(fm):
    arr = CoilArray.from_design(SMALL)
    s = fm.sensor_positions_m
    # the flat list: the upper array in coil order, then the lower array
    assert fm.n_sensors == 18 and s.shape == (18, 3)
    np.testing.assert_allclose(s, arr.sensor_positions_m().reshape(-1, 3))
    np.testing.assert_allclose(s[:9, :2], arr.positions()[:, :2], atol=1e-15)
    np.testing.assert_allclose(s[:9, 2], SMALL.sensors.offset_m)  # above the tops (z = 0)
    assert np.all(s[9:, 2] < -SMALL.coil.length_m)                # below the bottoms
    np.testing.assert_array_equal(fm.sensor_rotations, np.broadcast_to(np.eye(3), (18, 3, 3)))
    direct = arr.actuation_matrix(s)[:, :3, :]
    np.testing.assert_allclose(fm.sensor_coil_field(), direct, rtol=1e-12, atol=0)
    i = np.linspace(-3, 3, 9)
    np.testing.assert_allclose(fm.sensor_coil_field(i), direct @ i, rtol=1e-12,
                               atol=1e-15)
    np.testing.assert_array_equal(fm.saturation_factor(i), np.ones(9))
    # the gradient at the sensors (below the box of A) against central differences of the
    # direct model's field (h = 1 um): [s, i, j, k] = dB_i/dx_j of coil k
    h, pts = 1e-6, s
    fd = np.stack([(arr.actuation_matrix(pts + h * e)[:, :3] - arr.actuation_matrix(pts - h * e)
                    [:, :3]) / (2 * h) for e in np.eye(3)], axis=2)
    g = fm.sensor_coil_gradient()
    assert g.shape == (18, 3, 3, 9)
    np.testing.assert_allclose(g, fd, rtol=0, atol=1e-6 * np.abs(fd).max())
    np.testing.assert_allclose(g, np.swapaxes(g, 1, 2), atol=1e-12 * np.abs(g).max())


def test_the_format_holds_any_number_of_sensors(mapfile, tmp_path):
    # the sensors are a flat list independent of the coil count: the map's first 5 sensors
    # (and a tilted orientation) make a valid map whose reader gives those 5, unchanged
    from firmware_io.mapfile import MapFile, data_hash, read
    from firmware_io.localization import SensorModel

    arrays, meta = read(mapfile)
    keep = slice(0, 5)
    c, s_ = math.cos(0.3), math.sin(0.3)
    rot = arrays["SENSOR_ROT"][keep].copy()
    rot[2] = [[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]]
    sub = dict(arrays, SENSOR_POS=arrays["SENSOR_POS"][keep], SENSOR_ROT=rot,
               SENSOR_COIL=arrays["SENSOR_COIL"][keep],
               SENSOR_COIL_GRAD=arrays["SENSOR_COIL_GRAD"][keep],
               SCOEF=np.ascontiguousarray(arrays["SCOEF"][:, :, keep]))
    path = tmp_path / "five.npz"
    _resave(path, sub, dict(meta, n_sensors=5, data_sha256=data_hash(sub)))
    m = MapFile.load(path)
    full = MapFile.load(mapfile)
    assert m.n_sensors == 5 and m.n_coils == 9
    np.testing.assert_array_equal(m.sensor_positions_m, full.sensor_positions_m[keep])
    np.testing.assert_array_equal(m.sensor_coil_field(), full.sensor_coil_field()[keep])
    np.testing.assert_array_equal(m.sensor_rotations[2], rot[2])
    assert m.sensor_induced_field(np.mean(m.bounds, axis=0)).shape == (5, 3)
    # the pose estimators take the flat list as it is: its 5 sensors and their rotations
    model = SensorModel.from_map(path)
    assert model.n_sensors == 5 and model.n_coils == 9
    np.testing.assert_array_equal(model.sensor_positions_m, full.sensor_positions_m[keep])
    np.testing.assert_array_equal(model.sensor_orientations[2], rot[2])
    assert model.induced_field(np.mean(m.bounds, axis=0)).shape == (5, 3)


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


def test_map_check_command_summarizes_a_good_map_and_refuses_a_bad_one(mapfile, tmp_path,
                                                                       capsys):
    # python -m firmware_io.mapfile: a labelled summary (exit 0); a truncated or foreign file
    # one error line (exit 1), no traceback
    from firmware_io.mapfile.__main__ import main as check_map

    assert check_map([str(mapfile)]) == 0
    out = capsys.readouterr().out
    assert SMALL.name in out and "coils / sensors" in out
    assert "9 / 18" in out and "supply / driver" in out and "36 V / Cytron MD10C" in out
    assert "drive.supply_voltage_v = 36 V is above" in out and "format version" in out
    trunc = tmp_path / "corrupt.npz"
    trunc.write_bytes(mapfile.read_bytes()[:3000])
    for bad in (trunc, tmp_path / "missing.npz"):
        assert check_map([str(bad)]) == 1
        err = capsys.readouterr().err
        assert err.startswith("error: ") and err.count("\n") == 1 and "Traceback" not in err
    res = subprocess.run([sys.executable, "-m", "firmware_io.mapfile", str(trunc)],
                         capture_output=True, text=True)
    assert res.returncode == 1 and res.stdout == "" and "Traceback" not in res.stderr
    assert "truncated" in res.stderr


def test_bad_files(mapfile, tmp_path):
    from firmware_io.mapfile import data_hash, read

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
    for name in ("AH0", "MRZ0", "F0_RES", "SENSOR_COIL"):
        a2 = arrays[name].copy()
        a2.reshape(-1)[0] = np.nan
        _resave(bad, {**arrays, name: a2}, meta)
        with pytest.raises(BadInputError, match="finite"):
            fieldmap.load(bad)
        a2.reshape(-1)[0] = 0.5
        _resave(bad, {**arrays, name: a2}, meta)
        with pytest.raises(BadInputError, match="SHA-256"):
            fieldmap.load(bad)
    _resave(bad, {k: v for k, v in arrays.items() if k != "SCOEF"}, meta)
    with pytest.raises(BadInputError, match="SCOEF"):
        fieldmap.load(bad)
    # a sensor orientation that is not a rotation (a mirror), a drive record that lost a field
    rot = arrays["SENSOR_ROT"].copy()
    rot[3] = np.diag([1.0, 1.0, -1.0])
    write = dict(arrays, SENSOR_ROT=rot)
    _resave(bad, write, dict(meta, data_sha256=data_hash(write)))
    with pytest.raises(BadInputError, match="SENSOR_ROT"):
        fieldmap.load(bad)
    drive = {k: v for k, v in meta["drive"].items() if k != "hot_temperature_c"}
    _resave(bad, arrays, dict(meta, drive=drive))
    with pytest.raises(BadInputError, match="hot_temperature_c"):
        fieldmap.load(bad)
    _resave(bad, {**arrays, "AH0": arrays["AH0"][:-1]}, meta)
    with pytest.raises(BadInputError, match="a_layers"):
        fieldmap.load(bad)
    gap = [dict(lay) for lay in meta["a_layers"]]
    gap[-1]["z_lo_m"] += 1e-4
    _resave(bad, arrays, dict(meta, a_layers=gap))
    with pytest.raises(BadInputError, match="a_layers"):
        fieldmap.load(bad)
    _resave(bad, arrays, dict(meta, units={**meta["units"], "grid": "mm"}))
    with pytest.raises(BadInputError, match="units"):
        fieldmap.load(bad)


def test_older_maps_are_refused_with_the_rebuild_command(mapfile, tmp_path):
    # a v1-era file (the 3-D grid A/dG, version 2) and a version-3 file (A as (rho, z) tables)
    from firmware_io.mapfile import read

    old = tmp_path / "old.npz"
    meta = {"format": "designkit-fieldmap", "version": 2, "units": {}, "rows": []}
    np.savez(old, A=np.zeros((2, 2, 2, 8, 9), np.float32), dG=np.zeros((2, 2, 2, 7, 9)),
             meta=np.array(json.dumps(meta)))
    arrays, meta3 = read(mapfile)
    v3 = tmp_path / "v3.npz"
    _resave(v3, {**arrays, "RZ0": np.zeros((3, 3, 4), np.float32)}, dict(meta3, version=3))
    for path, version in ((old, 2), (v3, 3)):
        with pytest.raises(BadInputError, match=f"version {version}, written by an older") as e:
            fieldmap.load(path)
        assert "designkit map --out" in str(e.value)


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
    # A is float32 arithmetic: BLAS may pick other kernels (threads) in another process
    tol = 1e-6 * np.abs(fm.actuation(p[:100])).max()
    np.testing.assert_allclose(np.load(out), fm.actuation(p[:100]), rtol=1e-5, atol=tol)
    np.testing.assert_allclose(np.load(out.with_name("fw_one.npy")), fm.actuation(p[7]),
                               rtol=1e-5, atol=tol)
    np.testing.assert_array_equal(np.load(out.with_name("fw_f0.npy")), fm.bias_force(p[:100]))


def test_one_format_definition():
    # designkit builds, firmware_io defines: no private firmware_io name used in designkit
    import re

    pkg = Path(__file__).resolve().parents[1] / "designkit" / "fieldmap"
    src = "\n".join(f.read_text() for f in sorted(pkg.glob("*.py")))
    assert not re.search(r"\bmf\._\w+", src)
    assert "from firmware_io.mapfile import _" not in src
    assert "savez" not in src and "FORMAT_VERSION =" not in src


def test_map_file_and_field_map_are_actuation_sources(mapfile, fm, sample):
    # both satisfy firmware_io.actuation.ActuationSource, and a selection of rows and coils is
    # the same selection of the full A (one point and a batch)
    from firmware_io.actuation import ActuationSource
    from firmware_io.mapfile import MapFile

    m = MapFile.load(mapfile)
    assert isinstance(m, ActuationSource) and isinstance(fm, ActuationSource)
    p, _ = sample
    rows, coils = (1, 3, 7), (8, 0, 4)
    for src in (m, fm):
        assert src.n_coils == 9 and src.design_sha256 == SMALL.spec_hash()
        assert len(src.bounds) == 2 and np.shape(src.moment_a_m2) == (3,)
        full = src.actuation(p[:50])
        np.testing.assert_allclose(src.actuation(p[:50], rows=rows, coils=coils),
                                   full[:, rows][:, :, coils], rtol=1e-5,
                                   atol=1e-6 * np.abs(full).max())  # float32 products
        np.testing.assert_array_equal(src.actuation(p[3], rows=rows, coils=coils),
                                      src.actuation(p[3])[rows, :][:, coils])
        assert src.bias_force(p[:4]).shape == (4, 3) and src.bias_force(p[0]).shape == (3,)
        # every member of the interface, so callers never probe one
        assert src.n_sensors == 18 and src.sensor_positions_m.shape == (18, 3)
        assert src.sensor_coil_field().shape == (18, 3, 9)
        i = np.linspace(-2.0, 2.0, 9)
        np.testing.assert_allclose(src.sensor_coil_field(i), src.sensor_coil_field() @ i)
    members = [k for k in vars(ActuationSource) if not k.startswith("_")]
    members += list(ActuationSource.__annotations__)
    for src in (m, fm):
        assert all(hasattr(src, k) for k in members), members


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
                                   "workspace.shape": "box", "workspace.half_width_m": 0.03,
                                   "workspace.z_max_m": 0.04})


@pytest.fixture(scope="module")
def coupled(tmp_path_factory):
    path = tmp_path_factory.mktemp("map") / "two.npz"
    data = fieldmap.build(TWO, n_check=10, progress=False)
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
    # target 1e-3; more geometries and 1e4 points in test_fieldmap_accuracy.py
    assert np.all(err < 1e-3), err
    r, c = [2, 3, 6], [1]
    sub = fm.actuation(p, rows=r, coils=c)
    assert np.all(np.abs(sub - a[:, r][:, :, c]) < 1e-3 * np.abs(a).max(axis=(0, 2))[r][:, None])
    np.testing.assert_allclose(fm.actuation(p[5], rows=r, coils=c), sub[5], rtol=1e-5,
                               atol=1e-7 * np.abs(sub).max())
    g = _general_path(fm)
    np.testing.assert_allclose(fm.sensor_induced_field(p[:50]), g.sensor_induced_field(p[:50]),
                               rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(fm.bias_force(p[7]), g.bias_force(p[7]), rtol=1e-9, atol=1e-15)
    m = fm.moment_a_m2
    # the map's F0 is the finite cylinder's (the magnet the design names), not the dipole's
    f = arr.bias_force(p[:20], m, magnet_size_m=(TWO.magnet.radius_m, TWO.magnet.length_m))
    # per-core tables (0.5 mm, 2 %) + a 10 mm grid of the cores' interaction: ~0.5 % of the
    # largest F0 (the former 2 mm, 15 % tables and 25 mm grid: ~8-12 %)
    err = np.abs(fm.bias_force(p[:20]) - f).max() / np.abs(f).max()
    assert err < 0.01, err
    dipole = arr.bias_force(p[:20], m)   # 2-4 % off the cylinder at 20-30 mm: the map is not it
    assert np.abs(fm.bias_force(p[:20]) - dipole).max() / np.abs(f).max() > 0.01
    s = fm.sensor_positions_m
    np.testing.assert_allclose(s, arr.sensor_positions_m().reshape(-1, 3))
    direct = arr.actuation_matrix(s)[:, :3, :]
    np.testing.assert_allclose(fm.sensor_coil_field(), direct, rtol=1e-12)
    b = np.array([arr.magnet_core_field(s, q, m) for q in p[:10]])
    # the adjoint through the modes: measured 5.0e-4 of the largest induced field (reciprocity
    # with unit dipoles at the sensors, the former path: ~2-3 %)
    assert np.abs(fm.sensor_induced_field(p[:10]) - b).max() < 5e-3 * np.abs(b).max()
    np.testing.assert_allclose(fm.sensor_induced_field(p[3]), fm.sensor_induced_field(p[:10])[3])
    sat = arr.saturation_correction(currents_a=np.linspace(0, 6, 7))
    np.testing.assert_allclose(fm.saturation_factor([6.0, -3.0]),
                               [sat["saturation_factor"][-1, 0], sat["saturation_factor"][3, 1]])


# ---------------------------------------------------------------------------- mode formulas
def _closed_form(kind, p, d):
    """B = -grad(phi) and its gradient (central differences of the closed-form B) for the
    harmonic potentials phi of the mode kinds, source at (0, 0, -d)."""
    def b(q):
        x, y, z = q[..., 0], q[..., 1], q[..., 2] + d
        r2 = x * x + y * y + z * z
        if kind == (1, 0):  # phi = x r^-3 (transverse dipole)
            g = r2 ** -1.5
            return -np.stack([g - 3 * x * x * r2 ** -2.5, -3 * x * y * r2 ** -2.5,
                              -3 * x * z * r2 ** -2.5], -1)
        if kind == (1, 1):  # phi = y r^-3
            return -np.stack([-3 * x * y * r2 ** -2.5, r2 ** -1.5 - 3 * y * y * r2 ** -2.5,
                              -3 * y * z * r2 ** -2.5], -1)
        h, dh = r2 ** -2.5, -5 * r2 ** -3.5  # H = r^-5, dH/dx_i = -5 x_i r^-7
        if kind == (2, 0):  # phi = (x^2 - y^2) r^-5
            pp = x * x - y * y
            return -np.stack([2 * x * h + pp * dh * x, -2 * y * h + pp * dh * y, pp * dh * z], -1)
        qq = 2 * x * y  # phi = 2 x y r^-5
        return -np.stack([2 * y * h + qq * dh * x, 2 * x * h + qq * dh * y, qq * dh * z], -1)

    e = 1e-7
    g = np.stack([(b(p + e * u) - b(p - e * u)) / (2 * e) for u in np.eye(3)], -1)
    return b(p), g


def test_mode_rows_reproduce_harmonic_fields():
    # the table quantities of x G, y G (G = r^-3) and (x^2 - y^2) H, 2 x y H (H = r^-5) as
    # functions of (rho^2, z): (a, a1, a2, az, a1z) = -(G, G', G'', G_z, G'_z); at table nodes
    # the kernel's rows must equal the closed-form fields at any azimuth
    from firmware_io.mapfile import N_MODE_Q, mode_rows, prepare_modes

    d = 0.02
    spec = {"rho_step_m": 1e-3, "rho_scale_m": 0.05, "z_ref_m": 0.0, "u0": math.log(0.005),
            "u_step": 0.1}
    n_rho, n_u = 30, 20
    vn = spec["rho_step_m"] * np.arange(n_rho)
    rho = vn / (1 - vn / spec["rho_scale_m"])
    z = np.exp(spec["u0"] + spec["u_step"] * np.arange(n_u))
    R2, Z = np.meshgrid(rho ** 2, z + d, indexing="ij")
    s2 = R2 + Z * Z
    g = [s2 ** -1.5, -1.5 * s2 ** -2.5, 3.75 * s2 ** -3.5, -3 * Z * s2 ** -2.5,
         7.5 * Z * s2 ** -3.5]
    h = [s2 ** -2.5, -2.5 * s2 ** -3.5, 8.75 * s2 ** -4.5, -5 * Z * s2 ** -3.5,
         17.5 * Z * s2 ** -4.5]
    tab = np.stack([-q for q in g] + [-q for q in h], -1)
    scale = np.abs(tab).max(axis=(0, 1))
    tab = (tab / scale).astype(np.float16)  # as stored in a map file
    meta = {**spec, "coils": [0], "shape": list(tab.shape), "shapes": [[1, 0], [2, 0]],
            "column_scale": scale.tolist(),
            "columns": [0, 5], "basis": [[1, 0, 0], [1, 0, 1], [2, 0, 0], [2, 0, 1]]}
    t = prepare_modes([tab], [meta], [[0.0, 0.0, 0.0]], [np.eye(3).tolist()])[0]
    rng = np.random.default_rng(3)
    i, j = rng.integers(1, n_rho - 1, 40), rng.integers(0, n_u - 1, 40)
    phi = rng.uniform(0, 2 * np.pi, 40)
    p = np.c_[rho[i] * np.cos(phi), rho[i] * np.sin(phi), z[j]]
    rows = mode_rows(t, p)[:, 0]  # (n, nb in t['order'], 8)
    order = [tuple(meta["basis"][k]) for k in t["order"]]
    assert N_MODE_Q[1] == N_MODE_Q[2] == 5
    for b_idx, (m, _, c) in enumerate(order):
        bb, gg = _closed_form((m, c), p, d)
        want = np.concatenate([bb, gg[:, 0, :], gg[:, 1, 1:]], axis=1)
        scale = np.abs(want).max()
        np.testing.assert_allclose(rows[:, b_idx], want, rtol=0, atol=3e-3 * scale,
                                   err_msg=f"mode {m}, {'sin' if c else 'cos'}")
