"""The coupled model of arrays of other layouts against designkit's 3-D GetDP FEM.

Cached references (tests/data/layout_fem_refs.npz, ``tests/data/make_layout_fem_refs.py``; the
mesh level and time of each case in layout_fem_refs.json): a hexagonal array of 7 coils with
its centre coil and an outer coil energized, and a ring of 6 coils whose axes lean 30 degrees
inwards with coil 0 energized, every core iron (mu_r 1000), B and grad B on a 5 x 5 grid over
the workspace at 20, 30, 50 and 80 mm, mesh level 0. The acceptance: every row of the coupled
A within 2 % of its largest |value| over the points; measured 1.07 / 1.31 % (hexagon, centre /
outer coil) and 1.87 % (tilted ring; at the point 20 mm above the energized tilted coil, where
the level-0 FEM's own error is ~2 %: one such coil alone, whose model is the validated
single-core one, differs from it by 2.1 % there, 3.3 % at level -1). The uncoupled model is off
by 27-35 % (hexagon) and 7 % (tilted ring): a coupling term dropped, a tilted core's frame
turned the wrong way or a symmetry used on placements it does not map fails. The slow test
reruns the FEM (coarse mesh) for the tilted ring.
"""

import importlib.util
import json
import shutil

import numpy as np
import pytest

from conftest import DATA
from designkit.fem.array_check import row_errors
from designkit.model.array import g5_from_gradient

_spec = importlib.util.spec_from_file_location("make_layout_fem_refs",
                                               DATA / "make_layout_fem_refs.py")
REFS = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(REFS)
FEM = np.load(DATA / "layout_fem_refs.npz")
META = json.loads((DATA / "layout_fem_refs.json").read_text())

TOL = 0.02
"""Each row of A within 2 % of its largest |value| over the points (the issue's bound)."""


def _fem_rows(case: str) -> np.ndarray:
    return np.concatenate([FEM[f"{case}_b_t"], g5_from_gradient(FEM[f"{case}_g_t_per_m"])], 1)


@pytest.fixture(scope="module")
def arrays():
    return {name: REFS.case_array(name) for name in ("hex7", "ring6")}


@pytest.mark.parametrize("case", sorted(c for c in REFS.CASES if c in META))
def test_coupled_array_of_any_layout_against_cached_3d_fem(case, arrays):
    design, k = REFS.CASES[case]
    assert META[case]["design_toml"] == REFS.DESIGNS[design]  # the cache is of this design
    pts = FEM[f"{case}_points_m"]
    np.testing.assert_allclose(pts, REFS.case_points(design))
    ref = _fem_rows(case)
    arr = arrays[design] if design in arrays else REFS.case_array(design)
    coupled = row_errors(arr.actuation_matrix(pts)[:, :, k], ref)
    uncoupled = row_errors(arr.uncoupled_actuation_matrix(pts)[:, :, k], ref)
    assert max(coupled.values()) < TOL, coupled
    # the reference resolves the coupling: the single-coil model is far outside the bound
    assert max(uncoupled.values()) > 2 * TOL, uncoupled


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("getdp") is None,
                    reason="GetDP not installed (apt-get install getdp)")
def test_tilted_ring_against_a_fresh_3d_fem(arrays):
    # the FEM rerun at a coarse mesh (level -2, ~15k tetrahedra, ~30 s): its own error is
    # ~2-3 % of a row's largest value next to the tilted cores (the cached level's is below 1 %)
    from designkit.fem.array_check import check_array

    arr = arrays["ring6"]
    res = check_array(arr, REFS.case_points("ring6"), 0, level=-2)
    assert res.symmetry == "half"
    assert max(res.coupled_error.values()) < 0.06, res.coupled_error
    assert max(res.uncoupled_error.values()) > max(res.coupled_error.values())
    # the fresh coarse FEM agrees with the cached finer one within its own discretization
    assert max(row_errors(res.fem, _fem_rows("ring6_c0")).values()) < 0.06
