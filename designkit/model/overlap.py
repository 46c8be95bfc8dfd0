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


def check_overlap(coils) -> None:
    """Raise :class:`DesignRuleError` naming the first pair of coils whose solids intersect."""
    for (i, ci), (j, cj) in itertools.combinations(enumerate(coils), 2):
        for a in coil_solids(ci):
            for b in coil_solids(cj):
                if solids_overlap(ci.pose, a, cj.pose, b):
                    raise DesignRuleError(
                        f"Coils {i} and {j} overlap: the {a[0]} of coil {i} (at "
                        f"{np.round(np.asarray(ci.pose.position) * 1e3, 3).tolist()} mm) "
                        f"intersects the {b[0]} of coil {j} (at "
                        f"{np.round(np.asarray(cj.pose.position) * 1e3, 3).tolist()} mm). "
                        "Move them apart or make them smaller.")


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
        for name, r, z0, z1 in coil_solids(c):
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
