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
from dataclasses import dataclass, replace

import numpy as np

from ..errors import BadInputError
from .calibration import SensorCalibration
from .corrections import Corrections
from .integrity import (chi2_quantile, missed_detection_noncentrality, ratio_quantiles,
                        thresholds)
from .magnet import MU0, multipole_pose_rows
from .pose import rotated, tangent_axes
from .search import GridSearch
from .sensor_model import SensorModel
from .settings import EstimatorSettings


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
    """A converged (or abandoned) solve: its state, whitened Jacobian (3 b, P) and residual
    (3 b,) at it, the used blocks, chi2, converged, iterations."""

    state: State
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
        cov = np.asarray(seed.covariance, float)[:3 + self.n_rot, :3 + self.n_rot]
        info = np.linalg.cholesky(np.linalg.inv(cov)).T          # info^T info = cov^-1
        u0 = np.asarray(seed.moment_a_m2, float)
        u0 = u0 / math.sqrt(float(u0 @ u0))
        self.prior = (np.asarray(seed.position_m, float), tangent_axes(u0), info)

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
        if self.calibration is not None:
            cal = self.calibration
            readings = np.matmul(cal.gain_inverse, (readings - cal.offsets_t)[..., None])[..., 0]
        return np.matmul(self.model.sensor_orientations, readings[..., None])[..., 0]

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
                x = np.append(currents, 1.0)
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
        (weights w = 1 / sigma of those blocks, data d of those blocks)."""
        p, u = st.p, st.u
        scale = math.exp(st.log_scale)
        axes = tangent_axes(u)
        b, jp, ju = multipole_pose_rows(self.pts - p, u, self.c * scale, self.k * scale)
        if corrected and self.corr.active:
            cv = self.corr.value(p, u) * scale
            b = b + cv
            jp = jp + self.corr.jac_p * scale
            ju = ju + self.corr.jac_u * scale
        cols = [jp, ju @ axes.T] if self.n_rot else [jp]
        if self.fit_scale:
            cols.append(b[:, :, None])
        f = b
        if self.background:
            cols.append(self.bcols)
            f = f + st.b
        if st.g is not None:
            cols.append(self.gcols)
            f = f + self.gcols @ st.g
        jac = np.concatenate(cols, axis=2)
        if self.op is not None:
            jac = np.einsum("kisj,sjq->kiq", self.op, jac)
            f = np.einsum("kisj,sj->ki", self.op, f)
        jac = (jac[blocks] * w[:, None, None]).reshape(3 * len(blocks), -1)
        res = ((d - f[blocks]) * w[:, None]).reshape(-1)
        if self.prior is None:
            return jac, res
        p0, axes0, info = self.prior
        k = 3 + self.n_rot
        jp = np.zeros((k, jac.shape[1]))
        jp[:3, :3] = np.eye(3)
        dev = p - p0
        if self.n_rot:
            jp[3:, 3:5] = axes0 @ axes.T
            dev = np.r_[dev, axes0 @ u]
        return np.r_[jac, info[:k, :k] @ jp], np.r_[res, -(info[:k, :k] @ dev)]

    def step(self, st: State, delta: np.ndarray) -> State:
        """The state moved by the solve's step ``delta`` (position kept inside the box)."""
        p = np.minimum(np.maximum(st.p + delta[:3], self.lo), self.hi)
        j = 3 + self.n_rot
        u = rotated(st.u, tangent_axes(st.u), delta[3:5]) if self.n_rot else st.u
        log_scale = st.log_scale
        if self.fit_scale:
            log_scale += float(delta[5])
            j = 6
        b = st.b
        if self.background:
            k = self.bg_basis.shape[1]
            b = st.b + self.bg_basis @ delta[j:j + k]
            j += k
        g = None if st.g is None else st.g + delta[j:j + 5]
        return State(p, u, log_scale, b, g)

    # -- solving ---------------------------------------------------------------------------
    def solve(self, st: State, blocks, w, d, corrected: bool = True) -> Solution:
        """Levenberg-Marquardt from ``st`` on the used blocks. Converged when the Gauss-Newton
        step would lower chi2 by < 2.5e-3 (a step below 1/20 of the estimate's own noise,
        Mahalanobis): that step is taken and the fit stops."""
        jac, res = self.rows(st, blocks, w, d, corrected)
        cost = float(res @ res)
        lam, converged, it = 1e-4, False, 0
        for it in range(1, self.settings.max_iterations + 1):
            a = jac.T @ jac
            g = jac.T @ res
            diag = np.diag(a).copy()
            try:
                delta = np.linalg.solve(a + np.diag(lam * diag + 1e-300), g)
            except np.linalg.LinAlgError:
                break
            gain = float(delta @ g)
            if not math.isfinite(gain):
                break
            if gain < 2.5e-3 and lam < 1e-2:
                st = self.step(st, delta)
                converged = True
                break
            new = self.step(st, delta)
            jac2, res2 = self.rows(new, blocks, w, d, corrected)
            cost2 = float(res2 @ res2)
            if math.isfinite(cost2) and cost2 <= cost:
                st, jac, res = new, jac2, res2
                small = cost - cost2 <= 1e-9 * cost
                cost = cost2
                lam = max(lam * 0.2, 1e-9)
                if small:
                    converged = True
                    break
            else:
                lam *= 10.0
                if lam > 1e8:
                    break
        return Solution(st, jac, res, blocks, cost, converged, it)

    def solve_corrected(self, st: State, blocks, w, d, tol: float | None = None) -> Solution:
        """:meth:`solve` with the corrections linearized near the pose, re-linearized (at most
        4 times) until the solution stays within their reuse radius (or ``tol``)."""
        if not self.corr.active:
            return self.solve(st, blocks, w, d, corrected=False)
        iterations = 0
        for _ in range(5):
            self.corr.update(st.p, st.u, tol)
            sol = self.solve(st, blocks, w, d)
            iterations += sol.iterations
            st = sol.state
            if not sol.converged or self.corr.within(st.p, st.u, tol):
                break
        return replace(sol, iterations=iterations)

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

    def solve_cold(self, st: State, blocks, w, d) -> Solution:
        """From a search start: the multipole alone first, then corrected."""
        sol = self.solve(st, blocks, w, d, corrected=False)
        return self.solve_corrected(sol.state, blocks, w, d, 0.25 * self.settings.refresh_m)
