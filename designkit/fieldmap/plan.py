"""Where the map samples: the box, the layout of A's harmonic cells, the fit lattices, the grid of
the bias force's residual and the (rho, z) grids of the per-core tables.

All lengths in m, in the design's global frame unless a function says local. The cells grow
with the height above the sources' top (:func:`cell_layers`): a polynomial's error in a cell
falls like (cell size / distance to the sources)^degree, so fixed ratios keep it even. The
choices and their measured errors: docs/fieldmap.md.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError
from ..model.array import CoilArray
from ..model.skipping import source_box
from .clearance import Clearance



def default_box(design) -> tuple[np.ndarray, np.ndarray]:
    """Workspace box (lower, upper corners, m): the bounding box of the design's workspace
    (:meth:`designkit.design.Design.workspace_region`), z_min..z_max above the tops."""
    return design.workspace_region().bounds_m()


def uniform_axis(lo: float, hi: float, spacing: float) -> np.ndarray:
    """Nodes covering [lo, hi] exactly with steps <= ``spacing`` (m)."""
    n = max(2, int(math.ceil((hi - lo) / spacing - 1e-9)) + 1)
    return np.linspace(lo, hi, n)


def graded_axis(lo: float, hi: float, z_ref: float, log_step: float, max_step: float) -> np.ndarray:
    """Nodes on [lo, hi] uniform in log(z - z_ref) (steps ~ ``log_step`` x the height above
    ``z_ref``, fine just above the cores), no step above ``max_step`` (m). Uniform when
    lo <= z_ref."""
    if lo - z_ref <= 1e-6:
        return uniform_axis(lo, hi, max_step)
    u_lo, u_hi = math.log(lo - z_ref), math.log(hi - z_ref)
    n = max(2, int(math.ceil((u_hi - u_lo) / log_step - 1e-9)) + 1)
    z = z_ref + np.exp(np.linspace(u_lo, u_hi, n))
    z[0], z[-1] = lo, hi
    out = [z[:1]]
    for a, b in zip(z[:-1], z[1:]):
        out.append(np.linspace(a, b, max(2, int(math.ceil((b - a) / max_step - 1e-9)) + 1))[1:])
    return np.concatenate(out)


def box_axes(lower, upper, spacing: float, z_ref: float, log_step: float) -> list[np.ndarray]:
    """x, y uniform at ``spacing``; z graded from ``z_ref`` (:func:`graded_axis`)."""
    return [uniform_axis(lower[0], upper[0], spacing), uniform_axis(lower[1], upper[1], spacing),
            graded_axis(lower[2], upper[2], z_ref, log_step, spacing)]


def lattice_nodes(axes) -> np.ndarray:
    """The nodes (n, 3) m of the lattice of x, y, z ``axes``, x slowest."""
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)


# ============================================================================ (rho, z) tables
# per core type, on a grid uniform in v = rho / (1 + rho / rho_scale) and log(z - z_ref): the
# magnet's pull on one core and the sensor field's core modes
def rz_table_spec(coil, lower, upper, rho_step: float, log_step: float,
                  rho_scale: float = 0.05, n_q: int = 8) -> dict | None:
    """Grid of the (v, u) table covering the box for ``coil``'s pose.

    v = rho / (1 + rho / rho_scale) (uniform steps ``rho_step``: the rho step is ``rho_step``
    on the axis and grows as (1 + rho / rho_scale)^2, like the distance to the sources) and
    u = log(z - z_ref) (uniform steps ``log_step``), z_ref the top of the coil's sources.

    None when some box point is not above all of the coil's sources (z_local <= their top):
    the tables cannot cover such a box.
    """
    corners = np.array([[x, y, z] for x in (lower[0], upper[0]) for y in (lower[1], upper[1])
                        for z in (lower[2], upper[2])])
    loc = coil.pose.to_local(corners)
    z_ref = source_box(coil)[2]
    # rho is convex and z linear in the point: their extremes over the box are at corners
    rho_max = float(np.hypot(loc[:, 0], loc[:, 1]).max())
    z_lo, z_hi = float(loc[:, 2].min()), float(loc[:, 2].max())
    if z_lo - z_ref < 1e-4:
        return None
    u_lo, u_hi = math.log(z_lo - z_ref), math.log(z_hi - z_ref)
    n_u = int(math.ceil((u_hi - u_lo) / log_step - 1e-9)) + 1 + 3  # 1 node below, 2 above
    v_max = rho_max / (1 + rho_max / rho_scale)
    n_rho = int(math.ceil(v_max / rho_step - 1e-9)) + 1 + 2
    if (n_rho - 1) * rho_step >= rho_scale:
        return None  # v saturates: rho_scale is too small for this box
    return {"rho_step_m": float(rho_step), "rho_scale_m": float(rho_scale),
            "z_ref_m": float(z_ref),
            "u0": float(u_lo - log_step), "u_step": float(log_step), "shape": [n_rho, n_u, n_q]}


def spec_nodes(spec: dict):
    """rho (n_rho,) and z (n_u,) nodes of a table spec, m (local frame)."""
    n_rho, n_u, _ = spec["shape"]
    vn = spec["rho_step_m"] * np.arange(n_rho)
    rho = vn / (1 - vn / spec["rho_scale_m"])  # inverse of v = rho / (1 + rho / rho_scale)
    z = spec["z_ref_m"] + np.exp(spec["u0"] + spec["u_step"] * np.arange(n_u))
    return rho, z


def union_spec(specs: list) -> dict:
    """One table grid covering several specs of the same coil type (same steps and z_ref)."""
    if len(specs) == 1:
        return specs[0]
    s0 = specs[0]
    u0 = min(s["u0"] for s in specs)
    u_top = max(s["u0"] + s["u_step"] * (s["shape"][1] - 1) for s in specs)
    n_u = int(math.ceil((u_top - u0) / s0["u_step"] - 1e-9)) + 1
    return {**s0, "u0": u0, "shape": [max(s["shape"][0] for s in specs), n_u, s0["shape"][2]]}


def table_specs(arr: CoilArray, idx_lists, lower, upper, step: float, log_step: float,
                rho_scale: float, n_q: int) -> list:
    """One (v, u) table spec per list of coil indices (a coil type), covering the box for every
    coil of the list (:func:`rz_table_spec`, :func:`union_spec`); BadInputError when some
    coil's sources reach into the box."""
    out = []
    for idx in idx_lists:
        s = [rz_table_spec(arr.coils[k], lower, upper, step, log_step, rho_scale, n_q)
             for k in idx]
        if any(x is None for x in s):
            raise BadInputError("box", "above every coil's winding and core (the map's "
                                "(rho, z) tables cover only points above the sources), m",
                                (lower.tolist(), upper.tolist()))
        out.append(union_spec(s))
    return out


