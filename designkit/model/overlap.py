"""Where the coils' solids meet: overlap and separation checks of coils in any pose.

A coil occupies a solid cylinder for its winding envelope (radius = the winding's outer
radius) and one for its core, in its local frame (axis = local z). Two coils overlap when any
of their solids share interior points (exact for parallel axes, sampled on the surfaces for
tilted ones); a core must be surrounded by air (the coupled solve's assumption); a sensor may
not sit inside any solid. Lengths in m; the errors name the coils and their positions in mm.
"""

from __future__ import annotations

import itertools

import numpy as np

from ..errors import BadInputError, DesignRuleError
from ..geometry.pose import Pose


def coil_solids(coil) -> list:
    """Solid cylinders (radius, z_lo, z_hi) a coil occupies in its local frame, with names."""
    out = [("winding", coil.outer_radius, -coil.length / 2, coil.length / 2)]
    if coil.core is not None:
        c = coil.core
        out.append(("core", c.radius, c.offset - c.length / 2, c.offset + c.length / 2))
    return out


def solids_overlap(pa: Pose, a, pb: Pose, b) -> bool:
    """Do two solid cylinders (in poses) share interior points?

    Exact for parallel (or anti-parallel) axes; otherwise surface points of each (0.5 mm
    spacing or finer) are tested inside the other, which finds any overlap deeper than that.
    """
    _, ra, za0, za1 = a
    _, rb, zb0, zb1 = b
    ca = np.asarray(pa.position) + pa.matrix[:, 2] * 0.5 * (za0 + za1)
    cb = np.asarray(pb.position) + pb.matrix[:, 2] * 0.5 * (zb0 + zb1)
    rsa = np.hypot(ra, 0.5 * (za1 - za0))
    rsb = np.hypot(rb, 0.5 * (zb1 - zb0))
    if np.linalg.norm(ca - cb) >= rsa + rsb:
        return False
    ua, ub = pa.matrix[:, 2], pb.matrix[:, 2]
    eps = 1e-12
    # each cylinder lies inside the capsule of its radius about its axis segment
    if _segment_distance(ca, ua * 0.5 * (za1 - za0), cb, ub * 0.5 * (zb1 - zb0)) >= ra + rb:
        return False
    if abs(abs(ua @ ub) - 1.0) < 1e-9:
        d = cb - ca
        axial = d @ ua
        radial = np.linalg.norm(d - axial * ua)
        ha, hb = 0.5 * (za1 - za0), 0.5 * (zb1 - zb0)
        return bool(radial < ra + rb - eps and abs(axial) < ha + hb - eps)

    def surface(pose, r, z0, z1):
        step = min(5e-4, r / 8)
        nphi = max(16, int(2 * np.pi * r / step))
        nz = max(2, int((z1 - z0) / step) + 1)
        nr = max(2, int(r / step) + 1)
        phi = np.linspace(0, 2 * np.pi, nphi, endpoint=False)
        zz = np.linspace(z0, z1, nz)
        P, Z = np.meshgrid(phi, zz, indexing="ij")
        pts = [np.stack([r * np.cos(P), r * np.sin(P), Z], -1).reshape(-1, 3)]
        rr = np.linspace(0, r, nr)
        R, P = np.meshgrid(rr, phi, indexing="ij")
        for zc in (z0, z1):
            pts.append(np.c_[(R * np.cos(P)).ravel(), (R * np.sin(P)).ravel(),
                             np.full(R.size, zc)])
        loc = np.vstack(pts)
        return loc @ pose.matrix.T + np.asarray(pose.position)

    def inside(pose, r, z0, z1, pts):
        loc = pose.to_local(pts)
        return (np.hypot(loc[:, 0], loc[:, 1]) < r - eps) & (loc[:, 2] > z0 + eps) & (
            loc[:, 2] < z1 - eps)

    return bool(np.any(inside(pb, rb, zb0, zb1, surface(pa, ra, za0, za1)))
                or np.any(inside(pa, ra, za0, za1, surface(pb, rb, zb0, zb1))))


def _segment_distance(ca, ha, cb, hb) -> float:
    """Shortest distance between the segments ca +- ha and cb +- hb (3-vectors, m)."""
    s, t = np.meshgrid(np.linspace(-1.0, 1.0, 41), np.linspace(-1.0, 1.0, 41))
    d = (ca + s.ravel()[:, None] * ha) - (cb + t.ravel()[:, None] * hb)
    # sampled minimum, less the largest step between samples: a lower bound
    step = 0.05 * (np.linalg.norm(ha) + np.linalg.norm(hb))
    return float(np.sqrt(np.einsum("ij,ij->i", d, d).min()) - step)


def first_overlap(coils) -> tuple[int, int, str, str] | None:
    """(i, j, solid of i, solid of j) of the first pair of coils whose solids intersect, or
    None."""
    for (i, ci), (j, cj) in itertools.combinations(enumerate(coils), 2):
        for a in coil_solids(ci):
            for b in coil_solids(cj):
                if solids_overlap(ci.pose, a, cj.pose, b):
                    return i, j, a[0], b[0]
    return None


