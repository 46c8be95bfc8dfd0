"""The magnet's pose from one frame: :class:`PoseFit`, shared by the 'model' and 'dipole'
estimators.

Unknowns: the position p (3, m), the moment direction u (2: rotations about its tangent axes,
:mod:`.pose`), optionally log |m| (calibration), a uniform background field b (3, T) and, when
the data call for it, its gradient (5, T/m: symmetric and traceless). The model of a sensor's
field (array frame) is the magnet's multipole with its analytic Jacobians (:mod:`.magnet`), plus
the linearized corrections (exact cylinder, magnet-induced cores: :mod:`.corrections`), plus
b + G (x - x0). Observation blocks are the sensors ('model': readings minus the coils' field at
the frame's currents) or the subtracted (upper, lower) pairs ('dipole'). Levenberg-Marquardt on
the whitened residual (sigma^2 = noise^2 + lsb^2 / 12 + (relative_error |B|)^2 + the
calibration's own variance); a warm start from a prior pose, a cold one from the global search
(:mod:`.search`). Integrity (:mod:`.fix`): the chi-square test, single-sensor fault exclusion
and the undetected-fault protection levels (:mod:`.fde`), the gradient when the data call for
it. Derivations and measured accuracy: docs/localization.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import BadInputError
from .calibration import SensorCalibration
from .corrections import Corrections
from .integrity import (chi2_quantile, missed_detection_noncentrality, ratio_quantiles,
                        thresholds)
from .levenberg import levenberg_marquardt
from .magnet import MU0, multipole_pose_columns
from .pose import rotated, tangent_axes
from .search import GridSearch
from .sensor_model import SensorModel
from .settings import EstimatorSettings


PRIOR_ITERATIONS = 6
"""Iterations of a solve from a prior (a frame that agrees with it converges in 2-4; one that
does not is dragged by a liar, or the prior is wrong)."""

COLD_ITERATIONS = 20
"""Iterations of a cold start's multipole solve (a good start converges in 3-15)."""

_ONE = np.ones(1)


@dataclass(frozen=True)
class State:
    """A pose and the room: position p (3,) m, unit moment u (3,), log_scale (|m| / the
    model's), background b (3,) T, gradient g (5,) T/m or None (not fitted)."""

    p: np.ndarray
    u: np.ndarray
    log_scale: float
    b: np.ndarray
    g: np.ndarray | None


@dataclass(frozen=True)
class Solution:
    """A converged (or abandoned) solve: its state (a :class:`State`, or the several-magnet
    fit's joint state), whitened Jacobian (3 b + prior rows, P) and residual at it, the used
    blocks (sensors), chi2, converged, iterations."""

    state: Any
    jac: np.ndarray
    res: np.ndarray
    blocks: np.ndarray
    chi2: float
    converged: bool
    iterations: int


def gradient_columns(points: np.ndarray) -> np.ndarray:
    """(n, 3, 5): d(G x)/dg for G symmetric traceless, g = (Gxx, Gxy, Gxz, Gyy, Gyz), x the
    points relative to their centroid."""
    x = points - points.mean(axis=0)
    cols = np.zeros((len(x), 3, 5))
    cols[:, 0, 0], cols[:, 2, 0] = x[:, 0], -x[:, 2]
    cols[:, 0, 1], cols[:, 1, 1] = x[:, 1], x[:, 0]
    cols[:, 0, 2], cols[:, 2, 2] = x[:, 2], x[:, 0]
    cols[:, 1, 3], cols[:, 2, 3] = x[:, 1], -x[:, 2]
    cols[:, 1, 4], cols[:, 2, 4] = x[:, 2], x[:, 1]
    return cols