def sources_top(arr: CoilArray, lower=None, upper=None) -> float:
    """The sources' effective top, m: the floor of the box [lower, upper] less its distance
    from the nearest source (:class:`designkit.fieldmap.clearance.Clearance`); for upright coils
    under the box, the top of their sources. Without a box: the highest point of any source
    (any pose)."""
    if lower is not None:
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        return float(lower[2]) - Clearance(arr)(lower, np.r_[upper[:2], lower[2]])
    corners = [np.array([[x, y, z] for x in (-r, r) for y in (-r, r) for z in (zl, zh)])
               for r, zl, zh in (source_box(c) for c in arr.coils)]
    return max(float((c.pose.vectors_to_global(k)[:, 2] + c.pose.position[2]).max())
               for c, k in zip(arr.coils, corners))


# ============================================================================ harmonic cells

def cell_layers(lower, upper, clearance, cell_ratio: tuple, layer_ratio,
                degree: tuple) -> list:
    """The harmonic-cell layout of A over the box (meta ``a_layers``): layers from the floor
    up, each ``layer_ratio`` x d thick, d its distance from the sources (``clearance``: the
    sources' top z, m, for sources under the box -- d is the height above it -- or a callable
    (z_lo, z_hi) -> m, the distance between that slab of the box and the sources,
    :meth:`designkit.fieldmap.clearance.Clearance.slab`), cut into a uniform grid of cells no
    wider than ``cell_ratio`` x d, potentials of degree
    ``degree``; all three are sequences per layer from the lowest, the last entry serving every
    layer above (``layer_ratio`` may be one number for all). A polynomial's error in a cell
    grows with (cell size / distance to the sources)^degree, so fixed ratios keep it about even
    and the cells grow upwards (the default box: 10 x 10 cells of degree 12, then 12 x 12,
    8 x 8 and 6 x 6 of degree 7). The lowest layer holds every row's maximum, where the error
    measure is tightest; with a higher degree there its cells are larger and thicker: fewer
    cells (a batch lookup pays mostly per cell product, docs/fieldmap.md) and fewer fit nodes.
    A thin remainder at the top is shared with the layer below."""
    layer_ratio = tuple(np.atleast_1d(layer_ratio).tolist())
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    height = ((lambda z0, z1: z0 - float(clearance)) if np.ndim(clearance) == 0
              and not callable(clearance) else clearance)
    if height(lo[2], lo[2]) < 1e-4:
        raise BadInputError("box", "clear of every coil's sources by > 0.1 mm (the map's "
                            "potential is harmonic only there), m", (lo.tolist(), hi.tolist()))
    wx, wy = hi[0] - lo[0], hi[1] - lo[1]
    layers, z = [], float(lo[2])
    while z < hi[2] - 1e-12:
        ratio_z = layer_ratio[min(len(layers), len(layer_ratio) - 1)]
        d = height(z, z)
        # sources beside the box can come nearer the slab than its floor
        d = min(d, height(z, min(float(hi[2]), z + ratio_z * d)))
        dz = ratio_z * d
        rest = float(hi[2]) - z
        if rest <= 1.5 * dz:
            dz = rest if rest <= dz else rest / 2
        z1 = float(hi[2]) if hi[2] - (z + dz) < 1e-9 else z + dz
        ratio = cell_ratio[min(len(layers), len(cell_ratio) - 1)]
        nx = max(1, math.ceil(wx / (ratio * d) - 1e-9))
        ny = max(1, math.ceil(wy / (ratio * d) - 1e-9))
        layers.append({"name": f"AH{len(layers)}", "z_lo_m": z, "z_hi_m": z1,
                       "x0_m": float(lo[0]), "y0_m": float(lo[1]), "nx": nx, "ny": ny,
                       "cell_x_m": float(wx / nx), "cell_y_m": float(wy / ny),
                       "degree": int(degree[min(len(layers), len(degree) - 1)])})
        z = z1
    return layers


def lobatto(n: int) -> np.ndarray:
    """n Chebyshev-Lobatto nodes on [0, 1] (both ends: neighbouring cells share them)."""
    return (1.0 - np.cos(np.pi * np.arange(n) / (n - 1))) / 2


def layer_nodes(lay: dict, n: int) -> list:
    """The fit lattice of a layer: x, y, z node axes (m), ``n`` Chebyshev-Lobatto nodes per
    cell and axis, shared across cell faces."""
    t = lobatto(n)[:-1]

    def axis(x0, h, count):
        return np.r_[(x0 + h * (np.arange(count)[:, None] + t)).ravel(), x0 + h * count]

    return [axis(lay["x0_m"], lay["cell_x_m"], lay["nx"]),
            axis(lay["y0_m"], lay["cell_y_m"], lay["ny"]),
            lay["z_lo_m"] + (lay["z_hi_m"] - lay["z_lo_m"]) * lobatto(n)]
