"""Offline training of the thesis' learned inverse (section 3.2.2) for the runner's
``'learned'`` localization method: a small MLP from the largest upper-sensor field to the
magnet's position relative to that sensor, trained with scipy L-BFGS on the multipole field of
the runner's magnet model. Input: a :class:`firmware_io.localization.SensorModel`; output: a
:class:`firmware_io.localization.LearnedInverse` (``.save(path)`` writes the weights file).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize

from firmware_io.localization import LearnedInverse, multipole_field

from ..sim.readings import random_positions
from ..support import validate as v


def train_learned_inverse(model, *, n_samples: int = 20000, hidden: int = 24, seed: int = 0,
                          half_width_m: float = 0.075, z_range_m=(0.018, 0.085),
                          max_iterations: int = 3000):
    """Train the thesis' nearest-sensor inverse (a small MLP) on the magnet's field; offline.

    Samples: magnet positions uniform in |x|, |y| <= ``half_width_m``, z in ``z_range_m``; the
    input is the multipole field (the runner's magnet model, moment from the map) at the upper
    sensor where it is largest -- what the subtraction leaves in the ideal case, as the thesis
    trained on the computed dipole field -- and the target the magnet's position relative to that
    sensor. Network: features (field direction, log10 |B|) -> tanh(hidden) -> tanh(hidden) -> 3,
    outputs scaled to the training box (bounding box of the targets). Trained by scipy L-BFGS
    on the mean squared error with the analytic (backprop) gradient. The thesis used 10 x 10
    tanh layers, 1300 points, MATLAB Levenberg-Marquardt.

    Parameters
    ----------
    model : firmware_io.localization.SensorModel

    Returns
    -------
    firmware_io.localization.LearnedInverse (``.save(path)`` writes the weights file).
    """
    n_samples = v.positive_int("n_samples", n_samples)
    rng = np.random.default_rng(seed)
    pos = random_positions(n_samples, rng, z_range_m=z_range_m, half_width_m=half_width_m)
    up = model.sensor_positions_m[model.pairs[:, 0]]   # the subtraction's upper sensors
    b = np.stack([multipole_field(up, p, model.moment_a_m2, model.octupole_m2) for p in pos])
    k = np.argmax(np.linalg.norm(b, axis=-1), axis=1)
    x_b = b[np.arange(n_samples), k]
    rel = pos - up[k]
    lo, hi = rel.min(axis=0), rel.max(axis=0)
    feats = LearnedInverse.features(x_b)
    mean, std = feats.mean(axis=0), feats.std(axis=0)
    x = (feats - mean) / std
    y = (rel - 0.5 * (lo + hi)) / (0.5 * (hi - lo))
    sizes = [x.shape[1], hidden, hidden, 3]
    shapes = [(sizes[i], sizes[i + 1]) for i in range(3)]

    def unpack(theta):
        out, o = [], 0
        for a, c in shapes:
            w = theta[o:o + a * c].reshape(a, c)
            o += a * c
            out.append((w, theta[o:o + c]))
            o += c
        return out

    def loss(theta):
        ws = unpack(theta)
        hs = [x]
        for w, bias in ws[:-1]:
            hs.append(np.tanh(hs[-1] @ w + bias))
        pred = hs[-1] @ ws[-1][0] + ws[-1][1]
        err = pred - y
        f = float(np.mean(np.sum(err**2, axis=1)))
        g = 2 * err / len(x)
        grads = []
        for li in range(2, -1, -1):
            w, _ = ws[li]
            grads.append((hs[li].T @ g, g.sum(axis=0)))
            if li:
                g = (g @ w.T) * (1 - hs[li] ** 2)
        flat = []
        for gw, gb in reversed(grads):
            flat += [gw.ravel(), gb]
        return f, np.concatenate(flat)

    theta0 = np.concatenate([np.r_[rng.normal(scale=1 / math.sqrt(a), size=a * c), np.zeros(c)]
                             for a, c in shapes])
    res = minimize(loss, theta0, jac=True, method="L-BFGS-B",
                   options={"maxiter": max_iterations, "maxfun": 2 * max_iterations})
    ws = tuple((w.copy(), bias.copy()) for w, bias in unpack(res.x))
    lb = np.log10(np.linalg.norm(x_b, axis=1))
    return LearnedInverse(ws, mean, std, lo, hi, (float(lb.min()), float(lb.max())),
                          model.design_sha256)