def check_overlap(coils) -> None:
    """Raise :class:`DesignRuleError` naming the first pair of coils whose solids intersect."""
    hit = first_overlap(coils)
    if hit is not None:
        i, j, a, b = hit
        ci, cj = coils[i], coils[j]
        raise DesignRuleError(
            f"Coils {i} and {j} overlap: the {a} of coil {i} (at "
            f"{np.round(np.asarray(ci.pose.position) * 1e3, 3).tolist()} mm) "
            f"intersects the {b} of coil {j} (at "
            f"{np.round(np.asarray(cj.pose.position) * 1e3, 3).tolist()} mm). "
            "Move them apart or make them smaller.")


SCALE_KEYS = {"grid": "pitch_m", "hex": "pitch_m", "ring": "radius_m"}
"""The key that spreads each generated layout's coils apart (m)."""


def check_layout_overlap(design, coils_of) -> None:
    """Raise :class:`DesignRuleError` in one line naming the design keys when the coils of
    ``design`` intersect: a generated layout's spreading key (:data:`SCALE_KEYS`), its value
    and the smallest value at which these coils clear each other (bisection, 1 % of it, with
    ``coils_of(design)`` building the coils); a free layout's two positions (and axes).
    """
    hit = first_overlap(coils_of(design))
    if hit is None:
        return
    i, j, a, b = hit
    what = f"the {a} of coil {i} intersects the {b} of coil {j}"
    lay = design.array
    key = SCALE_KEYS.get(lay.kind)
    if key is None:
        def vec(v):
            return [float(q) for q in v]

        axes = (f" (axes {vec(lay.axis_vectors[i])}, {vec(lay.axis_vectors[j])})"
                if lay.axis_vectors else "")
        raise DesignRuleError(
            f"array.positions_m[{i}] = {vec(lay.positions_m[i])} and array.positions_m[{j}] = "
            f"{vec(lay.positions_m[j])} m{axes}: {what}; move them apart so that no winding "
            "or core meets another.")
    value = float(getattr(lay, key))
    tilt = f" at tilt_deg = {lay.tilt_deg:g}" if lay.kind == "ring" else ""
    need = _smallest_clear(design, key, value, coils_of)
    raise DesignRuleError(
        f"array.{key} = {value:g} m{tilt}: {what}; valid range: array.{key} >= {need:.4g} m "
        f"for these coils (layout '{lay.kind}').")


def _smallest_clear(design, key: str, value: float, coils_of) -> float:
    """The smallest value of ``array.<key>`` (m) at which the coils clear each other, by
    bisection between ``value`` (they meet) and a value where they do not (1 % of it)."""
    def clear(x):
        return first_overlap(coils_of(design.replace(**{f"array.{key}": x}))) is None

    lo, hi = value, 2.0 * value
    while not clear(hi):
        lo, hi = hi, 2.0 * hi
    while hi - lo > 0.01 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if clear(mid) else (mid, hi)
    return hi


def check_separation(coils) -> None:
    """Raise :class:`DesignRuleError` naming any core that overlaps or touches another coil's
    core or winding (the coupled solve needs every core surrounded by air).

    coils : sequence of :class:`designkit.Coil` in their poses.
    """
    for i, ci in enumerate(coils):
        if ci.core is None:
            continue
        core_cyl = coil_solids(ci)[1]
        for j, cj in enumerate(coils):
            if j == i:
                continue
            # winding and core of cj; core-core pairs once (j > i)
            others = coil_solids(cj) if j > i else coil_solids(cj)[:1]
            for o in others:
                if solids_overlap(ci.pose, _grow(core_cyl), cj.pose, _grow(o)):
                    raise DesignRuleError(
                        f"The core of coil {i} (at "
                        f"{np.round(np.asarray(ci.pose.position) * 1e3, 3).tolist()} mm) "
                        f"{'overlaps or touches'} the {o[0]} of coil {j} (at "
                        f"{np.round(np.asarray(cj.pose.position) * 1e3, 3).tolist()} mm); "
                        "cores must be separated from every other coil by air. Move the coils "
                        "apart or make them smaller.")


def _grow(cyl, eps=1e-9):
    """Grow a cylinder by eps so that touching counts as overlapping."""
    name, r, z0, z1 = cyl
    return (name, r + eps, z0 - eps, z1 + eps)


def sensor_inside(coils, position) -> tuple[int, str] | None:
    """(coil index, 'winding' or 'core') of the first coil solid that holds the point
    ``position`` (3,) m in its interior or on its surface, or None."""
    p = np.asarray(position, float)[None]
    for k, c in enumerate(coils):
        loc = c.pose.to_local(p)[0]
        rho = float(np.hypot(loc[0], loc[1]))
        for name, r, z0, z1 in coil_solids(c)[::-1]:  # the core first: inside the envelope
            if rho <= r and z0 <= loc[2] <= z1:
                return k, name
    return None


def check_sensors_clear(coils, positions, key: str = "sensors") -> None:
    """Raise BadInputError naming ``key[k]`` for the first sensor position (n, 3) m that lies
    in a coil's winding or core (a Hall sensor there reads the iron's or the winding's own
    field, not the magnet's)."""
    for k, pos in enumerate(np.asarray(positions, float)):
        hit = sensor_inside(coils, pos)
        if hit is not None:
            raise BadInputError(f"{key}[{k}]", "a point outside every coil's winding and core",
                                [round(float(q), 6) for q in pos],
                                f"It lies inside the {hit[1]} of coil {hit[0]}.")
