"""The position-only fit shared by the 'model' and 'dipole' estimators: :class:`PositionFit`.

Levenberg-Marquardt on the position (3 unknowns) over the multipole magnet model with its
analytic Jacobian; the exact cylinder's and the cores' fields enter as corrections linearized
about a recent position. Sensors are weighted by sigma^2 = noise^2 + (relative_error |B|)^2.
'model' data: both arrays minus the coils' field predicted from the currents; 'dipole' data:
the upper array minus the mirrored lower one. A fix is ok when the fit converged, the residual
passes the chi-square test (:mod:`.integrity`), the protection level is within the alert limit,
at least 3 sensors are usable and the position is inside the plausible box. A warm fit that
fails the test or moved farther than ``reacquire_m`` is re-solved from the global search (a
precomputed grid of the magnet's field). Models, derivations: docs/localization.md.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import BadInputError
from .calibration import SensorCalibration
from .estimate import Estimate
from .integrity import covariance_and_pl, ratio_quantiles, thresholds
from .lm import levenberg_marquardt
from .magnet import EYE3, MU0, cylinder_field, multipole_field, multipole_rows, multipole_work
from .sensor_model import SensorModel
from .settings import EstimatorSettings


def _dist(a: np.ndarray, b: np.ndarray) -> float:
    """|a - b| of two (3,) vectors (cheaper than np.linalg.norm on the fit's hot path)."""
    d = a - b
    return math.sqrt(float(d @ d))


class PositionFit:
    """The position fit of the 'model' and 'dipole' estimators (see the module docstring).

    Parameters
    ----------
    model : SensorModel
    settings : EstimatorSettings
    calibration : SensorCalibration, or (gain_inverse (2, n, 3, 3), offsets_t (2, n, 3)), or
        None: corrected reading = gain_inverse @ (reading - offset); a SensorCalibration also
        moves the sensors by its ``shift_m``, replaces the map's coil field at the sensors by
        the measured one and adds that one's variance at the frame's currents
        (``response_design_inverse``) to each reading's.

    The exact-magnet and core corrections are re-evaluated when the position moved farther
    than ``settings.refresh_m`` from where they were last evaluated (linear in between); their
    Jacobian (central differences, 6 more evaluations) when it moved 10x farther. A
    warm-started fit re-linearizes when its solution lands beyond 1.5 times the reuse radius
    (adapted from the linearization's observed error, kept near noise / 20, between 0.25 and
    5 mm), a cold one until within refresh_m / 4.
    """

    def __init__(self, model: SensorModel, settings: EstimatorSettings, calibration=None):
        self.model, self.settings = model, settings
        calibrated = calibration is not None
        self.noise_t = settings.noise_t
        self.rel = settings.relative_error_for(calibrated)
        self.mount_position_m = settings.mount_position_m
        self._moment = float(np.linalg.norm(model.moment_a_m2))
        self.residual_limit = settings.residual_limit
        self.model_bias_m, self._sig2n = settings.model_bias_for(calibrated), \
            settings.variance_floor_t2
        self.integrity_risk, self.false_alarm = settings.integrity_risk, settings.false_alarm
        self.alert_limit_m, self.reacquire_m = settings.alert_limit_m, settings.reacquire_m
        self._k2 = ratio_quantiles(self.integrity_risk)
        self._chi2_max = thresholds(self.false_alarm, 3 * model.n_sensors)
        cores = settings.cores
        self.cores = (model.induced is not None) if cores is None else bool(cores)
        if self.cores and model.induced is None:
            raise BadInputError("cores", "False (the model carries no induced core field)", cores)
        self.max_iterations = settings.max_iterations
        n = model.n_sensors
        self.refresh_m = settings.refresh_m
        cf = self._use_calibration(calibration)
        # subtraction: the lower sensor's coil field mapped onto the upper one's (for the
        # symmetric array diag(-1, -1, 1): Br is odd about the coil's mid-plane)
        pairs = model.pairs if model.pairs is not None else np.zeros((0, 2), int)
        self._up, self._lo = pairs[:, 0], pairs[:, 1]
        self._mirror = np.stack([cf[a] @ np.linalg.pinv(cf[b]) for a, b in pairs]) \
            if len(pairs) else np.zeros((0, 3, 3))
        # the residual's linear maps of the n sensors' fields (rows: per used sensor or pair,
        # 3 each): subtraction upper - P lower, or the identity for the model-based fit
        k = len(pairs)
        sub = np.zeros((k, 3, n, 3))
        for j, (a, b) in enumerate(pairs):
            sub[j, :, a] = EYE3
            sub[j, :, b] = -self._mirror[j]
        self._sub_op = sub.reshape(k, 3, 3 * n)
        self._id_op = np.eye(3 * n).reshape(n, 3, 3 * n)
        self._sub_op_all = self._sub_op.reshape(3 * k, 3 * n)
        self._id_op_all = self._id_op.reshape(3 * n, 3 * n)
        # every sensor usable (the usual frame): (op, mu0 op) by subtract
        self._ops = {True: (self._sub_op_all, MU0 * self._sub_op_all),
                     False: (self._id_op_all, MU0 * self._id_op_all)}
        mom = model.moment_a_m2
        mag = math.sqrt(float(mom @ mom))
        c_ = mag / (4 * math.pi)
        # the multipole's constants for multipole_rows (u, c, k) and its (n, 3, 4) buffer
        self._mp = (mom / mag, c_, 0.5 * c_ * model.octupole_m2)
        self._mp_stack = np.zeros((3 * n + 4, 4))
        self._mp_stack[-4:] = np.eye(4)
        self._mp_work = multipole_work(n, self._mp[0], c_)
        self._exact = model.magnet_size_m is not None
        self._candidates = self._grid_points(model.box_lower_m, model.box_upper_m)
        self._grid = self._grid_fields(self._candidates)
        self._last: np.ndarray | None = None
        self._box_lo = [float(x) for x in model.box_lower_m]
        self._box_hi = [float(x) for x in model.box_upper_m]
        # per correction: (p_c, value (n, 3), jacobian (n, 3, 3), radius, const (3n,),
        # jacobian (3n, 3)) -- the last two the same linearization as const + jacobian @ q
        self._lin = {}
        self._pj = None  # where the core term's Jacobian was last differenced
        self._radius = self.refresh_m  # reuse radius of the linearization, adapted

    def _use_calibration(self, calibration):
        """Set the sensors' positions, the calibration and the coils' field at the sensors
        (the measured one when the calibration has it) and the calibration's own variance
        sigma^2 x^T D x per sensor at x = (I, 1); returns that coils' field."""
        model, n = self.model, self.model.n_sensors
        self._pts = model.sensor_positions_m
        cf, self.calibration, self._resp = model.coil_field_t_per_a, None, None
        if calibration is not None:
            self.calibration = SensorCalibration.coerce(calibration, n, model.n_coils)
            self._pts = model.sensor_positions_m + self.calibration.shift_m
            if self.calibration.coil_field_t_per_a is not None:
                cf = self.calibration.coil_field_t_per_a
            d_inv = self.calibration.response_design_inverse
            if d_inv is not None:
                self._resp = self._sig2n * d_inv
        self._coil = cf
        return cf

    def reset(self) -> None:
        """Forget the warm start."""
        self._last = None

    @property
    def last_position_m(self) -> np.ndarray:
        """The last ok fix's position (3,) m, or the plausible box's centre."""
        return (self._last if self._last is not None else self._box_centre()).copy()

    def warm_start(self, position_m) -> None:
        """Start the next fit from ``position_m`` (3,) m (a tracker's prediction)."""
        self._last = np.array(position_m, float)

    def corrected(self, readings: np.ndarray) -> np.ndarray:
        """(n, 3) T readings, each in its sensor's frame, as the field in the array frame:
        R (gain_inverse @ (r - offset)) with the calibration, R r without."""
        if self.calibration is not None:
            cal = self.calibration
            readings = np.matmul(cal.gain_inverse, (readings - cal.offsets_t)[..., None])[..., 0]
        return np.matmul(self.model.sensor_orientations, readings[..., None])[..., 0]

    def fit(self, meas: np.ndarray, currents: np.ndarray | None, method: str) -> Estimate:
        """The fix of the field ``meas`` (n, 3) T (array frame, :meth:`corrected`): 'model'
        with ``currents`` (n_coils,) A, the subtraction ('dipole') without."""
        return self._fit(meas, currents, method)

    def _box_centre(self) -> np.ndarray:
        return 0.5 * (self.model.box_lower_m + self.model.box_upper_m)

    # subtraction: d = top - P bottom; model-based: both arrays minus the coils' field
    def _mount_var(self, d):
        """Variance from the sensors' position uncertainty: |dB| ~ 3 |B| dr / r for the magnet's
        field, with r from |B| (on-axis dipole: |B| = mu0 |m| / (2 pi r^3))."""
        if self.mount_position_m == 0.0:
            return 0.0
        b = np.linalg.norm(np.nan_to_num(d), axis=-1)
        r = np.cbrt(MU0 * self._moment / (2 * math.pi * np.maximum(b, 1e-9)))
        return (3 * self.mount_position_m * b / r) ** 2

    def _data(self, meas, currents):
        sig2n = self._sig2n
        mag2 = np.einsum("si,si->s", meas, meas)
        if currents is None:
            d = meas[self._up] - np.matmul(self._mirror, meas[self._lo][..., None])[..., 0]
            # a row sum is NaN when any component is (|B| <= 1 T: no overflow)
            use = np.isfinite(d.sum(1))
            s2 = 2 * sig2n + self.rel**2 * (mag2[self._up] + mag2[self._lo])
        else:
            d = (meas - self._coil @ currents).reshape(-1, 3)
            use = np.isfinite(d.sum(1))
            s2 = sig2n + self.rel**2 * mag2.reshape(-1)
            if self._resp is not None:
                x = np.append(currents, 1.0)
                s2 = s2 + (self._resp @ x) @ x
        if self.mount_position_m:
            s2 = s2 + self._mount_var(d)
        return d, use, np.sqrt(s2)

    def _exact_part(self, p):
        """The exact cylinder's field minus the multipole at the sensors near p, and its
        Jacobian (central differences, h = 0.1 mm, all in one vectorized call): (n, 3) T,
        (n, 3, 3) T/m. The l >= 5 terms the multipole misses fall as (size / r)^4 of the
        dipole's field: beyond 5 magnet lengths they are < 0.002 mT, 50x below the noise."""
        m = self.model
        a, length = m.magnet_size_m
        val = np.zeros((len(self._pts), 3))
        jac = np.zeros((len(self._pts), 3, 3))
        rel = self._pts - p
        near = np.einsum("ij,ij->i", rel, rel) < (5 * max(a, length)) ** 2
        if near.any():
            h = 1e-4
            # the magnet moved by +-h e_k is the sensors moved by -+h e_k
            shifts = np.r_[np.zeros((1, 3)), -h * EYE3, h * EYE3]
            pts = (self._pts[near][None] + shifts[:, None]).reshape(-1, 3)
            d = (cylinder_field(pts, p, m.moment_a_m2, a, length)
                 - multipole_field(pts, p, m.moment_a_m2, m.octupole_m2)).reshape(7, -1, 3)
            val[near] = d[0]
            jac[near] = np.stack([(d[1 + k] - d[4 + k]) / (2 * h) for k in range(3)], -1)
        return val, jac

    def _induced_part(self, p):
        return self.model.induced(p).reshape(-1, 3)

    def _extra(self, p) -> np.ndarray:
        """(n, 3) T: what the multipole misses at the sensors -- the exact cylinder's field minus
        the multipole, plus the field of the cores the magnet magnetizes."""
        out = np.zeros((len(self._pts), 3))
        if self._exact:
            out += self._exact_part(p)[0]
        if self.cores:
            out += self._induced_part(p)
        return out

    def _refresh(self, key, p, tol, evaluate, first_radius):
        """One correction's linearization near p: (p_c, value, jacobian), reused while p stays
        within the adapted radius (and ``tol``); ``evaluate(p, old)`` -> (value, jacobian)."""
        c = self._lin.get(key)
        if c is not None and _dist(p, c[0]) <= min(tol, c[3]):
            return c
        val, jac = evaluate(p, c)
        radius = first_radius
        if c is not None:
            # the linearization's error grows as |dp|^2: keep it near noise / 20
            dp = p - c[0]
            err = float(np.abs(val - c[1] - c[2] @ dp).max())
            step = math.sqrt(float(dp @ dp))
            radius = (min(max(step * math.sqrt(0.05 * self.noise_t / err), 0.1e-3), 5e-3)
                      if err > 0 else 5e-3)
        # also as the affine map the fit uses: value + J (q - p) = const + J q, flattened
        jf = jac.reshape(-1, 3)
        self._lin[key] = (p, val, jac, radius, val.reshape(-1) - jf @ p, jf)
        return self._lin[key]

    def _evaluate_induced(self, p, old):
        val = self._induced_part(p)
        if old is not None and _dist(p, old[4]) <= 10 * self.refresh_m:
            # Broyden: the reused Jacobian made exact along the move (free); the cores' field
            # is smooth on the 10 mm scale
            dp = p - old[0]
            jac = old[2] + np.einsum("ki,j->kij", val - old[1] - old[2] @ dp,
                                     dp / float(dp @ dp))
            self._pj = old[4]
            return val, jac
        h = 0.25e-3
        jac = np.stack([(self._induced_part(p + h * e) - self._induced_part(p - h * e))
                        / (2 * h) for e in EYE3], -1)
        self._pj = p
        return val, jac

    def _within(self, p, tol) -> bool:
        """Is p close enough to every correction's linearization point (``tol``, or 1.5 times
        each one's reuse radius)?"""
        return all(_dist(p, c[0]) <= (tol if tol is not None else 1.5 * c[3])
                   for c in self._lin.values())

    def _linearized(self, p, tol=None):
        """(const (3n,) T, jacobian (3n, 3) T/m): the corrections to the multipole at the n
        sensors, affine in the position q near p: const + jacobian @ q. Each part keeps its own
        linearization point and reuse radius (adapted from the linearization's observed error):
        the exact magnet's part (cheap, curved near the sensors: value and Jacobian fresh at each
        refresh) and the map's core term (the expensive one; Jacobian by central differences
        within 10 ``refresh_m``, Broyden-updated)."""
        p = np.array(p, dtype=float)
        tol = math.inf if tol is None else tol
        parts = []
        self._radius = math.inf
        if self._exact:
            # near the sensors the exact part curves on the 1 mm scale: start small
            parts.append(self._refresh("exact", p, tol, lambda q, old: self._exact_part(q),
                                       0.25e-3))
        if self.cores:
            def ev(q, old):
                return self._evaluate_induced(q, None if old is None else old[:4] + (self._pj,))
            parts.append(self._refresh("cores", p, tol, ev, self.refresh_m))
        self._radius = min(c[3] for c in parts)
        if len(parts) == 1:
            return parts[0][4], parts[0][5]
        return parts[0][4] + parts[1][4], parts[0][5] + parts[1][5]

    def _subtracted_model(self, p, extra=None):
        """The model of the subtracted data at position p: (n, 3) T, the multipole plus the
        corrections ``extra`` (n, 3) T at the n sensors, mapped by the fit's own subtraction
        operator."""
        m = self.model
        b = multipole_field(self._pts, p, m.moment_a_m2, m.octupole_m2)
        if extra is not None:
            b = b + extra
        return (self._sub_op_all @ b.reshape(-1)).reshape(-1, 3)

    def _fit(self, meas, currents, method) -> Estimate:
        subtract = currents is None
        d, use, sig = self._data(meas, np.asarray(currents) if currents is not None else None)
        n_used = int(use.sum())
        if n_used < 3:
            return Estimate(self.last_position_m, self.model.moment_a_m2.copy(), False,
                            f"only {n_used} usable sensors (need 3)", n_used=n_used,
                            method=method)
        # the whole weighted (and, for subtraction, mirrored) residual is one linear map of the
        # n sensors' field and Jacobian: op (3 m, 6 n), built once per frame
        if n_used == len(use):
            op, opm = self._ops[subtract]
            w3 = (1.0 / sig).repeat(3)[:, None]
            du = d.reshape(-1)
        else:
            op = (self._sub_op if subtract else self._id_op)[use].reshape(
                -1, 3 * self.model.n_sensors)
            opm = MU0 * op
            w3 = (1.0 / sig[use]).repeat(3)[:, None]
            du = d[use].reshape(-1)
        has_extra = self._exact or self.cores

        def residuals(lin):
            """p -> the 4 x 4 Gram matrix of [J, b - d] (weighted): J^T J, -J^T r and the cost
            r^T r in one product. The linearized corrections b_c(p) = const + L p enter as the
            constant columns A = op L and op const - d, weighted with the rows."""
            if lin is None:
                a_lin, c = np.zeros((len(op), 3)), du
            else:
                const, lf = lin
                a_lin, c = op @ lf, du - op @ const
            big = np.concatenate([opm, a_lin, -c[:, None]], 1)
            big *= w3
            return self._make_eval(big)

        def solve(p0, tol):
            """LM with the corrections linearized near the position, re-linearized (at most 4
            times) until the solution stays within tol of the linearization point."""
            it = 0
            for _ in range(5):
                lin = self._linearized(p0, tol) if has_extra else None
                out = self._lm(residuals(lin), p0)
                it += out[2]
                if lin is None or not out[3] or self._within(out[0], tol):
                    break
                p0 = out[0]
            return out[0], out[1], it, out[3], out[4]

        def cold():
            """The global search: the grid's best candidate polished on the multipole, then the
            full model; the next candidates only while the result fails the integrity test
            (a better cost wins). Returns (fit, its integrity check)."""
            found = None
            for q0 in self._global_starts(d, use, sig, subtract):
                out = self._lm(residuals(None), q0)
                if has_extra:
                    out = solve(out[0], 0.25 * self.refresh_m)
                if found is None or out[1] < found[0][1]:
                    found = (out, self._integrity(out, n_used))
                if found[1][0]:
                    break
            return found

        if self._last is not None:
            start = self._last
            best = solve(start, None)
            check = self._integrity(best, n_used)
            if not check[0] or _dist(best[0], start) > self.reacquire_m:
                # suspicious (failed, or moved far from the warm start): the global search
                other = cold()
                if other[0][1] < best[1]:
                    best, check = other
        else:
            best, check = cold()
        p, cost, iters = best[:3]
        ok, reason, cov, pl, dof = check
        self._last = p.copy() if ok else None
        return Estimate(p, self.model.moment_a_m2.copy(), ok, reason, cov, pl,
                        chi2=float(cost), dof=dof, n_used=n_used, iterations=iters,
                        method=method)

    def _integrity(self, out, n_used):
        """(ok, reason, covariance, protection level, dof) of a fit ``out`` (see
        :mod:`.integrity`): converged, inside the box, chi2 within the test's threshold, the
        protection level within the alert limit."""
        p, cost, _, converged, gm = out
        dof = 3 * n_used - 3
        cov, pl = covariance_and_pl(gm, cost, dof, self._k2)
        pl += self.model_bias_m
        rms = math.sqrt(cost / max(dof, 1))
        lo, hi = self._box_lo, self._box_hi
        if not converged:
            reason = "fit did not converge"
        elif not all(lo[k] + 1e-6 < p[k] < hi[k] - 1e-6 for k in range(3)):
            reason = "position at or outside the plausible box's edge"
        elif not cost <= self._chi2_max[dof]:
            reason = (f"residual chi2 {cost:.3g} > {self._chi2_max[dof]:.3g} ({dof} dof, "
                      f"false-alarm {self.false_alarm:g}): lost or model error")
        elif rms > self.residual_limit:
            reason = f"residual {rms:.3g} > {self.residual_limit:g} (lost or implausible)"
        elif not math.isfinite(pl):
            reason = "singular Fisher information: the position is not determined"
        elif not pl <= self.alert_limit_m:
            reason = (f"protection level {pl * 1e3:.3g} mm > alert limit "
                      f"{self.alert_limit_m * 1e3:.3g} mm")
        else:
            return True, "", cov, pl, dof
        return False, reason, cov, pl, dof

    @staticmethod
    def _grid_points(lo, hi) -> np.ndarray:
        """The global search's candidates (C, 3) m in the plausible box [lo, hi]: ~1.2 cm apart
        in x, y (the dipole's field varies over the sensor spacing, a coarser grid can put every
        start in a wrong basin near the board), 7 heights denser near the board."""
        nx = max(int(round((hi[0] - lo[0]) / 0.012)), 5)
        ny = max(int(round((hi[1] - lo[1]) / 0.012)), 5)
        zs = lo[2] + np.array([0.004, 0.010, 0.018, 0.028, 0.042, 0.060, 0.085])
        g = np.stack(np.meshgrid(np.linspace(lo[0] + 0.005, hi[0] - 0.005, nx),
                                 np.linspace(lo[1] + 0.005, hi[1] - 0.005, ny),
                                 zs[zs < hi[2] - 0.002], indexing="ij"), -1)
        return g.reshape(-1, 3)

    def _grid_fields(self, c):
        """The magnet's field at the n sensors for every grid candidate c (C, 3) m: the exact
        cylinder when its size is known, else the multipole; as (C, 3n) T for the model-based
        fit and subtracted (C, 3k) T, each with its square (the search's weighted costs)."""
        m = self.model
        rel = (self._pts[None] - c[:, None]).reshape(-1, 3)
        if self._exact:
            b = cylinder_field(rel, np.zeros(3), m.moment_a_m2, *m.magnet_size_m)
        else:
            b = multipole_field(rel, np.zeros(3), m.moment_a_m2, m.octupole_m2)
        b = np.ascontiguousarray(b.reshape(len(c), -1))
        sub = b @ self._sub_op_all.T
        return {False: (b, b * b), True: (sub, sub * sub)}

    def _global_starts(self, d, use, sig, subtract, keep: int = 3):
        """The best ``keep`` grid candidates for the frame: weighted cost sum_s |d_s - B_cs|^2
        / sigma_s^2 over the usable sensors, up to its candidate-independent part, from the
        precomputed fields (two matrix-vector products)."""
        b, b2 = self._grid[subtract]
        w = np.where(use, 1.0 / np.where(use, sig, 1.0) ** 2, 0.0)
        wd = (np.where(use[:, None], d, 0.0) * w[:, None]).reshape(-1)
        costs = b2 @ w.repeat(3) - 2.0 * (b @ wd)
        costs[~np.isfinite(costs)] = np.inf
        k = min(keep, len(costs))
        best = np.argpartition(costs, k - 1)[:k]
        return [self._candidates[j] for j in best[np.argsort(costs[best])]]

    def _lm(self, evaluate, p0):
        return levenberg_marquardt(evaluate, p0, self._box_lo, self._box_hi,
                                   self.max_iterations)

    def _make_eval(self, big):
        """p -> the Gram matrix of [J, -r] (4 x 4 nested lists) for :meth:`_lm`; big (3 m, 6 n + 4)
        = the weighted [mu0 op | A | -c] (see :meth:`_fit`)."""
        u, cc, k = self._mp
        pts = self._pts
        work = self._mp_work
        # one product: [mu0 op | A | -c] @ [[multipole rows (3n, 4)], [I, p], [0, 0, 0, 1]] =
        # op b(p) + A p - c next to op J(p) + A (A = 0 without corrections)
        stack = self._mp_stack
        buf = stack[:-4].reshape(-1, 3, 4)

        def evaluate(p):
            multipole_rows(pts - p, u, cc, k, buf, work)
            stack[-4:-1, 3] = p
            y = big @ stack
            return (y.T @ y).tolist()
        return evaluate

    def learned_fit(self, meas: np.ndarray, learned) -> Estimate:
        """The thesis' learned inverse on the subtracted data of ``meas`` (n, 3) T: the
        sensor with the largest remainder, its field mapped to the magnet's position. No
        covariance, no protection level: never ok (nothing bounds its error); ``reason`` says
        whether it also left its training box or failed the residual cap."""
        d, use, sig = self._data(meas, None)
        mom = self.model.moment_a_m2.copy()
        if not use.any():
            return Estimate.refused(np.zeros(3), mom, "no usable sensor pair", "learned")
        mag = np.where(use, np.linalg.norm(np.nan_to_num(d), axis=1), -1.0)
        k = int(np.argmax(mag))
        rel, inside = learned(d[k])
        p = self.model.sensor_positions_m[self._up[k]] + rel
        b = self._subtracted_model(p, self._extra(p) if (self._exact or self.cores) else None)
        r = ((d[use] - b[use]) / sig[use, None]).reshape(-1)
        chi2, dof = float(r @ r), max(r.size - 3, 1)
        reason = "the learned inverse has no protection level"
        if not inside:
            reason = "outside the learned inverse's training box"
        elif math.sqrt(chi2 / dof) > self.residual_limit:
            reason = f"residual {math.sqrt(chi2 / dof):.3g} > {self.residual_limit:g}"
        return Estimate(p, mom, False, reason, chi2=chi2, dof=dof, n_used=int(use.sum()),
                        method="learned")
