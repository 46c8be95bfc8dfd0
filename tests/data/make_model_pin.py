"""Regenerate the pinned values of designkit's coupled array model (tests/data/model_pin.npz).

Question: what does the coupled model (designkit.cores.coupled through CoilArray, linear mu_r
1000 cores, 1 A) give for B (T) and grad B (T/m) of the 3 x 3 thesis array's centre and corner
coils on the 5 x 5 workspace grid (150 mm wide; 12, 20, 30, 50, 80 mm above the cores), for two
cores at the array pitch, and for the pull (N) of one core and of the array on the 10 x 10 mm
magnet at 20, 30, 50 mm?

The pin is not a reference: it records the model as validated against designkit's 3-D GetDP
FEM (``studies/fem3d_array.py``; README: within 1.2 % in B and 1.8 % in grad B). The coupling
and the pull are held to independent references (tests/data/make_axisym_refs.py); the pin
guards what those cannot excite: the transverse (m >= 1) terms between side-by-side cores. After a
deliberate model change: re-validate with the FEM study, then regenerate with
``PYTHONPATH=$PWD python tests/data/make_model_pin.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
HEIGHTS_M = (0.012, 0.020, 0.030, 0.050, 0.080)
PULL_HEIGHTS_M = (0.020, 0.030, 0.050)


def grid_points() -> np.ndarray:
    """The 5 x 5 x 5 workspace grid (x, y in [-75, 75] mm) of studies/fem3d_array.py, m."""
    xy = np.linspace(-0.075, 0.075, 5)
    return np.array([[x, y, h] for h in HEIGHTS_M for x in xy for y in xy])


def pin(array3, array2, array1, moment, magnet_size) -> dict:
    """The pinned arrays (see the module docstring) from the three arrays' coupled models."""
    from designkit.model.array import gradient_from_g5

    pts = grid_points()
    a = array3.actuation_matrix(pts)
    a2 = array2.actuation_matrix(pts[np.abs(pts[:, 0]) <= 0.0375 + 1e-9])
    out = {"grid_points_m": pts, "two_points_m": pts[np.abs(pts[:, 0]) <= 0.0375 + 1e-9]}
    for name, aa, k in (("centre", a, 4), ("corner", a, 0), ("two", a2, 0)):
        out[f"{name}_b_t"] = aa[:, :3, k]
        out[f"{name}_g_t_per_m"] = gradient_from_g5(aa[:, 3:, k])
    h = np.array(PULL_HEIGHTS_M)
    out["pull_heights_m"] = h
    for name, arr in (("one", array1), ("array", array3)):
        out[f"pull_{name}_fz_n"] = np.array([
            arr.bias_force([0.0, 0.0, q], moment, magnet_size_m=magnet_size)[2] for q in h])
    return out


def main() -> int:
    from designkit.model.array import CoilArray
    from designkit.design import default_design

    d = default_design()
    arrays = [CoilArray.from_design(d.replace(**{"array.rows": r, "array.columns": c}))
              for r, c in ((3, 3), (1, 2), (1, 1))]
    m = np.asarray(d.magnet.moment_vector_a_m2, float)
    np.savez_compressed(HERE / "model_pin.npz",
                        **pin(*arrays, m, (d.magnet.radius_m, d.magnet.length_m)))
    print(f"wrote {HERE / 'model_pin.npz'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
