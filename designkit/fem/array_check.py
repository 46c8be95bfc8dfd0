"""A design's whole array against the 3-D FEM: one energized coil, every core in its pose.

The check behind ``designkit fem --3d``: the column of the coupled actuation matrix A(p) of coil
k (:meth:`designkit.model.array.CoilArray.actuation_matrix`) against the 3-D GetDP model of the
same array (:func:`designkit.fem.fem3d.device_case`, coil k at 1 A, linear cores) at points over
the workspace, with the uncoupled single-coil model beside it. Errors per row of A, relative to
the row's largest |value| over the points (the map's and the issue's measure). B in T/A, grad B
in T/(m A), lengths in m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.array import ROWS, CoilArray, g5_from_gradient
from .fem3d import device_case

HEIGHTS_M = (0.020, 0.030, 0.050, 0.080)
"""Heights of the compared points above the coil tops, m (the workspace's 20-80 mm)."""


@dataclass(frozen=True)
class ArrayCheck:
    """The comparison: points (n, 3) m; the FEM's and the models' A column (n, 8); per row the
    largest error relative to the FEM row's largest |value|, coupled and uncoupled; the FEM's
    mesh and symmetry."""

    points_m: np.ndarray
    fem: np.ndarray
    coupled: np.ndarray
    uncoupled: np.ndarray
    coupled_error: dict
    uncoupled_error: dict
    tetrahedra: int
    symmetry: str
    seconds: float

    def to_dict(self) -> dict:
        return {"rows": list(ROWS), "points_m": self.points_m.tolist(),
                "fem": self.fem.tolist(), "coupled": self.coupled.tolist(),
                "uncoupled": self.uncoupled.tolist(),
                "coupled_max_rel_per_row": self.coupled_error,
                "uncoupled_max_rel_per_row": self.uncoupled_error,
                "tetrahedra": self.tetrahedra, "symmetry": self.symmetry,
                "fem_seconds": self.seconds}


def workspace_points(design, n_side: int = 5, heights=HEIGHTS_M) -> np.ndarray:
    """(n_side^2 len(heights), 3) m: an n_side x n_side grid over the bounding box of the
    design's workspace at ``heights`` above the coil tops."""
    lo, hi = design.workspace_region().bounds_m()
    X, Y, Z = np.meshgrid(np.linspace(lo[0], hi[0], n_side), np.linspace(lo[1], hi[1], n_side),
                          np.asarray(heights, float), indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), Z.ravel()])


def row_errors(got: np.ndarray, ref: np.ndarray) -> dict:
    """{row: max |got - ref| / max |ref|} over the points, rows of A (n, 8)."""
    err = np.abs(got - ref).max(axis=0) / np.maximum(np.abs(ref).max(axis=0), 1e-300)
    return dict(zip(ROWS, err.tolist()))


def check_array(array: CoilArray, points, coil: int, level: int, out_dir=None) -> ArrayCheck:
    """The 3-D FEM of ``array`` with ``coil`` at 1 A at ``points`` (n, 3) m (mesh ``level``,
    GetDP's files in ``out_dir`` or a temporary folder) against the coupled and the uncoupled
    model (:class:`ArrayCheck`)."""
    pts = np.atleast_2d(np.asarray(points, float))
    b, g, res = device_case(array, pts, energized=coil, level=level, out_dir=out_dir)
    fem = np.concatenate([b, g5_from_gradient(g)], axis=1)
    coupled = array.actuation_matrix(pts)[:, :, coil]
    uncoupled = array.uncoupled_actuation_matrix(pts)[:, :, coil]
    return ArrayCheck(pts, fem, coupled, uncoupled, row_errors(coupled, fem),
                      row_errors(uncoupled, fem), int(res.mesh_stats["tetrahedra"]),
                      res.extra["symmetry"], res.solve_seconds + res.mesh_seconds)
