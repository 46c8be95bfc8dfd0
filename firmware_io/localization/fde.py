"""Single-fault tests of a fit, as GNSS RAIM does them (fault detection and exclusion):
:func:`block_statistics`.

A fault is one observation block (a sensor: its 3 axes) reading a wrong value. At the fit's
solution, with J the whitened Jacobian (3 b rows, P unknowns), r the whitened residual and
C0 = (J^T J)^-1, the residual projector is S = I - J C0 J^T; block i's 3 x 3 part is
S_ii = I - J_i C0 J_i^T. A fault f (whitened) in block i

- adds f^T S_ii f to the chi-square statistic's noncentrality, and removing block i lowers the
  statistic by Delta_i = r_i^T S_ii^-1 r_i (exactly for a linear model: the exclusion test);
- moves the estimate by C0 J_i^T f, so its position part K_i f (K_i: the position rows of
  C0 J_i^T) is at most slope_i sqrt(noncentrality), slope_i^2 = l_max(K_i S_ii^-1 K_i^T) (the
  same with the orientation rows).

The undetected-fault protection level is max_i slope_i sqrt(lam_md), lam_md the noncentrality
the test misses with probability p_md (:func:`.integrity.missed_detection_noncentrality`), for a
fault of any shape. For faults of known shapes and bounds (an offset on one axis, a gain error:
:func:`gain_and_offset_bias`) the worst undetected bias is computed shape by shape; a sensor
that alone determines part of the pose (S_ii singular: no redundancy, RAIM's critical
satellite) has an infinite slope but a finite bias for bounded faults.
References: Brown, "A baseline GPS RAIM scheme", Navigation 39 (1992); Baarda's data snooping
for vector outliers; Walter & Enge, ION GPS 1995. numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BlockStatistics:
    """Per block of a fit: ``delta`` (b,) the chi-square drop if it were removed, ``slope_p``
    (b,) m and ``slope_u`` (b,) rad per unit sqrt(noncentrality) (inf where the block is the
    only one that determines something: S_ii singular)."""

    delta: np.ndarray
    slope_p: np.ndarray
    slope_u: np.ndarray


def block_statistics(jac: np.ndarray, res: np.ndarray, cov0: np.ndarray,
                     n_rot: int = 2) -> BlockStatistics:
    """The single-block statistics (module docstring) of a fit: ``jac`` (3 b, P) whitened
    Jacobian, ``res`` (3 b,) whitened residual, ``cov0`` (P, P) = (J^T J)^-1; the position is
    the first three unknowns, the moment direction the next ``n_rot`` (2, or 0 when fixed)."""
    b = len(res) // 3
    jb = jac.reshape(b, 3, -1)
    k = np.einsum("pq,bjq->bpj", cov0, jb)                     # C0 J_i^T: (b, P, 3)
    s = np.eye(3) - np.einsum("bip,bpj->bij", jb, k)
    # a block that alone determines some combination has S_ii singular: no redundancy
    ok = np.linalg.det(s) > 1e-9
    s_inv = np.linalg.inv(np.where(ok[:, None, None], s, np.eye(3)))
    rb = res.reshape(b, 3)
    delta = np.einsum("bi,bij,bj->b", rb, s_inv, rb)
    kp, ku = k[:, :3], k[:, 3:3 + n_rot]
    mp = np.einsum("bij,bjk,blk->bil", kp, s_inv, kp)
    slope_p = np.sqrt(np.maximum(np.linalg.eigvalsh(mp)[:, -1], 0.0))
    slope_u = np.zeros(b)
    if n_rot:
        mu = np.einsum("bij,bjk,blk->bil", ku, s_inv, ku)
        slope_u = np.sqrt(np.maximum(np.linalg.eigvalsh(mu)[:, -1], 0.0))
    inf = np.full(b, np.inf)
    return BlockStatistics(np.where(ok, delta, 0.0), np.where(ok, slope_p, inf),
                           np.where(ok, slope_u, inf))


def gain_and_offset_bias(jac: np.ndarray, cov0: np.ndarray, shapes: np.ndarray,
                         lam_md: float, n_rot: int = 2):
    """The largest position (m) and orientation (rad) bias per block that a fault of the given
    shapes can cause while undetected: shapes (b, s, 3) whitened fault vectors (their
    largest magnitudes); a shape f scaled by a <= 1 moves the estimate by a C0 J_i^T f at
    noncentrality a^2 f^T S_ii f, so the worst undetected one is a = min(1, sqrt(lam_md /
    f^T S_ii f)). Returns (b,), (b,)."""
    b = len(shapes)
    jb = jac.reshape(b, 3, -1)
    k = np.einsum("pq,bjq->bpj", cov0, jb)                      # (b, P, 3)
    s = np.eye(3) - np.einsum("bip,bpj->bij", jb, k)
    nc = np.einsum("bsi,bij,bsj->bs", shapes, s, shapes)
    scale = np.minimum(1.0, np.sqrt(lam_md / np.maximum(nc, 1e-300)))
    move = np.einsum("bpj,bsj->bsp", k, shapes) * scale[..., None]       # (b, s, P)
    dp = np.sqrt(np.einsum("bsp,bsp->bs", move[..., :3], move[..., :3])).max(axis=1)
    rot = move[..., 3:3 + n_rot]
    du = np.sqrt(np.einsum("bsp,bsp->bs", rot, rot)).max(axis=1)
    return dp, du
