"""The solved bound surface currents of one core and their field, anywhere.

A :class:`CoreSolution` holds the azimuthal surface current density K (A/m) on the side
panels (current sheets at r = radius) and the annular face / slice-interface panels of a core,
in the local frame of the winding that drives it. Its field is evaluated per point and per
source group by the cheapest quadrature whose error bound holds there
(:mod:`designkit.cores.quadrature`; derivation in docs/core_model.md, "Field evaluation");
its flux linkage with a winding is the reciprocal mutual inductance, ring by ring.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..constants import MU0
from ..errors import BadInputError
from ..field.kernels import loop_rz
from ..geometry.winding import WindingGeometry
from . import quadrature as q
from .material import KNEE_T
from .saturation import SaturationWarning


@dataclass(frozen=True)
class CoreSolution:
    """Bound azimuthal surface currents of a solved core (A/m), in the winding's local frame.

    ``side_*``: current-sheet panels at r = radius spanning [z_lo, z_hi]; ``disc_*``: annular
    panels in planes z with [r_lo, r_hi]; ``k_*`` the azimuthal surface current density.
    """

    radius: float
    side_z_lo: np.ndarray
    side_z_hi: np.ndarray
    k_side: np.ndarray
    disc_z: np.ndarray
    disc_r_lo: np.ndarray
    disc_r_hi: np.ndarray
    k_disc: np.ndarray
    peak_b: float
    linear_model: bool = True
    model: str = "surface-current"

    def scaled(self, factor: float, core) -> "CoreSolution":
        """These currents times ``factor``, flagged by the model of ``core`` (a Core)."""
        return CoreSolution(self.radius, self.side_z_lo, self.side_z_hi, self.k_side * factor,
                            self.disc_z, self.disc_r_lo, self.disc_r_hi, self.k_disc * factor,
                            abs(self.peak_b * factor), core.bh == "linear" or
                            core.model == "thesis-uniform", core.model)

    def warn_if_saturated(self, knee_t: float = KNEE_T) -> None:
        """Warn :class:`SaturationWarning` when a linear model's peak |B| passes ``knee_t`` (T)."""
        if self.linear_model and self.peak_b > knee_t:
            warnings.warn(
                f"core flux density {self.peak_b:.2f} T exceeds the {knee_t:g} T knee of "
                "low-carbon steel: the linear core model overestimates the field; for the "
                "saturating B-H curve use Core(bh='steel1010') or, in a design file, "
                "[core] bh = \"steel1010\"", SaturationWarning, stacklevel=4)

    def currents_rz(self, rho, z, gradient):
        """Sum of all panels' fields per mu0 at (rho, z): list of the 2 or 7 rz components."""
        return q.panels_rz(self, np.arange(len(self.k_side)), np.arange(len(self.k_disc)),
                           rho, z, gradient)

    def field(self, points_local: np.ndarray, *, gradient: bool = False,
              rule: Literal["auto", "panels"] = "auto"):
        """B (n, 3) T [, G (n, 3, 3) T/m] of the bound currents at local Cartesian points.

        ``rule='auto'``: for every point and every *source group* (three stretches of the side,
        each end face or slice interface) the cheapest quadrature whose error bound holds at
        that point is used (docs/core_model.md, "Field evaluation"): a compressed product rule
        of 4-24 rings per group when the point is far from the group *in units of the group's
        own length*, else the group's exact panels (side: closed-form current sheets; faces:
        Gauss rules of loops, refined geometrically towards the point's projection when the
        point is near the panel). ``'panels'`` always sums the panels (with the same near
        refinement): the reference for the compressed rules.
        """
        p = np.asarray(points_local, dtype=float)
        rho = np.hypot(p[:, 0], p[:, 1])
        z = p[:, 2]
        if rule not in ("auto", "panels"):
            raise BadInputError("rule", "'auto' or 'panels'", rule)
        if rule == "panels" or len(self.k_disc) == 0:
            comps = self.currents_rz(rho, z, gradient)
            return q.rz_to_xyz(p, rho, comps, gradient, MU0)
        comps = [np.zeros(len(z)) for _ in range(7 if gradient else 2)]
        rings = ([], [], [], [])  # point index, ring r, ring z, ring current
        for grp in self.groups():
            self._add_group(grp, rho, z, gradient, comps, rings)
        if rings[0]:
            pt, ring_r, ring_z, ww = (np.concatenate(a) for a in rings)
            res = loop_rz(ring_r, rho[pt], z[pt] - ring_z, gradient=gradient)
            for c in range(len(comps)):
                comps[c] += np.bincount(pt, weights=res[c] * ww, minlength=len(z))
        return q.rz_to_xyz(p, rho, comps, gradient, MU0)

    def _add_group(self, grp, rho, z, gradient, comps, rings):
        """One source group: the points its compressed rules serve go to ``rings`` (summed
        later in one kernel call), the others get its panels added to ``comps`` now."""
        # singularity of the kernel as a function of the source coordinate: where the
        # source ring would pass through the point (complex for points off the contour)
        if grp["kind"] == "side":
            s = z + 1j * np.abs(self.radius - rho)
        else:
            s = rho + 1j * np.abs(z - grp["fixed"])
        bound_rho = q.usable_rho(grp["lo"], grp["hi"], s)
        # a face's kernel grows like r'^2 (its dipole moment) off the interval: its size on
        # the ellipse exceeds that on [0, R] by up to the Chebyshev growth ((rho+1/rho)/2)^2
        growth = (0.5 * (bound_rho + 1.0 / bound_rho)) ** 2 if grp["kind"] == "disc" else 1.0
        todo = np.ones(len(z), dtype=bool)
        for nodes in q.FAR_NODES:
            sel = todo & (q.interp_bound(bound_rho, nodes) * grp["cancel"] * growth
                          <= q.EVAL_RTOL)
            if not np.any(sel):
                continue
            todo &= ~sel
            rq, zq, wq = self._rule(grp, nodes)
            idx = np.flatnonzero(sel)
            rings[0].append(np.repeat(idx, len(rq)))
            rings[1].append(np.tile(rq, len(idx)))
            rings[2].append(np.tile(zq, len(idx)))
            rings[3].append(np.tile(wq, len(idx)))
        if np.any(todo):
            idx = np.flatnonzero(todo)
            near = q.panels_rz(self, grp["side"], grp["disc"], rho[idx], z[idx], gradient)
            for c in range(len(comps)):
                comps[c][idx] += near[c]

    def _rule(self, grp: dict, nodes: int):
        """The group's product rule with ``nodes`` rings (built on first use, cached)."""
        rule = grp["rules"].get(nodes)
        if rule is None:
            if grp["kind"] == "side":
                i = grp["side"]
                rule = q.product_rule(self.side_z_lo[i], self.side_z_hi[i], self.k_side[i],
                                      grp["lo"], grp["hi"], nodes, "side", self.radius)
            else:
                i = grp["disc"]
                rule = q.product_rule(self.disc_r_lo[i], self.disc_r_hi[i], self.k_disc[i],
                                      grp["lo"], grp["hi"], nodes, "disc", grp["fixed"])
            grp["rules"][nodes] = rule
        return rule

    def groups(self) -> list[dict]:
        """Source groups of the compressed rule (cached on the instance).

        Each: ``kind`` ('side' or 'disc'), source-coordinate interval ``lo``, ``hi`` (z for the
        side, r for a face), ``fixed`` (the face's z), the panel indices ``side`` / ``disc`` it
        covers, ``cancel`` (:func:`designkit.cores.quadrature.cancellation`) and ``rules``:
        {nodes: (r, z, current per ring)} product rules filled on first use by :meth:`_rule`
        (the loop field interpolated at Gauss nodes, the piecewise-constant K with its rim
        singularity integrated exactly in the weights).
        """
        cached = self.__dict__.get("_groups")
        if cached is not None:
            return cached
        out = self._side_groups() + self._face_groups()
        object.__setattr__(self, "_groups", out)  # frozen dataclass: cache the derived rules
        return out

    def _side_groups(self) -> list[dict]:
        """The side in stretches: the two ends and a middle cut into pieces <= 4 radii."""
        lo, hi = float(self.side_z_lo.min()), float(self.side_z_hi.max())
        length = hi - lo
        end = min(0.15 * length, 2 * self.radius)
        # group edges on panel edges, so a group that falls back to panels owns whole panels
        edges = np.unique(np.concatenate([self.side_z_lo, self.side_z_hi]))
        # middle stretch cut into pieces <= 4 radii: a group's length sets how far away a
        # point must be for its compressed rule, so shorter groups serve nearer points
        n_mid = max(1, int(math.ceil((length - 2 * end) / (4 * self.radius))))
        want = np.concatenate([[lo], lo + end + (length - 2 * end) * np.arange(n_mid + 1)
                               / n_mid, [hi]])
        cut = sorted(set(float(edges[np.argmin(np.abs(edges - c))]) for c in want))
        out = []
        mid = 0.5 * (self.side_z_lo + self.side_z_hi)
        for a, b in zip(cut[:-1], cut[1:]):
            sel = np.flatnonzero((mid > a) & (mid < b))
            out.append({"kind": "side", "lo": a, "hi": b, "fixed": self.radius, "side": sel,
                        "disc": np.zeros(0, dtype=int),
                        "cancel": q.cancellation(self.k_side[sel], self.side_z_hi[sel]
                                                 - self.side_z_lo[sel]),
                        "rules": {}})
        return out

    def _face_groups(self) -> list[dict]:
        """One group per end face or slice interface."""
        out = []
        for zp in np.unique(self.disc_z):
            sel = np.flatnonzero(self.disc_z == zp)
            r_lo = float(self.disc_r_lo[sel].min())
            r_hi = float(self.disc_r_hi[sel].max())
            # a face's far field is that of its dipole moment: weights ~ r^2 dr
            mom = (self.disc_r_hi[sel] ** 3 - self.disc_r_lo[sel] ** 3) / 3.0
            out.append({"kind": "disc", "lo": r_lo, "hi": r_hi, "fixed": float(zp),
                        "side": np.zeros(0, dtype=int), "disc": sel,
                        "cancel": max(q.cancellation(self.k_disc[sel], mom),
                                      q.cancellation(self.k_disc[sel], self.disc_r_hi[sel]
                                                     - self.disc_r_lo[sel])),
                        "rules": {}})
        return out

    def flux_linkage(self, winding) -> float:
        """Flux linkage of these currents with the winding, Wb (per the winding's turns).

        ``winding``: a :class:`designkit.geometry.winding.WindingGeometry` (or a Coil)."""
        geo = WindingGeometry.of(winding)
        total = 0.0
        xg, wg = np.polynomial.legendre.leggauss(4)
        if len(self.k_side):
            h = 0.5 * (self.side_z_hi - self.side_z_lo)
            c = 0.5 * (self.side_z_hi + self.side_z_lo)
            zq = (c[:, None] + h[:, None] * xg[None, :]).ravel()
            wq = (h[:, None] * wg[None, :]).ravel() * np.repeat(self.k_side, len(xg))
            phi = geo.disc_flux(np.full_like(zq, self.radius), zq)
            total += float(np.sum(wq * phi))
        if len(self.k_disc):
            h = 0.5 * (self.disc_r_hi - self.disc_r_lo)
            c = 0.5 * (self.disc_r_hi + self.disc_r_lo)
            rq = (c[:, None] + h[:, None] * xg[None, :]).ravel()
            zq = np.repeat(self.disc_z, len(xg))
            wq = (h[:, None] * wg[None, :]).ravel() * np.repeat(self.k_disc, len(xg))
            phi = geo.disc_flux(rq, zq)
            total += float(np.sum(wq * phi))
        return total