class PoseFit:
    """The pose fit of one sensor model (module docstring).

    Parameters
    ----------
    model : SensorModel
    settings : EstimatorSettings
    calibration : SensorCalibration, (gain_inverse (n, 3, 3), offsets_t (n, 3)) or None
    subtract : bool -- observation blocks are the model's (upper, lower) pairs
    """

    def __init__(self, model: SensorModel, settings: EstimatorSettings, calibration=None, *,
                 subtract: bool = False):
        self.model, self.settings = model, settings
        n = model.n_sensors
        self.calibration = (None if calibration is None
                            else SensorCalibration.coerce(calibration, n, model.n_coils))
        cal = self.calibration
        calibrated = cal is not None
        self.rel = settings.relative_error_for(calibrated)
        self.bias_m = settings.model_bias_for(calibrated)
        self.bias_rad = settings.model_bias_rad_for(calibrated)
        self.pts = model.sensor_positions_m + (cal.shift_m if calibrated else 0.0)
        # a reading r (sensor frame) to the array frame: R G^-1 (r - o) = M r - M o
        rot = model.sensor_orientations
        self.to_array = rot @ cal.gain_inverse if calibrated else rot.copy()
        self.to_array_offset = (np.einsum("sij,sj->si", self.to_array, cal.offsets_t)
                                if calibrated else np.zeros((n, 3)))
        self.coil = (cal.coil_field_t_per_a if calibrated and cal.coil_field_t_per_a is not None
                     else model.coil_field_t_per_a)
        self.resp = (settings.variance_floor_t2 * cal.response_design_inverse
                     if calibrated and cal.response_design_inverse is not None else None)
        self.moment = float(np.linalg.norm(model.moment_a_m2))
        self.c = self.moment / (4 * math.pi)
        self.k = 0.5 * self.c * model.octupole_m2
        self.lo, self.hi = np.asarray(model.box_lower_m, float), np.asarray(model.box_upper_m, float)
        self._observation(subtract)
        cores = (model.induced is not None) if settings.cores is None else settings.cores
        if cores and model.induced is None:
            raise BadInputError("cores", "False (the model carries no induced core field)", cores)
        self.corr = Corrections(self.pts, model, exact=model.magnet_size_m is not None,
                                cores=bool(cores), noise_t=settings.noise_t,
                                first_radius_m=settings.refresh_m,
                                fixed_direction=settings.orientation == "fixed")
        self.background = settings.background == "uniform"
        self.bg_basis = self._background_basis() if self.background else np.zeros((3, 0))
        self.bg_identity = self.bg_basis.shape == (3, 3) and bool(np.all(self.bg_basis
                                                                          == np.eye(3)))
        self.search = GridSearch(self.pts, self.op, self.lo, self.hi, self.moment,
                                 self.bg_basis)
        self.bcols = np.tile(self.bg_basis, (n, 1, 1))
        self.gcols = gradient_columns(self.pts)
        self.fit_scale = settings.fit_moment_magnitude
        self.n_rot = 2 if settings.orientation == "fit" else 0
        rows = 3 * self.n_blocks
        self.chi2_max = thresholds(settings.false_alarm, rows)
        self.k2 = ratio_quantiles(settings.integrity_risk)
        self.gradient_drop = chi2_quantile(settings.false_alarm, 5)
        self.lam_md = [0.0] + [missed_detection_noncentrality(
            settings.false_alarm, settings.missed_detection, d) for d in range(1, rows + 1)]
        self.last: State | None = None
        self.prior = None

    def set_prior(self, seed) -> None:
        """Use ``seed`` (a :class:`Pose` with a ``covariance``) as five more observations of the
        pose in the next solves: (p - p0, e1.u, e2.u) whitened by the covariance's inverse
        square root (e1, e2 the seed's tangent axes); None or no covariance: no prior."""
        if seed is None or seed.covariance is None:
            self.prior = None
            return
        k = 3 + self.n_rot
        cov = np.asarray(seed.covariance, float)[:k, :k]
        info = np.linalg.cholesky(np.linalg.inv(cov)).T          # info^T info = cov^-1
        u0 = np.asarray(seed.moment_a_m2, float)
        u0 = u0 / math.sqrt(float(u0 @ u0))
        p0, axes0 = np.asarray(seed.position_m, float), tangent_axes(u0)
        info_p = info[:, :3].copy()
        # info (p - p0, axes0 . u) = info_p (p - p0) + info_u u (:meth:`rows`)
        info_u = info[:, 3:] @ axes0 if self.n_rot else None
        self.prior = (p0, axes0, info, info_p, info_u)

    def _observation(self, subtract: bool) -> None:
        """The observation blocks: each sensor, or each (upper, lower) pair with the lower
        sensor's coil field mapped onto the upper one's (P = C_u C_l^+; for the symmetric
        array diag(-1, -1, 1): Br is odd about the coils' mid-plane)."""
        n = self.model.n_sensors
        if not subtract:
            self.op, self.pairs, self.mirror = None, None, None
            self.block_sensors = [(s,) for s in range(n)]
            return
        pairs = self.model.pairs
        self.pairs = pairs
        self.mirror = np.stack([self.coil[a] @ np.linalg.pinv(self.coil[b]) for a, b in pairs])
        op = np.zeros((len(pairs), 3, n, 3))
        for j, (a, b) in enumerate(pairs):
            op[j, :, a] = np.eye(3)
            op[j, :, b] = -self.mirror[j]
        self.op = op
        self.block_sensors = [(int(a), int(b)) for a, b in pairs]

    def _background_basis(self) -> np.ndarray:
        """(3, k): the uniform field's directions the blocks see (all three for sensors; the
        subtraction cancels what the mirror maps onto itself, e.g. B_z for P = diag(-1, -1,
        1))."""
        if self.op is None:
            return np.eye(3)
        t = self.op.sum(axis=2).reshape(-1, 3)
        _, sv, vt = np.linalg.svd(t, full_matrices=False)
        return vt[sv > 1e-6 * sv[0]].T

    @property
    def n_blocks(self) -> int:
        return len(self.block_sensors)

    # -- data ------------------------------------------------------------------------------
    def corrected(self, readings: np.ndarray) -> np.ndarray:
        """(n, 3) T readings, each in its sensor's frame, as the field in the array frame:
        R (gain_inverse @ (r - offset)) with the calibration, R r without."""
        return np.einsum("sij,sj->si", self.to_array, readings) - self.to_array_offset

    def data(self, field: np.ndarray, currents: np.ndarray | None):
        """(d (b, 3) T, usable (b,), sigma (b,) T, reading (b, 3) T) of the blocks from the
        field (n, 3) T (array frame): the field minus the coils' at ``currents`` per sensor,
        or the subtracted pairs (``currents`` None); ``reading`` is the field a gain error
        would scale (the sensor's, or the subtracted pair's)."""
        sig2n = self.settings.variance_floor_t2
        mag2 = np.einsum("si,si->s", field, field)
        if self.op is None:
            d = field - self.coil @ currents
            s2 = sig2n + self.rel ** 2 * mag2
            if self.resp is not None:
                x = np.concatenate((currents, _ONE))
                s2 = s2 + (self.resp @ x) @ x
        else:
            up, lo = self.pairs[:, 0], self.pairs[:, 1]
            d = field[up] - np.matmul(self.mirror, field[lo][..., None])[..., 0]
            s2 = 2 * sig2n + self.rel ** 2 * (mag2[up] + mag2[lo])
        if self.settings.mount_position_m:
            s2 = s2 + self._mount_variance(d)
        use = np.isfinite(d.sum(1))      # a row sum is NaN when any component is
        reading = field if self.op is None else d
        return np.where(use[:, None], d, 0.0), use, np.sqrt(s2), reading

    def _mount_variance(self, d):
        """Variance from the sensors' position uncertainty: |dB| ~ 3 |B| dr / r for the magnet's
        field, with r from |B| (on-axis dipole: |B| = mu0 |m| / (2 pi r^3))."""
        b = np.linalg.norm(np.nan_to_num(d), axis=-1)
        r = np.cbrt(MU0 * self.moment / (2 * math.pi * np.maximum(b, 1e-9)))
        return (3 * self.settings.mount_position_m * b / r) ** 2

    def explained_without_magnet(self, d: np.ndarray, w_all: np.ndarray) -> bool:
        """Do the blocks' data d (b, 3) T (weights w = 1 / sigma, 0 where unusable) pass the
        residual test with no magnet: a uniform background alone (its observable directions,
        when fitted), else nothing? Needs at least two usable blocks."""
        use = w_all > 0
        n_use = int(use.sum())
        if n_use < 2:
            return False
        wd = (d[use] * w_all[use, None]).reshape(-1)
        k = self.bg_basis.shape[1]
        if k:
            jac = (np.broadcast_to(self.bg_basis, (n_use, 3, k)) if self.op is None
                   else self.op.sum(axis=2)[use] @ self.bg_basis) * w_all[use, None, None]
            jac = jac.reshape(-1, k)
            coef, *_ = np.linalg.lstsq(jac, wd, rcond=None)
            wd = wd - jac @ coef
        dof = 3 * n_use - k
        return bool(float(wd @ wd) <= self.chi2_max[dof])

    # -- the model and its Jacobian ----------------------------------------------------------
    def n_unknowns(self, gradient: bool) -> int:
        return 3 + self.n_rot + self.fit_scale + self.bg_basis.shape[1] + 5 * gradient

    def rows(self, st: State, blocks: np.ndarray, w: np.ndarray, d: np.ndarray,
             corrected: bool = True):
        """Whitened Jacobian (3 b, P) and residual (3 b,) of the used ``blocks`` at ``st``
        (weights w = 1 / sigma of those blocks, data d of those blocks); with a prior
        (:meth:`set_prior`) its rows follow."""
        p, u = st.p, st.u
        scale = math.exp(st.log_scale) if st.log_scale else 1.0
        axes = tangent_axes(u)
        n, nb = len(self.pts), len(blocks)
        n_par = self.n_unknowns(st.g is not None)
        kp = 0 if self.prior is None else 3 + self.n_rot
        jac = np.empty((3 * nb + kp, n_par))
        direct = self.op is None and nb == n        # every sensor a block: fill jac in place
        cols = jac[:3 * n].reshape(n, 3, n_par) if direct else np.empty((n, 3, n_par))
        pose = cols if self.n_rot else np.empty((n, 3, 5))
        b = multipole_pose_columns(self.pts - p, u, axes, self.c * scale, self.k * scale, pose)
        if not self.n_rot:
            cols[:, :, :3] = pose[:, :, :3]
        if corrected and self.corr.active:
            self.corr.add_to(b, cols, p, u, axes if self.n_rot else None, scale)
        j = 3 + self.n_rot
        if self.fit_scale:
            cols[:, :, j] = b
            j += 1
        f = b
        if self.background:
            k = self.bg_basis.shape[1]
            cols[:, :, j:j + k] = self.bg_basis
            f += st.b
            j += k
        if st.g is not None:
            cols[:, :, j:j + 5] = self.gcols
            f += self.gcols @ st.g
        res = np.empty(3 * nb + kp)
        if direct:
            cols *= w[:, None, None]
            res[:3 * n] = ((d - f) * w[:, None]).reshape(-1)
        else:
            if self.op is not None:
                cols = np.einsum("kisj,sjq->kiq", self.op, cols)
                f = np.einsum("kisj,sj->ki", self.op, f)
            jac[:3 * nb] = (cols[blocks] * w[:, None, None]).reshape(3 * nb, n_par)
            res[:3 * nb] = ((d - f[blocks]) * w[:, None]).reshape(-1)
        if kp:
            # the prior's rows info (p - p0, axes0 . u) = info_p (p - p0) + info_u u
            p0, _, _, info_p, info_u = self.prior
            top = jac[3 * nb:]
            top[:, :3] = info_p
            res[3 * nb:] = info_p @ (p0 - p)
            if self.n_rot:
                top[:, 3:5] = info_u @ axes.T
                res[3 * nb:] -= info_u @ u
            top[:, kp:] = 0.0
        return jac, res

    def step(self, st: State, delta: np.ndarray) -> State:
        """The state moved by the solve's step ``delta`` (position kept inside the box)."""
        p = np.minimum(np.maximum(st.p + delta[:3], self.lo), self.hi)
        j = 3 + self.n_rot
        u = rotated(st.u, tangent_axes(st.u), delta[3:5]) if self.n_rot else st.u
        log_scale = st.log_scale
        if self.fit_scale:
            log_scale += float(delta[j])
            j += 1
        b = st.b
        if self.background:
            k = self.bg_basis.shape[1]
            b = st.b + (delta[j:j + 3] if self.bg_identity else self.bg_basis @ delta[j:j + k])
            j += k
        g = None if st.g is None else st.g + delta[j:j + 5]
        return State(p, u, log_scale, b, g)

    # -- solving ---------------------------------------------------------------------------
    def solve(self, st: State, blocks, w, d, corrected: bool = True,
              first: tuple | None = None, max_iterations: int | None = None,
              give_up=None) -> Solution:
        """Levenberg-Marquardt from ``st`` on the used blocks (:func:`.levenberg.
        levenberg_marquardt`, with its quadratic-convergence stop): converged when the
        Gauss-Newton step would lower chi2 by < :data:`.levenberg.CONVERGED_GAIN` (a step below
        1/20 of the estimate's own noise, Mahalanobis) or the step after it would by a tenth
        of that. ``first``: the rows at ``st`` when the caller has them; ``max_iterations``
        (default the settings'); ``give_up``: the test that abandons a hopeless solve (None:
        never; :func:`.levenberg.levenberg_marquardt`)."""
        def rows(state):
            return self.rows(state, blocks, w, d, corrected)

        out = levenberg_marquardt(st, rows, self.step, first if first is not None else rows(st),
                                  max_iterations or self.settings.max_iterations,
                                  quadratic=True, give_up=give_up)
        return Solution(out.state, out.jac, out.res, blocks, out.chi2, out.converged,
                        out.iterations)

    def solve_corrected(self, st: State, blocks, w, d, first: tuple | None = None,
                        max_iterations: int | None = None, give_up=None
                        ) -> Solution:
        """:meth:`solve` with the corrections linearized near the pose, re-linearized (at most
        4 times) until the solution stays within twice their reuse radius. ``first``: the rows
        at ``st`` with the corrections as they are linearized now; ``max_iterations`` per
        solve (default the settings'), ``give_up`` as :meth:`solve`'s."""
        if not self.corr.active:
            return self.solve(st, blocks, w, d, corrected=False, first=first,
                              max_iterations=max_iterations, give_up=give_up)
        iterations = 0
        for _ in range(5):
            if first is None or not self.corr.within(st.p, st.u):
                self.corr.update(st.p, st.u)
                first = None
            sol = self.solve(st, blocks, w, d, first=first, max_iterations=max_iterations,
                             give_up=give_up)
            first = None
            iterations += sol.iterations
            st = sol.state
            # twice the radius leaves a quarter of the noise / 20 the radius keeps (the error
            # grows as the distance squared); the next fix re-linearizes from here
            if not sol.converged or self.corr.within(st.p, st.u, slack=2.0):
                break
        return Solution(sol.state, sol.jac, sol.res, sol.blocks, sol.chi2, sol.converged,
                        iterations)

    def initial_state(self, position, moment, gradient: bool = False) -> State:
        m = np.asarray(moment, float)
        size = math.sqrt(float(m @ m))
        u = m / size if size > 0 and self.n_rot else self.model.moment_a_m2 / self.moment
        return State(np.minimum(np.maximum(np.asarray(position, float), self.lo), self.hi), u,
                     0.0, np.zeros(3), np.zeros(5) if gradient else None)

    def cold_starts(self, d_all: np.ndarray, weights_all: np.ndarray) -> list:
        """The global search's best starts (states) for the frame's blocks ``d_all`` (b, 3)
        with weights 1 / sigma^2 (b,), 0 where unusable."""
        return [self.initial_state(p0, m0)
                for p0, m0 in self.search.starts(d_all, weights_all, self.background)]

    def solve_cold(self, st: State, blocks, w, d, give_up=None) -> Solution:
        """From a search start: the multipole alone first (at most :data:`COLD_ITERATIONS`
        iterations: a start that does not converge by then is in a wrong basin or dragged by a
        liar, and is returned as not converged), then corrected; ``give_up`` as
        :meth:`solve`'s."""
        sol = self.solve(st, blocks, w, d, corrected=False,
                         max_iterations=min(COLD_ITERATIONS, self.settings.max_iterations),
                         give_up=give_up)
        if not sol.converged:
            return sol
        return self.solve_corrected(sol.state, blocks, w, d, give_up=give_up)
