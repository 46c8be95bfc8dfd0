"""The per-core (rho, z) tables of a map: the magnet's pull on each core and the sensor field's
core modes, and their kernels (numpy only).

A table is bilinear on a grid uniform in v = rho / (1 + rho / rho_scale) and u = log(z - z_ref)
in the frame of each of its coils. Magnet tables (``MRZ<k>``) hold F_rho / rho and F_z (N/m,
N) of the magnet's pull on one core alone (:func:`magnet_terms` sums them). Mode tables
(``SM<k>``) hold the quantities of the cores' basis fields (:data:`N_MODE_Q` per shape; the
formulas in :func:`_poly`); :func:`mode_rows` gives the 8 rows per basis field, and the
one-point and batch kernels :func:`modes_one`, :func:`kernel_rows_many` give m . B per basis
field for the sensor field (the coupled system's adjoint sources, linear cores; docs/
mapfile_format.md). Points in m, global frame.
"""

from __future__ import annotations

import math

import numpy as np

from .format import N_MODE_Q, NQ_MAGNET

def gradient_tensor(g5: np.ndarray) -> np.ndarray:
    """Gradient rows (..., 5) (dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) -> the full gradient
    (..., 3, 3), [i, j] = dB_i/dx_j: symmetric (curl-free) and traceless (divergence-free)."""
    gxx, gxy, gxz, gyy, gyz = np.moveaxis(np.asarray(g5), -1, 0)
    return np.stack([np.stack([gxx, gxy, gxz], -1), np.stack([gxy, gyy, gyz], -1),
                     np.stack([gxz, gyz, -gxx - gyy], -1)], -2)


