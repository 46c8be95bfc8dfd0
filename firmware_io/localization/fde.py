"""Single-fault tests of a fit, as GNSS RAIM does them (fault detection and exclusion):
:func:`exclusion_drops`, :func:`fault_slopes`, :func:`bounded_fault_bias`.

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
:func:`bounded_fault_bias`) the worst undetected bias is computed shape by shape; a sensor
that alone determines part of the pose (S_ii singular: no redundancy, RAIM's critical
satellite) has an infinite slope but a finite bias for bounded faults. Each statistic is
computed only when the verdict needs it (the drops when the residual test fails, the slopes for
faults of any shape, the bounded biases otherwise) from the blocks' gains C0 J_i^T
(:func:`projections`), once per solution.
References: Brown, "A baseline GPS RAIM scheme", Navigation 39 (1992); Baarda's data snooping
for vector outliers; Walter & Enge, ION GPS 1995. numpy only.
"""

from __future__ import annotations

import numpy as np

_EYE3 = np.eye(3)


def projections(jac: np.ndarray, cov0: np.ndarray) -> np.ndarray:
    """(b, 3, P): (C0 J_i^T)^T per block of a fit's whitened Jacobian ``jac`` (3 b, P) with
    ``cov0`` = (J^T J)^-1 (the gain of each block's rows on the estimate)."""
    b = len(jac) // 3
    return jac.reshape(b, 3, -1) @ cov0


def _residual_projector(jac: np.ndarray, kt: np.ndarray) -> np.ndarray:
    """S_ii = I - J_i C0 J_i^T, (b, 3, 3)."""
    jb = jac.reshape(len(kt), 3, -1)
    return _EYE3 - kt @ jb.transpose(0, 2, 1)


def exclusion_drops(jac: np.ndarray, res: np.ndarray, kt: np.ndarray) -> np.ndarray:
    """(b,): Delta_i = r_i^T S_ii^-1 r_i, the chi-square drop if block i were removed (0 where
    S_ii is singular: a block without redundancy cannot be tested)."""
    s = _residual_projector(jac, kt)
    ok = np.linalg.det(s) > 1e-9
    s_inv = np.linalg.inv(np.where(ok[:, None, None], s, _EYE3))
    rb = res.reshape(len(kt), 3)
    return np.where(ok, np.einsum("bi,bij,bj->b", rb, s_inv, rb), 0.0)


def fault_slopes(jac: np.ndarray, kt: np.ndarray, n_rot: int = 2):
    """(slope_p (b,) m, slope_u (b,) rad) per unit sqrt(noncentrality) (module docstring;
    inf where the block alone determines something: S_ii singular)."""
    s = _residual_projector(jac, kt)
    ok = np.linalg.det(s) > 1e-9
    s_inv = np.linalg.inv(np.where(ok[:, None, None], s, _EYE3))
    kp = kt[:, :, :3].transpose(0, 2, 1)
    slope_p = np.sqrt(np.maximum(np.linalg.eigvalsh(kp @ s_inv @ kt[:, :, :3])[:, -1], 0.0))
    slope_u = np.zeros(len(kt))
    if n_rot:
        ku = kt[:, :, 3:3 + n_rot]
        mu = ku.transpose(0, 2, 1) @ s_inv @ ku
        slope_u = np.sqrt(np.maximum(np.linalg.eigvalsh(mu)[:, -1], 0.0))
    return np.where(ok, slope_p, np.inf), np.where(ok, slope_u, np.inf)


def bounded_fault_bias(jac: np.ndarray, kt: np.ndarray, axis_amp: np.ndarray,
                       vector: np.ndarray, lam_md: float, n_rot: int = 2):
    """The largest position (m) and orientation (rad) bias per block that a bounded fault can
    cause while undetected, (b,), (b,). Shapes (whitened): on one axis j an error of at most
    ``axis_amp`` (b, 3) (an offset, or a gain error of that axis' reading), and the vector
    ``vector`` (b, 3) (a gain error of all three axes). A shape f scaled by a <= 1 moves the
    estimate by a C0 J_i^T f at noncentrality a^2 f^T S_ii f, so the worst undetected one is
    a = min(1, sqrt(lam_md / f^T S_ii f)); along an axis that is min(amp, sqrt(lam_md /
    S_jj)) |C0 J_i^T e_j| (monotone in the amplitude: the larger of offset and gain)."""
    b = len(kt)
    jb = jac.reshape(b, 3, -1)
    q = 3 + n_rot
    groups = _GROUPS[:q, :1 + (n_rot > 0)]
    s_diag = 1.0 - (kt * jb).sum(axis=2)
    amp = np.minimum(axis_amp, np.sqrt(lam_md / np.maximum(s_diag, 1e-300)))
    # |K_p e_j|, |K_u e_j| per block and axis (b, 3, 2): the gains' norms by group
    norms = np.sqrt(np.square(kt[:, :, :q]) @ groups)
    worst = (amp[:, :, None] * norms).max(axis=1)                      # (b, 2)
    move = (vector[:, None, :] @ kt)[:, 0]
    nc = np.einsum("bj,bj->b", vector, vector) - np.einsum(
        "bp,bp->b", move, (vector[:, None, :] @ jb)[:, 0])
    scale = np.minimum(1.0, np.sqrt(lam_md / np.maximum(nc, 1e-300)))
    np.maximum(worst, scale[:, None] * np.sqrt(np.square(move[:, :q]) @ groups), out=worst)
    return worst[:, 0], (worst[:, 1] if n_rot else np.zeros(b))


_GROUPS = np.array([[1.0, 0.0]] * 3 + [[0.0, 1.0]] * 3)
"""Sums of squares over the position (0-2) and the orientation (3-4) parameters."""
