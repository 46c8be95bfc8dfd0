"""TEST DOUBLE, not a localizer: an N-magnet "estimator" that returns the TRUE positions (read
from the trajectory at the frame's time) plus Gaussian noise, with the interface the N-magnet
estimator of firmware_io.localization provides (its MagnetsEstimate; docs/runner.md, "Several
magnets"). It tests the runner's and the simulator's N-magnet paths with a known localization
error; it is never shipped (it lives in tests/ and reads the simulation's truth)."""

from __future__ import annotations

import math

import numpy as np

from firmware_io.localization import Estimate, EstimatorSettings, MagnetsEstimate


class TruthPlusNoiseMagnets:
    """TEST DOUBLE (module docstring). ``truth(t_s) -> (N, 3)`` m; ``moments`` (N, 3) A m^2;
    ``noise_m`` rms per axis; ``untrusted(t_s) -> set of magnet indices`` not trusted then
    (default none)."""

    settings = EstimatorSettings(model_bias_m=0.0)
    calibration = None

    def __init__(self, truth, moments, noise_m: float = 2e-4, seed: int = 0, untrusted=None):
        self.truth = truth
        self.moments = np.asarray(moments, float)
        self.noise_m = float(noise_m)
        self.rng = np.random.default_rng(seed)
        self.untrusted = untrusted if untrusted is not None else (lambda t: set())
        self.resets = 0
        self.seeds_seen: list = []

    def reset(self):
        self.resets += 1

    def estimate(self, readings_t, currents_a=None, *, usable=None, seeds=None, time_s=None):
        self.seeds_seen.append(None if seeds is None else [s is not None for s in seeds])
        p = np.asarray(self.truth(time_s), float)
        bad = self.untrusted(time_s)
        sd = self.noise_m
        out = []
        for k in range(len(p)):
            ok = k not in bad
            q = p[k] + self.rng.normal(scale=sd, size=3)
            out.append(Estimate(q, self.moments[k].copy(), ok, "" if ok else "test: untrusted",
                                np.eye(3) * sd * sd, 6 * sd if ok else math.inf,
                                consistent=ok, fault_free_protection_level_m=6 * sd,
                                prior_used=seeds is not None and seeds[k] is not None))
        return MagnetsEstimate(tuple(out), consistent=True)