def _rotate_rows(rows: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Local rows (8, n, k) of coils with rotations (k, 3, 3) -> global rows (8, n, k)."""
    b = rows[:3].astype(np.float64)
    gxx, gxy, gxz, gyy, gyz = rows[3:].astype(np.float64)
    g = np.stack([np.stack([gxx, gxy, gxz]), np.stack([gxy, gyy, gyz]),
                  np.stack([gxz, gyz, -gxx - gyy])])  # (3, 3, n, k)
    bg = np.einsum("kia,ank->ink", rot, b)
    gg = np.einsum("kia,abnk,kjb->ijnk", rot, g, rot)
    return np.stack([bg[0], bg[1], bg[2], gg[0, 0], gg[0, 1], gg[0, 2], gg[1, 1], gg[1, 2]])


def prepare_magnet(tables: list, metas: list, positions, rotations) -> list:
    """Per coil type, what :func:`magnet_terms` needs."""
    out = []
    for tab, m in zip(tables, metas):
        out.append(dict(_table_constants(tab, m, positions, rotations),
                        flat=np.ascontiguousarray(tab, dtype=np.float64).reshape(-1, NQ_MAGNET)))
    return out


def _table_constants(tab: np.ndarray, m: dict, positions, rotations) -> dict:
    """What every (v, u) table lookup needs: its coils (idx, pos, rot or None), its size and
    its steps (inverted), from the table and its meta entry."""
    idx = np.asarray(m["coils"], dtype=np.intp)
    rot = np.asarray(rotations, float)[idx]
    return {"idx": idx, "pos": np.asarray(positions, float)[idx],
            "rot": None if np.all(rot == np.eye(3)) else rot,
            "n_rho": tab.shape[0], "n_u": tab.shape[1], "inv_h": 1.0 / m["rho_step_m"],
            "inv_scale": 1.0 / m["rho_scale_m"], "z_ref": m["z_ref_m"], "u0": m["u0"],
            "inv_du": 1.0 / m["u_step"]}


def magnet_terms(prepared: list, p: np.ndarray) -> np.ndarray:
    """The magnet's pull at points (n, 3) summed over the cores, each core alone: (n, 3) N."""
    force = np.zeros((len(p), 3))
    for t in prepared:
        x, y, val = _bilinear(t, p)  # val (n, k, 2): F_rho / rho, F_z
        fl = np.stack([val[..., 0] * x, val[..., 0] * y, val[..., 1]], axis=-1)  # local frame
        if t["rot"] is not None:
            fl = np.einsum("kij,nkj->nki", t["rot"], fl)
        force += fl.sum(axis=1)
    return force


# ============================================================================ coupled core modes
def prepare_modes(tables: list, metas: list, positions, rotations) -> list:
    """Per core type, what :func:`mode_rows` needs."""
    out = []
    for tab, m in zip(tables, metas):
        out.append(dict(_table_constants(tab, m, positions, rotations),
                        flat=(tab.reshape(-1, tab.shape[2]).astype(np.float64)
                              * np.asarray(m["column_scale"], float)),
                        basis=[tuple(b) for b in m["basis"]],
                        col={tuple(s): c for s, c in zip(m["shapes"], m["columns"])}))
        t = out[-1]
        groups, order = [], []
        for key in sorted({(b[0], b[2]) for b in t["basis"]}):
            members = [i for i, b in enumerate(t["basis"]) if (b[0], b[2]) == key]
            cols = np.array([[t["col"][(t["basis"][i][0], t["basis"][i][1])] + q
                              for q in range(N_MODE_Q[key[0]])] for i in members], np.intp)
            groups.append((key, cols))
            order += members
        t["groups"], t["order"] = groups, np.array(order, np.intp)
        _prepare_one(t)
    return out


def _prepare_one(t: dict) -> None:
    """What :func:`prepare_one` needs: every group's quantities padded to 5 columns, so one
    GEMM gives all polynomials and one batched matmul all basis rows.

    ``one_src`` / ``one_dst``: scatter of the table's columns into (n_basis, 5 n_groups) per core
    (basis in ``t['order']``); ``one_poly`` (15, 5 n_groups * 8): the groups' :data:`_POLY_T`
    side by side (zero rows for the padding of m = 0's 4 quantities).
    """
    width = 5 * len(t["groups"])
    src, dst = [], []
    poly = np.zeros((15, width, 8))
    s = 0
    for g, ((m, c), cols) in enumerate(t["groups"]):
        poly[:, 5 * g:5 * g + N_MODE_Q[m]] = _POLY_T[(m, c)].reshape(15, N_MODE_Q[m], 8)
        for member in cols:
            src += [int(x) for x in member]
            dst += [s * width + 5 * g + q for q in range(len(member))]
            s += 1
    t["one_src"], t["one_dst"] = np.array(src, np.intp), np.array(dst, np.intp)
    t["one_poly"], t["one_width"], t["one_nb"] = poly.reshape(15, -1), width, s


_POW_X = np.array([0, 1, 0, 2, 1, 0, 3, 2, 1, 0, 4, 3, 2, 1, 0], np.intp)
"""Powers of x, resp. y, of the 15 monomials of :func:`_monomials`."""
_POW_Y = np.array([0, 0, 1, 0, 1, 2, 0, 1, 2, 3, 0, 1, 2, 3, 4], np.intp)
_POW = np.arange(5.0)


def _bilinear(t: dict, p: np.ndarray):
    """Local x, y (n, k) and the table quantities (n, k, Q) of a type's k coils at (n, 3)."""
    d = p[:, None, :] - t["pos"][None]
    loc = d if t["rot"] is None else np.einsum("nki,kij->nkj", d, t["rot"])
    x, y = loc[..., 0], loc[..., 1]
    rho = np.sqrt(x * x + y * y)
    vv = np.minimum(rho * t["inv_h"] / (1.0 + rho * t["inv_scale"]), t["n_rho"] - 1.0001)
    u = (np.log(np.maximum(loc[..., 2] - t["z_ref"], 1e-12)) - t["u0"]) * t["inv_du"]
    u = np.clip(u, 0.0, t["n_u"] - 1.000001)
    i, j = vv.astype(np.intp), u.astype(np.intp)
    tr, tz = (vv - i)[..., None], (u - j)[..., None]
    base = i * t["n_u"] + j
    f, nu = t["flat"], t["n_u"]
    lo = f[base]
    lo += tz * (f[base + 1] - lo)
    hi = f[base + nu]
    hi += tz * (f[base + nu + 1] - hi)
    lo += tr * (hi - lo)
    return x, y, lo


_MIRROR_XY = np.array([1, 0, 2, 6, 4, 7, 3, 5], np.intp)
"""The rows of A (Bx, By, Bz, Gxx, Gxy, Gxz, Gyy, Gyz) with x and y exchanged."""


def _poly(x: np.ndarray, y: np.ndarray, m: int, c: int) -> np.ndarray:
    """(n, k, Q_m, 8): row r of a basis field = sum over its quantities q of val[q] * P[q, r].

    m = 0: (b, Bz, e, w) -> Bx = b x, By = b y, Bz, Gxx = b + w x^2, Gxy = w x y, Gxz = e x,
    Gyy = b + w y^2, Gyz = e y. m = 1, 2: B = -grad of the potential x G, y G (m = 1 cos, sin)
    or (x^2 - y^2) H, 2 x y H (m = 2), G, H functions of (rho^2, z); the quantities are
    (a, a1, a2, az, a1z) = -mu0 (G, G', G'', G_z, G'_z), ' = d/d(rho^2).
    """
    xx, xy, yy = x * x, x * y, y * y
    P = np.zeros(x.shape + (N_MODE_Q[m], 8))
    if m == 0:
        P[..., 0, 0], P[..., 0, 1], P[..., 0, 3], P[..., 0, 6] = x, y, 1.0, 1.0
        P[..., 1, 2] = 1.0
        P[..., 2, 5], P[..., 2, 7] = x, y
        P[..., 3, 3], P[..., 3, 4], P[..., 3, 6] = xx, xy, yy
    elif m == 1 and c == 0:
        P[..., 0, 0] = 1.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 4], P[..., 1, 6] = (
            2 * xx, 2 * xy, 6 * x, 2 * y, 2 * x)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * x * xx, 4 * xx * y, 4 * x * yy
        P[..., 3, 2], P[..., 3, 5] = x, 1.0
        P[..., 4, 5], P[..., 4, 7] = 2 * xx, 2 * xy
    elif m == 1:  # y G is x G mirrored in x = y: swap x, y and the rows (x <-> y)
        return _poly(y, x, 1, 0)[..., _MIRROR_XY]
    elif c == 0:
        pp = xx - yy
        P[..., 0, 0], P[..., 0, 1], P[..., 0, 3], P[..., 0, 6] = 2 * x, -2 * y, 2.0, -2.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 6] = (
            2 * x * pp, 2 * y * pp, 8 * xx + 2 * pp, 2 * pp - 8 * yy)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * xx * pp, 4 * xy * pp, 4 * yy * pp
        P[..., 3, 2], P[..., 3, 5], P[..., 3, 7] = pp, 2 * x, -2 * y
        P[..., 4, 5], P[..., 4, 7] = 2 * x * pp, 2 * y * pp
    else:
        qq = 2 * xy
        P[..., 0, 0], P[..., 0, 1], P[..., 0, 4] = 2 * y, 2 * x, 2.0
        P[..., 1, 0], P[..., 1, 1], P[..., 1, 3], P[..., 1, 4], P[..., 1, 6] = (
            2 * x * qq, 2 * y * qq, 12 * xy, 4 * (xx + yy), 12 * xy)
        P[..., 2, 3], P[..., 2, 4], P[..., 2, 6] = 4 * xx * qq, 4 * xy * qq, 4 * yy * qq
        P[..., 3, 2], P[..., 3, 5], P[..., 3, 7] = qq, 2 * y, 2 * x
        P[..., 4, 5], P[..., 4, 7] = 2 * x * qq, 2 * y * qq
    return P


