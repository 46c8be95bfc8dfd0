"""GetDP FEM pipeline: air core against designkit's quadrature, linear and nonlinear cores
against the surface-current model, CLI. Skipped only when the getdp program is absent."""

import shutil

import numpy as np
import pytest

from conftest import shared_fem_solves
from designkit.model.coil import Coil
from designkit.cores.panel import Core
from designkit.fem.compare import air_inductance, model_field

pytestmark = pytest.mark.skipif(shutil.which("getdp") is None,
                                reason="GetDP not installed (apt-get install getdp)")

THESIS = dict(inner_radius=0.012, outer_radius=0.019, length=0.100, turns=1429)


@pytest.fixture(autouse=True)
def _shared_fem_solves(monkeypatch, fem_solve_memo):
    """Identical FEM models solved once per run (conftest.fem_solve_memo)."""
    shared_fem_solves(monkeypatch, fem_solve_memo)


@pytest.fixture(scope="module")
def air_result(fem_solve_memo):
    return fem_solve_memo(Coil(**THESIS), 1.0, level=0)


def test_air_core_fem_matches_quadrature(air_result):
    coil = Coil(**THESIS)
    z = np.array([coil.length / 2 + 0.030])
    fit = air_result.axis.fit(z)
    bz, dbz = model_field(coil, 1.0, 0.0, z, None)
    assert abs(fit["bz"][0] / bz[0] - 1) < 2e-4
    assert abs(fit["dbz_dz"][0] / dbz[0] - 1) < 2e-4
    l_ref = air_inductance(coil)
    assert air_result.inductance_energy == pytest.approx(l_ref, rel=1e-4)
    assert air_result.inductance_linkage == pytest.approx(l_ref, rel=1e-4)


def test_linear_core_surface_current_model_within_1_percent_of_fem():
    from designkit.fem import solve

    # smaller case: a 16 mm x 60 mm core in a 60 mm winding, mu_r 500, 2 A
    core = Core(0.008, 0.060, 500.0)
    coil = Coil(0.009, 0.015, 0.060, 600, core)
    res = solve(coil, 2.0, level=0, line_z=(0.008, 0.06))
    z = coil.length / 2 + np.array([0.012, 0.03, 0.05])
    for line in (res.axis, res.off_axis):
        fit = line.fit(z)
        bz, dbz = model_field(coil, 2.0, line.r, z, "surface-current")
        np.testing.assert_allclose(bz, fit["bz"], rtol=0.01)
        np.testing.assert_allclose(dbz, fit["dbz_dz"], rtol=0.01)
        # the thesis' uniform model is visibly worse near the core (>5 % in dBz/dz on axis)
    bz_u, dbz_u = model_field(coil, 2.0, 0.0, z[:1], "thesis-uniform")
    assert abs(dbz_u[0] / res.axis.fit(z[:1])["dbz_dz"][0] - 1) > 0.05
    l_model = air_inductance(coil) + core.extra_inductance(coil)
    assert l_model == pytest.approx(res.inductance_energy, rel=0.01)


@pytest.mark.slow
def test_nonlinear_core_at_6A_matches_fem():
    from designkit.fem import solve

    core = Core(0.012, 0.110, bh="steel1010")
    coil = Coil(**THESIS, core=core)
    res = solve(coil, 6.0, level=0)
    z = np.array([coil.length / 2 + 0.030])
    fit = res.axis.fit(z)
    _, dbz = model_field(coil, 6.0, 0.0, z, "surface-current")
    assert dbz[0] == pytest.approx(fit["dbz_dz"][0], rel=0.03)
    l_model = air_inductance(coil) + core.extra_inductance(coil, 6.0)
    assert l_model == pytest.approx(res.inductance_linkage, rel=0.02)


def test_missing_getdp_message(monkeypatch):
    from designkit.errors import MissingDependencyError
    from designkit.fem import find_getdp

    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(MissingDependencyError, match="apt-get install getdp"):
        find_getdp()


def test_cli_fem_writes_everything(tmp_path, capsys):
    from designkit.cli import main

    out = tmp_path / "fem"
    assert main(["fem", "--level", "0", "--mu-r", "1000", "--current", "6", "--out",
                 str(out)]) == 0
    for name in ("model.msh", "model.vtu", "model.pro", "fem_results.json",
                 "fem_vs_designkit.png"):
        assert (out / name).stat().st_size > 0
    import json

    data = json.loads((out / "fem_results.json").read_text())
    # the thesis coil with a mu_r 1000 core: designkit's inductance within 1 % of FEM
    assert data["model_inductance_h"] == pytest.approx(data["inductance_linkage_h"], rel=0.01)
    err = np.abs(data["comparison"]["axis"]["surface-current_dbz_dz_rel_err"])
    assert err.max() < 0.01


# ------------------------------------------------------------ all around the coil (issue 11)
CORE_GEOMETRIES = {
    "thesis": dict(radius=0.012, length=0.110),
    "short-thin": dict(radius=0.008, length=0.070),
    "offset": dict(radius=0.010, length=0.090, offset=0.015),
}


def _around(geometry, material, level):
    from designkit.fem import solve
    from designkit.fem.compare import probe_errors, probe_set

    kw = CORE_GEOMETRIES[geometry]
    core = Core(**kw, bh="steel1010") if material == "steel1010" else \
        Core(**kw, relative_permeability=float(material))
    coil = Coil(**THESIS, core=core)
    pts, labels = probe_set(coil)
    res = solve(coil, 6.0, level=level, probes=pts)
    return probe_errors(coil, res), labels


@pytest.mark.parametrize("geometry", ["thesis", "short-thin"])
def test_core_model_within_3_percent_of_fem_all_around_the_coil(geometry):
    """Issue 11: beside, below, above, in the bore beyond the core's ends and at the neighbours'
    positions (50 mm pitch), B and dBz/dz of winding + core within 3 % of GetDP (coarse mesh;
    error measures: see probe_errors). Includes the points where the old fixed-distance rule
    was 46 % off: (0.02, -0.006), (0.025, 0.02), (0.03, 0)."""
    e, labels = _around(geometry, 1000.0, 0)
    assert {"above", "below", "beside", "between"} <= set(labels)
    assert e["b_err"].max() < 0.03, (e["b_err"].max(), labels[int(np.argmax(e["b_err"]))])
    assert e["dbz_err"].max() < 0.03, (e["dbz_err"].max(), labels[int(np.argmax(e["dbz_err"]))])
    # the point beside the winding: Br has the FEM's sign
    i = int(np.flatnonzero((np.abs(e["r"] - 0.02) < 1e-9) & (np.abs(e["z"] + 0.006) < 1e-9))[0])
    assert np.sign(e["model"]["br"][i]) == np.sign(e["fem"]["br"][i])


@pytest.mark.slow
@pytest.mark.parametrize("geometry", list(CORE_GEOMETRIES))
@pytest.mark.parametrize("material", [200.0, 1000.0, 5000.0, "steel1010"])
def test_core_model_within_3_percent_of_fem_full_matrix(geometry, material):
    e, labels = _around(geometry, material, 1)
    assert e["b_err"].max() < 0.03
    assert e["dbz_err"].max() < 0.03