def _monomials(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(..., 15): 1, x, y, x^2, x y, y^2, x^3, x^2 y, x y^2, y^3, x^4, x^3 y, x^2 y^2,
    x y^3, y^4."""
    xx, yy = x * x, y * y
    return np.stack([np.ones_like(x), x, y, xx, x * y, yy, xx * x, xx * y, x * yy, yy * y,
                     xx * xx, xx * x * y, xx * yy, x * yy * y, yy * yy], axis=-1)


def _poly_tensors() -> dict:
    """_poly as constant tensors on the monomials: P = monomials @ T[(m, c)] (15, Q_m * 8).

    _poly is a polynomial of degree <= 4 in (x, y), so evaluating it at 40 random points and
    solving for the 15 monomial coefficients is exact up to rounding (checked)."""
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-1, 1, (2, 40))
    mono = _monomials(x, y)
    out = {}
    for key in ((0, 0), (1, 0), (1, 1), (2, 0), (2, 1)):
        p = _poly(x, y, *key).reshape(40, -1)
        t = np.linalg.lstsq(mono, p, rcond=None)[0]
        t[np.abs(t) < 1e-9] = 0.0
        t = np.round(t)  # the coefficients are small integers
        assert np.allclose(mono @ t, p, atol=1e-12)
        out[key] = t
    return out


def mode_rows(t: dict, p: np.ndarray) -> np.ndarray:
    """Rows (n, k, n_basis, 8) of every basis field of the type's k cores at points (n, 3),
    global frame, basis in the order of ``t['order']`` (grouped by mode order and cos / sin;
    :func:`prepare_modes` permutes the coefficients to match)."""
    x, y, val = _bilinear(t, p)
    n, k = x.shape
    mono = _monomials(x, y).reshape(n * k, 15)
    parts = []
    for (m, c), cols in t["groups"]:
        v = val[..., cols]  # (n, k, nb_g, Q_m)
        pm = (mono @ _POLY_T[(m, c)]).reshape(n, k, 1, N_MODE_Q[m], 8)  # one GEMM
        # a sum over the 4-5 quantities: numpy's batched matmul is slow on tiny matrices
        acc = v[..., 0, None] * pm[..., 0, :]
        for q in range(1, v.shape[-1]):
            acc += v[..., q, None] * pm[..., q, :]
        parts.append(acc)  # (n, k, nb_g, 8)
    out = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=2)
    if t["rot"] is not None:
        flat = out.transpose(3, 0, 2, 1).reshape(8, -1, k)
        out = _rotate_rows(flat, t["rot"]).reshape(8, n, -1, k).transpose(1, 3, 2, 0)
    return out


_POLY_T = _poly_tensors()


# ============================================================================ one-point kernels
# The sensor field for one magnet position in a few small numpy calls (the per-call overhead,
# not the arithmetic, is the cost): every core's mode table looked up with one gather of
# the 4 corners and one matmul for the weights, all polynomials one GEMM and the sum one GEMV.
def _lookup(t: dict, flat: np.ndarray) -> dict | None:
    """A table of a prepared type as :func:`_interp_one` reads it; None unless its coils are
    unrotated at one height (then z and u are scalars)."""
    pos = np.asarray(t["pos"], float)
    if t["rot"] is not None or not np.all(pos[:, 2] == pos[0, 2]):
        return None
    nu = t["n_u"]
    return {"flat": np.ascontiguousarray(flat, dtype=np.float64), "n_u": nu,
            "inv_h": t["inv_h"], "inv_scale": t["inv_scale"], "vmax": t["n_rho"] - 1.0001,
            "zr0": float(pos[0, 2] + t["z_ref"]), "u0": t["u0"], "inv_du": t["inv_du"],
            "umax": nu - 1.000001, "off4": np.array([0, 1, nu, nu + 1], np.intp)}


def _interp_one(L: dict, rho: np.ndarray, zq: float) -> np.ndarray:
    """Bilinear in (v, u) at one height ``zq`` (global, m) for every coil's rho (k,) m:
    (k, Q) float64, the same cells and weights as the batch kernels."""
    vv = rho * L["inv_h"]
    vv /= rho * L["inv_scale"] + 1.0
    np.minimum(vv, L["vmax"], out=vv)
    i = vv.astype(np.intp)
    vv -= i
    zz = zq - L["zr0"]
    u = (math.log(zz if zz > 1e-12 else 1e-12) - L["u0"]) * L["inv_du"]
    u = min(max(u, 0.0), L["umax"])
    j = int(u)
    tz = u - j
    sz = 1.0 - tz
    corners = L["flat"][(i * L["n_u"] + j)[:, None] + L["off4"]]  # (k, 4, Q)
    w = np.multiply.outer(vv, (-sz, -tz, sz, tz))
    w += (sz, tz, 0.0, 0.0)
    return np.matmul(w[:, None, :], corners)[:, 0]


def prepare_magnet_one(prepared: list) -> dict | None:
    """The one-point bias-force kernel's table (:func:`magnet_terms_one`): None unless the map
    has one coil type, unrotated at one height (the general path runs then). Besides
    :func:`_lookup`'s: ``quad`` (n_rho n_u, 4, 2), each cell's four corners side by side (one
    gather a point), and ``pos_xy0`` (k, 3), the coils' centres with z = 0."""
    if len(prepared) != 1:
        return None
    t = prepared[0]
    table = _lookup(t, t["flat"])
    if table is None:
        return None
    flat, nu = table["flat"], table["n_u"]
    rows = np.arange(len(flat))
    table["quad"] = np.ascontiguousarray(
        flat[np.minimum(rows[:, None] + table["off4"], len(flat) - 1)])
    pos = np.array(t["pos"], float)
    pos[:, 2] = 0.0
    table["pos_xy0"] = pos
    return table


_F0_PICK = np.array([0, 1, 5], np.intp)
"""Entries (0, 0), (0, 1), (1, 2) of the (2, 3) product in :func:`magnet_terms_one`: sum F_rho /
rho x, sum F_rho / rho y, sum F_z."""


def magnet_terms_one(prepared: list, table: dict | None, q) -> np.ndarray:
    """:func:`magnet_terms` at one point ``q`` (3 floats, m) -> (3,) N, through the one-point
    table of :func:`prepare_magnet_one` when there is one: the same cells and weights as the
    batch kernel in a dozen numpy calls (their count, not the arithmetic, is the cost)."""
    if table is None:
        return magnet_terms(prepared, np.array([q], float))[0]
    d = np.subtract((q[0], q[1], 1.0), table["pos_xy0"])      # x, y and a column of ones
    rho = np.hypot(d[:, 0], d[:, 1])
    vv = rho * table["inv_h"]
    rho *= table["inv_scale"]
    rho += 1.0
    vv /= rho
    np.minimum(vv, table["vmax"], out=vv)
    i = vv.astype(np.intp)
    vv -= i
    zz = q[2] - table["zr0"]
    u = (math.log(zz if zz > 1e-12 else 1e-12) - table["u0"]) * table["inv_du"]
    u = min(max(u, 0.0), table["umax"])
    j = int(u)
    tz = u - j
    sz = 1.0 - tz
    i *= table["n_u"]
    i += j
    corners = table["quad"][i]                                 # (k, 4, 2)
    w = np.multiply.outer(vv, (-sz, -tz, sz, tz))
    w += (sz, tz, 0.0, 0.0)
    val = np.matmul(w[:, None, :], corners)[:, 0]              # (k, 2): F_rho / rho, F_z
    return (val.T @ d).take(_F0_PICK)


def prepare_one(modes: tuple, coefs: tuple, moment) -> dict | None:
    """The one-point kernel's constants for a sum of mode tables with coefficients ``coefs``
    ((k * n_basis, n_out) per type, MapFile's layout), giving m . B per basis field for the
    moment ``moment`` (3,) A m^2 (the sensor fields). None: the general path is used (several
    types, rotated coils or coils at different heights)."""
    if len(modes) != 1:
        return None
    mt = modes[0]
    lcm = _lookup(mt, mt["flat"])
    if lcm is None:
        return None
    n_out = coefs[0].shape[1]
    nb, width = mt["one_nb"], mt["one_width"]
    src, dst = mt["one_src"], mt["one_dst"]
    poly = mt["one_poly"].reshape(15, width, 8)[..., :3] @ np.asarray(moment, float)
    # on all 25 products x^a y^b (a, b <= 4): those of degree > 4 get zero rows
    poly25 = np.zeros((5, 5) + poly.shape[1:])
    poly25[_POW_X, _POW_Y] = poly
    # for the batch kernel: the basis fields grouped by the block of polynomials they use
    # (each mode order and cos / sin), values unpadded
    blocks: dict = {}
    for b in np.unique(dst // width):
        sel = dst // width == b
        cols = dst[sel] % width
        blocks.setdefault(int(cols.min()), []).append((int(b), src[sel][np.argsort(cols)]))
    groups = [(start, len(mem[0][1]), np.array([b for b, _ in mem], np.intp),
               np.array([v for _, v in mem], np.intp)) for start, mem in sorted(blocks.items())]
    return {"pos": mt["pos"], "cm": lcm, "src": src, "dst": dst,
            "poly": np.ascontiguousarray(poly25.reshape(25, -1)),
            "nb": nb, "width": width, "groups": groups,
            "coef": np.ascontiguousarray(coefs[0].reshape(-1, n_out))}


def modes_one(F: dict, q) -> np.ndarray:
    """One point ``q`` (3 floats, m): m . B (k * n_basis,) of every core's basis fields; the
    sensor field = that @ F['coef'] (see :func:`prepare_one`)."""
    d = np.subtract(q, F["pos"])
    x, y = d[:, 0], d[:, 1]
    val = _interp_one(F["cm"], np.sqrt(x * x + y * y), q[2])
    k = len(x)
    pw = np.power(d[:, :2, None], _POW)  # (k, 2, 5): powers 0..4 of x and y
    poly = ((pw[:, 0, :, None] * pw[:, 1, None, :]).reshape(k, 25) @ F["poly"]
            ).reshape(k, F["width"], 1)
    pad = np.zeros((k, F["nb"] * F["width"]))
    pad[:, F["dst"]] = val[:, F["src"]]
    return np.matmul(pad.reshape(k, F["nb"], F["width"]), poly).reshape(-1)


def _interp_many(L: dict, rho: np.ndarray, z: np.ndarray) -> np.ndarray:
    """:func:`_interp_one` for points (m,) at heights ``z`` (m,) m, rho (m, k) m: (m, k, Q)."""
    vv = rho * L["inv_h"]
    vv /= rho * L["inv_scale"] + 1.0
    np.minimum(vv, L["vmax"], out=vv)
    i = vv.astype(np.intp)
    vv -= i
    u = np.log(np.maximum(z - L["zr0"], 1e-12))
    u -= L["u0"]
    u *= L["inv_du"]
    np.clip(u, 0.0, L["umax"], out=u)
    j = u.astype(np.intp)
    tz = (u - j)[:, None, None]
    f, nu = L["flat"], L["n_u"]
    base = i * nu + j[:, None]
    lo = f[base]
    lo += tz * (f[base + 1] - lo)
    base += nu
    hi = f[base]
    hi += tz * (f[base + 1] - hi)
    hi -= lo
    hi *= vv[..., None]
    hi += lo
    return hi


BATCH_CHUNK = 256
"""Points per block of :func:`kernel_rows_many` (~k * 1.5 k floats of temporaries per point:
small blocks stay in cache)."""


def kernel_rows_many(F: dict, p: np.ndarray) -> np.ndarray:
    """:func:`modes_one` for points (m, 3): (m, k * n_basis), for one GEMM with
    ``F['coef']``."""
    m = len(p)
    d = p[:, None, :] - F["pos"]  # (m, k, 3)
    k = d.shape[1]
    x, y = d[..., 0], d[..., 1]
    val = _interp_many(F["cm"], np.sqrt(x * x + y * y), p[:, 2])
    pw = np.empty((m, k, 2, 5))  # powers 0..4 of x and y (products: np.power is slow)
    pw[..., 0] = 1.0
    pw[..., 1] = d[..., :2]
    for e in range(2, 5):
        np.multiply(pw[..., e - 1], pw[..., 1], out=pw[..., e])
    mono = (pw[..., 0, :, None] * pw[..., 1, None, :]).reshape(m * k, 25)
    poly = (mono @ F["poly"]).reshape(m * k, F["width"], 1)
    # per block of polynomials, its basis fields' values (m k, n_g, Q) @ (m k, Q, 1)
    out = np.empty((m * k, F["nb"], 1))
    flat = val.reshape(m * k, -1)
    for start, nq, basis, cols in F["groups"]:
        out[:, basis] = np.matmul(flat[:, cols], poly[:, start:start + nq])
    return out.reshape(m, k * F["nb"])
