"""Where is the finger magnet? Estimators over the two Hall arrays -- numpy only (runs on the
controller).

    loc = Localizer.from_map("fieldmap.npz", method="model")
    est = loc.locate(top_t, bottom_t, currents_a)     # (9, 3) T each; NaN = missing/saturated
    est.position_m, est.residual, est.ok

Methods (``method=``):

``'learned'``
    The thesis' algorithm (section 3.2.2): subtract the lower array from the upper one, take the
    sensor with the largest remainder and map its 3-vector to the magnet's position relative to
    that sensor with a learned inverse. Here a small MLP (4 inputs: field direction and
    log10 |B|; two tanh layers; 3 outputs), trained offline with scipy L-BFGS on the dipole's
    field (designkit.localize.train_learned_inverse) and stored in a weights file; inference is
    numpy. An output outside the training box is clipped to it and flagged (ok = False).
``'dipole'``
    Subtraction + least-squares fit of the magnet's field over every usable sensor pair
    (Levenberg-Marquardt on the position, analytic Jacobian of the dipole(+octupole) field;
    warm start from the last good estimate, a coarse global search when lost). With
    ``cores=True`` (default when the map carries it) the model includes the subtracted field of
    the cores magnetized by the magnet; ``cores=False`` is the naive fit.
``'model'``
    Model-based cancellation: subtract the coils' field predicted from the commanded currents
    (the map's per-ampere field at the sensors) from both arrays and fit magnet + magnet-induced
    core field to all usable sensors (no subtraction, so no doubled noise, and the lower array's
    weak magnet signal is used too). Needs ``currents``.
``'kalman'``
    ``'model'`` (``'dipole'`` when no currents are given) followed by a constant-velocity Kalman
    filter (:class:`ConstantVelocityKalman`); :meth:`Localizer.predict` extrapolates between
    sensor frames for the control loop.

Magnet model: with ``magnet_size_m`` (radius, length) the exact field of the uniformly magnetized
cylinder (:func:`cylinder_field`, Derby & Olbert with Bulirsch's cel, numpy only); the iterations
run on the axisymmetric multipole (dipole plus the l = 3 term, coefficient ratio
``octupole_m2`` = h^2 - 3 a^2 / 4 for radius a, half-length h; analytic Jacobian) and the
difference exact - multipole enters, like the map's core term, as a correction linearized about
a recent position (value and Jacobian; each correction keeps its own linearization point and a
reuse radius adapted from the linearization's observed error, kept near noise / 20). So the
warm-started fit costs a few multipole evaluations; the map's core term (~0.2 ms a call today)
is evaluated only when the magnet moved beyond that radius (cold fits re-linearize until the
solution stays within ``refresh_m`` / 4). Without a size: the multipole alone (the l >= 5 terms
it misses cost ~0.15 mm of bias 20-45 mm above the coils).

Sensor weights: sigma^2 = noise^2 + (relative_error |B_sensor|)^2, so a sensor dominated by a
large coil field (where gain and mounting errors matter) counts less.

Calibration (:func:`calibrate`, :class:`SensorCalibration`; optional, ``calibration=`` of
:class:`Localizer` and :meth:`Localizer.from_map`): from ~1000 frames with the coils driven at
known currents and the magnet away, each sensor's offset, gains, mounting rotation and (where the
map gives the coils' field gradient: the upper array) position error, plus the coils' field as
the sensor reads it. The simulator's default errors (0.5 mm, 1 degree, 1 % gain) bias an
uncalibrated fit by ~0.5 mm; after calibration what is left is ~0.06 mm.

Robustness: a sensor with any NaN component is excluded (for subtraction, the pair); the fit
needs >= 3 usable sensors. ``ok`` is False when the fit did not converge, the normalized rms
residual exceeds ``residual_limit``, too few sensors remain, or the position leaves the
plausible box -- the runner then fails safe.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from . import special
from .errors import BadInputError
from .mapfile import gradient_tensor

MU0 = 4e-7 * math.pi
_EYE = np.eye(3)
_DIAG = np.arange(3)
METHODS = ("learned", "dipole", "model", "kalman")
DEFAULT_NOISE_T = 0.1e-3
"""TLV493D noise per axis, T rms (datasheet)."""


# ---------------------------------------------------------------------------- magnet model
def _dist(a: np.ndarray, b: np.ndarray) -> float:
    """|a - b| of two (3,) vectors (np.linalg.norm costs ~5x more on the fit's hot path)."""
    d = a - b
    return math.sqrt(float(d @ d))


def multipole_field(points_m: np.ndarray, position_m: np.ndarray, moment_a_m2: np.ndarray,
                    octupole_m2: float = 0.0, *, jacobian: bool = False):
    """Field of an axisymmetric magnet (dipole + l = 3 term) at points, (n, 3) T.

    Potential phi = C1 cos(t) / r^2 + C1 q P3(cos t) / r^4 with C1 = |m| / (4 pi), q =
    ``octupole_m2``; B = -mu0 grad phi. Written as phi = f(s, rho), s = u.r, rho = r.r, so that
    B = -mu0 (f_s u + 2 f_rho r) and dB/dr = -mu0 (f_ss u u^T + 2 f_srho (u r^T + r u^T)
    + 4 f_rhorho r r^T + 2 f_rho I).

    Parameters
    ----------
    points_m : (n, 3) m; position_m : (3,) m; moment_a_m2 : (3,) A m^2; octupole_m2 : float, m^2
    jacobian : also return dB/d(position_m), (n, 3, 3) T/m (= -dB/dr).
    """
    mag = math.sqrt(float(moment_a_m2 @ moment_a_m2))
    u = moment_a_m2 / mag
    r = points_m - position_m
    rho = np.einsum("ij,ij->i", r, r)
    s = r @ u
    c = mag / (4 * math.pi)
    ir = 1.0 / rho
    a = ir * ir * np.sqrt(ir)        # rho^-5/2: every derivative below is a = times a polynomial
    sa = s * a
    if octupole_m2:
        # with t = s^2 / rho (cos^2 of the polar angle) and w = k / rho, k = c q / 2:
        # f_s = a (c rho + k (15 t - 3)), f_rho = s a (-3c/2 + w (15/2 - 35 t / 2)), ...
        k = 0.5 * c * octupole_m2
        t = s * s * ir
        w = k * ir
        fs = a * (c * rho + k * (15.0 * t - 3.0))
        fr = sa * (w * (7.5 - 17.5 * t) - 1.5 * c)
    else:
        fs = c * rho * a
        fr = -1.5 * c * sa
    b = -MU0 * (fs[:, None] * u[None] + 2 * fr[:, None] * r)
    if not jacobian:
        return b
    if octupole_m2:
        fsr = a * (w * (7.5 - 52.5 * t) - 1.5 * c)
        frr = sa * ir * (w * (78.75 * t - 26.25) + 3.75 * c)
        fss = 30.0 * w * sa
    else:
        fsr = -1.5 * c * a
        frr = 3.75 * c * sa * ir
    # 2 fsr (u r^T + r u^T) + 4 frr r r^T + fss u u^T + 2 fr I, as r v1^T + u v2^T + 2 fr I
    # (fewer small-array operations: this runs in every fit iteration)
    v1 = (4 * frr)[:, None] * r + (2 * fsr)[:, None] * u
    v2 = (2 * fsr)[:, None] * r
    if octupole_m2:
        v2 += fss[:, None] * u
    d = r[:, :, None] * v1[:, None, :] + u[None, :, None] * v2[:, None, :]
    d[:, _DIAG, _DIAG] += (2 * fr)[:, None]
    return b, MU0 * d  # d/d(position) = -d/dr


def _multipole_rows(r: np.ndarray, u: np.ndarray, c: float, k: float, out: np.ndarray,
                    work: tuple | None = None):
    """The fit's hot path: :func:`multipole_field`'s Jacobian and field at r = points - position
    (n, 3) m, written as out[:, :, :3] = dB/d(position) / mu0 (T/m per mu0) and out[:, :, 3] =
    B / mu0 (T per mu0), out (n, 3, 4); c = |m| / (4 pi), k = c q / 2, u the unit moment;
    ``work``: :func:`_multipole_work` (n, u, c), reused between calls. The same algebra as
    :func:`multipole_field` (tested equal), arranged as a few matrix products (each small numpy
    call costs ~0.5-1 us here, more than its arithmetic)."""
    b3, r5, pq, cm, tv, v, k6 = work if work is not None else _multipole_work(len(r), u, c)
    rho = np.einsum("ij,ij->i", r, r)
    s = r @ u
    ir = 1.0 / rho
    a = ir * ir * np.sqrt(ir)
    # the radial functions, each a = rho^-5/2 times (a power of s, 1/rho, rho) times a polynomial
    # c0 c + c1 w + c2 w t in w = k / rho and t = s^2 / rho (see multipole_field), in the order
    # of cm: [4 f_rho rho, 2 f_s rho, -2 f_rho; 2 f_s rho, f_ss, -f_s]
    np.multiply(ir, k, out=tv[:, 1])
    np.multiply(tv[:, 1], s * s * ir, out=tv[:, 2])
    np.multiply(s, ir, out=v[:, 0])
    v[:, 2] = v[:, 4] = s
    v[:, 5] = rho
    x = tv @ k6
    x *= v
    np.multiply(x, a[:, None], out=cm.reshape(-1, 6))
    # row i of out[k] is r_i P_k + u_i Q_k + 2 f_rho [e_i, 0] with P = [4 frr r + 2 fsr u, -2 fr]
    # and Q = [2 fsr r + fss u, -fs]: [P; Q] = cm @ [[r, 0], [u, 0], [0, 0, 0, 1]], then
    # out = [r, u, I] @ [P; Q; 2 f_rho [I, 0]]
    b3[:, 0, :3] = r
    r5[:, :, 0] = r
    np.matmul(cm, b3, out=pq[:, :2])
    np.negative(cm[:, 0, 2], out=pq[:, 2, 0])
    pq[:, 3, 1] = pq[:, 4, 2] = pq[:, 2, 0]
    np.matmul(r5, pq, out=out)
    return out


def _multipole_work(n: int, u: np.ndarray, c: float) -> tuple:
    """Buffers and constants of :func:`_multipole_rows` for n points, unit moment u and c =
    |m| / (4 pi): b3 (n, 3, 4) = [[r, 0], [u, 0], [0, 0, 0, 1]], r5 (n, 3, 5) = [r, u, I],
    pq (n, 5, 4) (rows 2-4: 2 f_rho [I, 0]), cm (n, 2, 3), tv (n, 3) = [1, w, w t],
    v (n, 6) = [s / rho, 1, s, 1, s, rho], k6 (3, 6) the polynomials' coefficients; r, s, rho,
    w, t are filled in per call."""
    b3 = np.zeros((n, 3, 4))
    b3[:, 1, :3] = u
    b3[:, 2, 3] = 1.0
    r5 = np.zeros((n, 3, 5))
    r5[:, :, 1] = u
    r5[:, :, 2:] = _EYE
    tv = np.zeros((n, 3))
    tv[:, 0] = 1.0
    v = np.ones((n, 6))
    # columns: 4 f_rho rho / (a s / rho), 2 f_s rho / a, -2 f_rho / (a s), 2 f_s rho / a,
    # f_ss / (a s), -f_s / (a rho) as c0 c + c1 w + c2 w t
    k6 = np.array([[15.0 * c, -3.0 * c, 3.0 * c, -3.0 * c, 0.0, -c],
                   [-105.0, 15.0, -15.0, 15.0, 30.0, 3.0],
                   [315.0, -105.0, 35.0, -105.0, 0.0, -15.0]])
    return b3, r5, np.zeros((n, 5, 4)), np.zeros((n, 2, 3)), tv, v, k6


def cylinder_field(points_m: np.ndarray, position_m: np.ndarray, moment_a_m2: np.ndarray,
                   radius_m: float, length_m: float) -> np.ndarray:
    """Exact field (n, 3) T of a uniformly magnetized cylinder magnet (axis along the moment).

    Derby & Olbert, Am. J. Phys. 78, 229 (2010): the cylinder's B is that of a current sheet
    K = M = |m| / (pi a^2 L) on its side; in units of the radius a, with z0 = L / (2 a),
    z+- = z +- z0, B_rho and B_z are sums of Bulirsch cel integrals. Valid at every point outside
    the magnet (the sensors).

    Parameters
    ----------
    points_m : (n, 3) m; position_m : (3,) m, the magnet's centre; moment_a_m2 : (3,) A m^2;
    radius_m, length_m : float, m
    """
    mag = math.sqrt(float(moment_a_m2 @ moment_a_m2))
    u = moment_a_m2 / mag
    a = float(radius_m)
    pol = MU0 * mag / (math.pi * a * a * float(length_m))
    rel = (np.asarray(points_m, float) - position_m) / a
    z = rel @ u
    perp = rel - z[:, None] * u
    r = np.sqrt(np.einsum("ij,ij->i", perp, perp))
    z0 = 0.5 * float(length_m) / a
    zp, zm = z + z0, z - z0
    dp, dm = 1.0 + r, 1.0 - r
    sq = np.sqrt(np.r_[zp * zp, zm * zm] + np.r_[dp, dp] ** 2)
    k = np.sqrt((np.r_[zp * zp, zm * zm] + np.r_[dm, dm] ** 2)) / sq
    gam = dm / dp
    one = np.ones_like(k)
    # kc = 0 only on the magnet's edge circles, where the field is singular
    cel = special.cel(np.r_[k, k], np.r_[one, np.r_[gam, gam] ** 2], np.r_[one, one],
                      np.r_[-one, gam, gam], tol=1e-12, kc_min=1e-12)
    n = len(z)
    cr, cz = cel[:2 * n] / sq, cel[2 * n:] / sq
    br = pol / math.pi * (cr[:n] - cr[n:])
    bz = pol / (math.pi * dp) * (zp * cz[:n] - zm * cz[n:])
    # B_rho along the unit radial direction; on the axis B_rho = 0 (perp = 0)
    rhat = perp / np.maximum(r, 1e-300)[:, None]
    return br[:, None] * rhat + bz[:, None] * u


# ---------------------------------------------------------------------------- the sensor model
@dataclass
class SensorModel:
    """What the estimators know (the v2 map's sensor section).

    sensor_positions_m : (2, n, 3) m, upper array then lower array
    coil_field_t_per_a : (2, n, 3, n_coils) T/A, the coils' field at the sensors per ampere
    moment_a_m2 : (3,) A m^2
    design_sha256 : str
    octupole_m2 : float, m^2 (0 = pure dipole)
    induced : callable (3,) m -> (2, n, 3) T, or None: field of the magnet-magnetized cores
    box_lower_m, box_upper_m : (3,) plausible magnet positions (outside: ok = False)
    magnet_size_m : (radius, length) m of the cylinder magnet, or None. Given, the fits use its
        exact field (:func:`cylinder_field`; the multipole with its analytic Jacobian carries
        the iterations, the difference enters as a per-frame linearized correction).
    coil_gradient_t_per_a_m : (2, n, 3, 3, n_coils) T/(m A) or None: the coils' field gradient
        at the sensors (entry [a, s, i, j] = dB_i/dx_j), for :func:`calibrate` to recover the
        sensors' position errors; ``gradient_known`` (2, n) bool says where it is known.
    coil_rows : callable (k, 3) m -> (k, 8, n_coils), or None: the coils' field and gradient
        rows (Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz per ampere) at any point where
        ``gradient_known``; given, :func:`calibrate` uses the exact field at the shifted
        position, else its linearization C(p + d) = C(p) + grad C d (from_map: the map's
        gradient at the sensors; a 0.5 mm shift ~9 mm from a core's end leaves ~0.1 % of C).
    """

    sensor_positions_m: np.ndarray
    coil_field_t_per_a: np.ndarray
    moment_a_m2: np.ndarray
    design_sha256: str
    octupole_m2: float = 0.0
    induced: Callable[[np.ndarray], np.ndarray] | None = None
    box_lower_m: np.ndarray | None = None
    box_upper_m: np.ndarray | None = None
    magnet_size_m: tuple | None = None
    coil_gradient_t_per_a_m: np.ndarray | None = None
    gradient_known: np.ndarray | None = None
    coil_rows: Callable[[np.ndarray], np.ndarray] | None = None

    def __post_init__(self):
        sp = np.asarray(self.sensor_positions_m, dtype=float)
        if sp.ndim != 3 or sp.shape[0] != 2 or sp.shape[2] != 3 or not np.all(np.isfinite(sp)):
            raise BadInputError("sensor_positions_m", "finite, shape (2, n, 3), m", f"shape {sp.shape}")
        n = sp.shape[1]
        cf = np.asarray(self.coil_field_t_per_a, dtype=float)
        if cf.ndim != 4 or cf.shape[:3] != (2, n, 3) or not np.all(np.isfinite(cf)):
            raise BadInputError("coil_field_t_per_a", f"finite, shape (2, {n}, 3, n_coils), T/A",
                                f"shape {cf.shape}")
        m = np.asarray(self.moment_a_m2, dtype=float)
        if m.shape != (3,) or not np.all(np.isfinite(m)) or not np.linalg.norm(m) > 0:
            raise BadInputError("moment_a_m2", "a finite non-zero 3-vector, A m^2", m.tolist())
        self.sensor_positions_m, self.coil_field_t_per_a, self.moment_a_m2 = sp, cf, m
        if self.magnet_size_m is not None:
            size = tuple(float(x) for x in self.magnet_size_m)
            if len(size) != 2 or not all(math.isfinite(x) and x > 0 for x in size):
                raise BadInputError("magnet_size_m", "(radius, length) > 0, m", self.magnet_size_m)
            self.magnet_size_m = size
        if self.coil_gradient_t_per_a_m is not None:
            g = np.asarray(self.coil_gradient_t_per_a_m, dtype=float)
            if g.shape != (2, n, 3, 3, cf.shape[3]) or not np.all(np.isfinite(g)):
                raise BadInputError("coil_gradient_t_per_a_m", f"finite, shape (2, {n}, 3, 3, "
                                    f"{cf.shape[3]}), T/(m A)", f"shape {g.shape}")
            self.coil_gradient_t_per_a_m = g
            k = (np.ones((2, n), bool) if self.gradient_known is None
                 else np.asarray(self.gradient_known, bool))
            if k.shape != (2, n):
                raise BadInputError("gradient_known", f"bool, shape (2, {n})", f"shape {k.shape}")
            self.gradient_known = k
        if self.box_lower_m is None:
            xy = np.abs(sp[..., :2]).max()
            self.box_lower_m = np.array([-xy - 0.05, -xy - 0.05, sp[0, :, 2].max() + 0.002])
            self.box_upper_m = np.array([xy + 0.05, xy + 0.05, sp[0, :, 2].max() + 0.15])

    @classmethod
    def from_operator(cls, *, induced_samples_m, induced_operator, **kw) -> "SensorModel":
        """Induced field as a linear operator on the magnet's applied H_z at sample points
        (designkit.localize.InducedCoreModel), evaluated with the multipole magnet model."""
        samples = np.asarray(induced_samples_m, float)
        op = np.asarray(induced_operator, float)
        model = cls(**kw)
        shape = model.sensor_positions_m.shape

        def induced(p):
            h = multipole_field(samples, p, model.moment_a_m2, model.octupole_m2)[:, 2] / MU0
            return (op @ h).reshape(shape)

        model.induced = induced
        return model

    @property
    def n_sensors(self) -> int:
        return self.sensor_positions_m.shape[1]

    @property
    def n_coils(self) -> int:
        return self.coil_field_t_per_a.shape[3]


@dataclass(frozen=True)
class Estimate:
    """position_m (3,) m; residual: normalized rms fit residual (1 ~ noise level; 0.0 when no
    fit was possible, then ok is False and ``reason`` says why); ok; n_used
    sensors (pairs for subtraction); iterations; method; velocity_m_s (3,) (Kalman only);
    reason: why ok is False ('' when ok)."""

    position_m: np.ndarray
    residual: float
    ok: bool
    n_used: int
    iterations: int
    method: str
    velocity_m_s: np.ndarray | None = None
    reason: str = ""


# ---------------------------------------------------------------------------- Kalman
class ConstantVelocityKalman:
    """Constant-velocity Kalman filter on the position estimates (per axis, shared dt).

    Process: white acceleration of ``accel_rms_m_s2`` (a finger's ~2 m/s^2); measurement noise
    ``meas_rms_m`` per axis. Estimates with ok = False are skipped (prediction only).
    """

    def __init__(self, accel_rms_m_s2: float = 2.0, meas_rms_m: float = 0.5e-3):
        for name, val in (("accel_rms_m_s2", accel_rms_m_s2), ("meas_rms_m", meas_rms_m)):
            if not (isinstance(val, (int, float)) and math.isfinite(val) and val > 0):
                raise BadInputError(name, "a finite number > 0", val)
        self.q = float(accel_rms_m_s2) ** 2
        self.r = float(meas_rms_m) ** 2
        self.reset()

    def reset(self) -> None:
        self.x = None                # (2, 3): position, velocity
        self.t = None
        self.p = (0.0, 0.0, 0.0)     # covariance p00, p01, p11 (the same for each axis)

    def update(self, position_m, time_s: float, ok: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Fold in one estimate; returns (position (3,), velocity (3,)). Scalar arithmetic on
        the shared 2 x 2 covariance: a few microseconds per call (it runs on the control
        thread)."""
        z = np.asarray(position_m, dtype=float)
        if self.x is None:
            if ok:
                self.x = np.stack([z, np.zeros(3)])
                self.p = (self.r, 0.0, 1.0)
                self.t = float(time_s)
            return z.copy(), np.zeros(3)
        dt = max(float(time_s) - self.t, 0.0)
        p00, p01, p11 = self.p
        q = self.q
        # predict: F P F^T + Q with F = [[1, dt], [0, 1]], Q = q [[dt^4/4, dt^3/2], [., dt^2]]
        p00, p01, p11 = (p00 + 2 * dt * p01 + dt * dt * p11 + q * dt ** 4 / 4,
                         p01 + dt * p11 + q * dt ** 3 / 2, p11 + q * dt * dt)
        x = self.x[0] + dt * self.x[1]
        v = self.x[1]
        if ok:
            s = p00 + self.r
            k0, k1 = p00 / s, p01 / s
            innov = z - x
            x = x + k0 * innov
            v = v + k1 * innov
            p00, p01, p11 = p00 - k0 * p00, p01 - k0 * p01, p11 - k1 * p01
        self.x = np.stack([x, v])
        self.p = (p00, p01, p11)
        self.t = float(time_s)
        return x.copy(), v.copy()

    def predict(self, time_s: float) -> np.ndarray:
        """Extrapolated position (3,) at ``time_s`` (between frames); NaN-free: raises if empty."""
        if self.x is None:
            raise BadInputError("filter state", "at least one ok estimate before predict", None)
        return self.x[0] + max(float(time_s) - self.t, 0.0) * self.x[1]


# ---------------------------------------------------------------------------- learned inverse
@dataclass(frozen=True)
class LearnedInverse:
    """MLP: features (u_B (3), log10 |B|) -> magnet position relative to the sensor, m."""

    weights: tuple
    feature_mean: np.ndarray
    feature_std: np.ndarray
    box_lower_m: np.ndarray
    box_upper_m: np.ndarray
    log_b_range: tuple
    design_sha256: str

    @classmethod
    def load(cls, path) -> "LearnedInverse":
        p = Path(path)
        if not p.is_file():
            raise BadInputError("weights", "a path to an existing learned-inverse .npz", str(p))
        try:
            with np.load(p, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                nl = int(meta["layers"])
                w = tuple((z[f"W{k}"].astype(float), z[f"b{k}"].astype(float)) for k in range(nl))
                out = cls(w, z["feature_mean"].astype(float), z["feature_std"].astype(float),
                          z["box_lower_m"].astype(float), z["box_upper_m"].astype(float),
                          tuple(meta["log_b_range"]), meta["design_sha256"])
        except (KeyError, ValueError, OSError, EOFError) as exc:
            raise BadInputError("weights", "a learned-inverse file written by designkit.localize"
                                f" ({type(exc).__name__}: {exc})", str(p)) from None
        return out

    def save(self, path) -> None:
        arrays = {f"W{k}": w for k, (w, _) in enumerate(self.weights)}
        arrays.update({f"b{k}": b for k, (_, b) in enumerate(self.weights)})
        meta = {"layers": len(self.weights), "log_b_range": list(self.log_b_range),
                "design_sha256": self.design_sha256, "format": "designkit-learned-inverse"}
        np.savez(path, feature_mean=self.feature_mean, feature_std=self.feature_std,
                 box_lower_m=self.box_lower_m, box_upper_m=self.box_upper_m,
                 meta=json.dumps(meta), **arrays)

    @staticmethod
    def features(b: np.ndarray) -> np.ndarray:
        """(k, 3) T -> (k, 4)."""
        n = np.linalg.norm(b, axis=-1)
        return np.c_[b / n[:, None], np.log10(n)]

    def raw(self, b: np.ndarray) -> np.ndarray:
        """Unclipped network output (k, 3) m for fields (k, 3) T."""
        h = (self.features(b) - self.feature_mean) / self.feature_std
        for k, (w, bias) in enumerate(self.weights):
            h = h @ w + bias
            if k < len(self.weights) - 1:
                h = np.tanh(h)
        c = 0.5 * (self.box_lower_m + self.box_upper_m)
        return c + h * 0.5 * (self.box_upper_m - self.box_lower_m)

    def __call__(self, b: np.ndarray) -> tuple[np.ndarray, bool]:
        """(3,) T -> (relative position (3,) m inside the training box, inside flag)."""
        b = np.asarray(b, float).reshape(1, 3)
        lb = math.log10(float(np.linalg.norm(b)) or 1e-30)
        rel = self.raw(b)[0]
        inside = bool(np.all(rel >= self.box_lower_m) and np.all(rel <= self.box_upper_m)
                      and self.log_b_range[0] <= lb <= self.log_b_range[1])
        return np.clip(rel, self.box_lower_m, self.box_upper_m), inside


# ---------------------------------------------------------------------------- the localizer
def _field_gradient(rows: np.ndarray):
    """Rows (k, 8, n_coils) (Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) -> field
    (k, 3, n_coils) and full gradient (k, 3, 3, n_coils), [.., i, j, ..] = dB_i/dx_j
    (:func:`firmware_io.mapfile.gradient_tensor`)."""
    g = gradient_tensor(np.moveaxis(rows[:, 3:8], 1, -1))  # (k, n_coils, 3, 3)
    return rows[:, :3], np.moveaxis(g, 1, -1)


def _solve3_damped(a, g, lam):
    """Solve (A + lam diag(A)) x = g for a symmetric 3 x 3 A (nested lists) by the adjugate;
    None when singular or not finite."""
    m00, m11, m22 = (a[0][0] * (1 + lam) + 1e-30, a[1][1] * (1 + lam) + 1e-30,
                     a[2][2] * (1 + lam) + 1e-30)
    m01, m02, m12 = a[0][1], a[0][2], a[1][2]
    c00 = m11 * m22 - m12 * m12
    c01 = m02 * m12 - m01 * m22
    c02 = m01 * m12 - m02 * m11
    det = m00 * c00 + m01 * c01 + m02 * c02
    if not (math.isfinite(det) and det != 0.0):
        return None
    c11 = m00 * m22 - m02 * m02
    c12 = m01 * m02 - m00 * m12
    c22 = m00 * m11 - m01 * m01
    g0, g1, g2 = g
    x = ((c00 * g0 + c01 * g1 + c02 * g2) / det, (c01 * g0 + c11 * g1 + c12 * g2) / det,
         (c02 * g0 + c12 * g1 + c22 * g2) / det)
    if not all(math.isfinite(v) for v in x):
        return None
    return x


def _check_frame(name: str, a, n: int) -> np.ndarray:
    arr = np.asarray(a, dtype=float)
    if arr.shape != (n, 3):
        raise BadInputError(name, f"an array of shape ({n}, 3), T", f"shape {arr.shape}")
    if (np.abs(arr) <= 1.0).all():  # the usual frame: one test (False with NaN, Inf, > 1 T)
        return arr
    if np.any(np.isinf(arr)):  # NaN compares False
        raise BadInputError(name, "finite values or NaN (missing/saturated), T",
                            f"Inf at {np.argwhere(np.isinf(arr))[0].tolist()}")
    if np.any(np.abs(arr) > 1.0):
        raise BadInputError(name, "fields in tesla (|B| <= 1 T; a TLV493D reads <= 0.2 T)",
                            f"{np.nanmax(np.abs(arr))!r} -- millitesla passed as tesla?")
    return arr


class Localizer:
    """Magnet position from the two arrays' readings (see the module docstring).

    Parameters
    ----------
    model : SensorModel
    method : {'learned', 'dipole', 'model', 'kalman'}
    learned : LearnedInverse, needed for 'learned'
    noise_t : float, T rms per axis
    relative_error : float, relative model error of a sensor's reading (gain, mounting);
        default 0.02, or 0.003 with a calibration
    residual_limit : float, largest normalized rms residual for ok
    cores : bool or None, model the magnet-induced core field ('dipole'; default: if known)
    mount_position_m : float, m -- sensor position uncertainty, weighs near-field sensors
    calibration : SensorCalibration (see :func:`calibrate`), or (gain_inverse (2, n, 3, 3),
        offsets_t (2, n, 3)), or None: corrected reading = gain_inverse @ (reading - offset); a
        SensorCalibration also moves the sensors by its ``shift_m`` and replaces the map's coil
        field at the sensors by the measured one.
    refresh_m : float, m -- the exact-magnet and core corrections are re-evaluated when the
        position moved farther than this from where they were last evaluated (linear in between);
        their Jacobian (central differences, 6 more evaluations) when it moved 10x farther. A
        warm-started fit re-linearizes when its solution lands beyond 1.5 times the reuse
        radius (adapted from the linearization's observed error, kept near noise / 20, between
        0.25 and 5 mm), a cold one until within refresh_m / 4.
    """

    def __init__(self, model: SensorModel, method: str = "model", *,
                 learned: LearnedInverse | None = None, noise_t: float = DEFAULT_NOISE_T,
                 relative_error: float | None = None, residual_limit: float = 5.0,
                 cores: bool | None = None, max_iterations: int = 30, calibration=None,
                 kalman: ConstantVelocityKalman | None = None, frame_period_s: float = 0.01,
                 mount_position_m: float = 0.0, refresh_m: float = 1e-3):
        if method not in METHODS:
            raise BadInputError("method", f"one of {METHODS}", method)
        if method == "learned":
            if learned is None:
                raise BadInputError("weights", "a learned-inverse file for method 'learned'", None)
            if learned.design_sha256 != model.design_sha256:
                raise BadInputError("weights", f"trained for design {model.design_sha256[:12]}...",
                                    f"design {learned.design_sha256[:12]}...",
                                    "Retrain: designkit.localize.train_learned_inverse.")
        if relative_error is None:
            relative_error = 0.02 if calibration is None else 0.003
        for name, val in (("noise_t", noise_t), ("relative_error", relative_error + 1e-300),
                          ("residual_limit", residual_limit), ("frame_period_s", frame_period_s),
                          ("refresh_m", refresh_m)):
            if not (math.isfinite(val) and val > 0):
                raise BadInputError(name, "a finite number > 0", val)
        self.model = model
        self.method = method
        self.learned = learned
        self.noise_t = float(noise_t)
        self.rel = float(relative_error)
        if not (math.isfinite(mount_position_m) and mount_position_m >= 0):
            raise BadInputError("mount_position_m", "a finite number >= 0, m", mount_position_m)
        self.mount_position_m = float(mount_position_m)
        self._moment = float(np.linalg.norm(model.moment_a_m2))
        self.residual_limit = float(residual_limit)
        self.cores = (model.induced is not None) if cores is None else bool(cores)
        if self.cores and model.induced is None:
            raise BadInputError("cores", "False (the model carries no induced core field)", cores)
        self.max_iterations = int(max_iterations)
        self.frame_period_s = float(frame_period_s)
        self.kalman = kalman or (ConstantVelocityKalman() if method == "kalman" else None)
        n = model.n_sensors
        self.refresh_m = float(refresh_m)
        self._pts = model.sensor_positions_m.reshape(-1, 3)
        cf = model.coil_field_t_per_a
        self.calibration = None
        if calibration is not None:
            self.calibration = SensorCalibration.coerce(calibration, n, model.n_coils)
            self._pts = (model.sensor_positions_m + self.calibration.shift_m).reshape(-1, 3)
            if self.calibration.coil_field_t_per_a is not None:
                cf = self.calibration.coil_field_t_per_a
        self._coil = cf
        # subtraction: the lower sensor's coil field mapped onto the upper one's (for the
        # symmetric array diag(-1, -1, 1): Br is odd about the coil's mid-plane)
        self._mirror = np.stack([cf[0, i] @ np.linalg.pinv(cf[1, i]) for i in range(n)])
        # the residual's linear maps of the 2n sensors' fields (rows: per used sensor, 3 each):
        # subtraction top - P bottom, or the identity for the model-based fit
        sub = np.zeros((n, 3, 2, n, 3))
        for s_ in range(n):
            sub[s_, :, 0, s_] = _EYE
            sub[s_, :, 1, s_] = -self._mirror[s_]
        self._sub_op = sub.reshape(n, 3, 6 * n)
        self._id_op = np.eye(6 * n).reshape(2 * n, 3, 6 * n)
        self._sub_op_all = self._sub_op.reshape(3 * n, 6 * n)
        self._id_op_all = self._id_op.reshape(6 * n, 6 * n)
        # every sensor usable (the usual frame): (op, mu0 op) by subtract
        self._ops = {True: (self._sub_op_all, MU0 * self._sub_op_all),
                     False: (self._id_op_all, MU0 * self._id_op_all)}
        mom = model.moment_a_m2
        mag = math.sqrt(float(mom @ mom))
        c_ = mag / (4 * math.pi)
        # the multipole's constants for _multipole_rows (u, c, k) and its (2n, 3, 4) buffer
        self._mp = (mom / mag, c_, 0.5 * c_ * model.octupole_m2)
        self._mp_stack = np.zeros((6 * n + 4, 4))
        self._mp_stack[-4:] = np.eye(4)
        self._mp_work = _multipole_work(2 * n, self._mp[0], c_)
        self._exact = model.magnet_size_m is not None
        lo, hi = model.box_lower_m, model.box_upper_m
        # ~1 cm apart: the dipole's field varies over the sensor spacing, a coarser grid can put
        # every start in a wrong basin near the board
        nx = max(int(round((hi[0] - lo[0]) / 0.012)), 5)
        ny = max(int(round((hi[1] - lo[1]) / 0.012)), 5)
        zs = lo[2] + np.array([0.004, 0.010, 0.018, 0.028, 0.042, 0.060, 0.085])
        g = np.stack(np.meshgrid(np.linspace(lo[0] + 0.005, hi[0] - 0.005, nx),
                                 np.linspace(lo[1] + 0.005, hi[1] - 0.005, ny),
                                 zs[zs < hi[2] - 0.002], indexing="ij"), -1)
        self._candidates = g.reshape(-1, 3)
        self._last: np.ndarray | None = None
        self._box_lo = [float(x) for x in model.box_lower_m]
        self._box_hi = [float(x) for x in model.box_upper_m]
        # per correction: (p_c, value (2n, 3), jacobian (2n, 3, 3), radius, const (6n,),
        # jacobian (6n, 3)) -- the last two the same linearization as const + jacobian @ q
        self._lin = {}
        self._pj = None  # where the core term's Jacobian was last differenced
        self._radius = self.refresh_m  # reuse radius of the linearization, adapted

    # -- construction from files -----------------------------------------------------------
    @classmethod
    def from_map(cls, path, method: str = "model", *, weights=None,
                 expected_design_sha256: str | None = None, octupole_m2: float | None = None,
                 magnet_size_m=None, calibration=None, **kw) -> "Localizer":
        """From a v2 map file (its sensor section) and, for 'learned', a weights file.

        ``magnet_size_m``: (radius, length) m of the cylinder magnet -> its exact field; default
        the map's ``meta['magnet_radius_m']``, ``meta['magnet_length_m']`` if it has them.
        ``octupole_m2``: the magnet's l = 3 coefficient ratio h^2 - 3 a^2 / 4 (m^2); default from
        the magnet's size, else the map's ``meta['magnet_octupole_m2']``, else 0 (pure dipole).
        ``calibration``: a :class:`SensorCalibration`, or a path to one saved with
        :meth:`SensorCalibration.save` (default None: uncalibrated). Other keywords go to
        :class:`Localizer`.
        """
        from .mapfile import MapFile

        m = MapFile.load(path, expected_design_sha256=expected_design_sha256)
        need = ("sensor_positions_m", "sensor_coil_field", "sensor_coil_gradient",
                "sensor_induced_field", "moment_a_m2",
                "design_sha256")
        missing = [a for a in need if not hasattr(m, a)]
        if missing:
            raise BadInputError("map file", "a v2 map with the sensor section (missing "
                                f"{', '.join(missing)})", str(path))
        sp = np.asarray(m.sensor_positions_m() if callable(m.sensor_positions_m)
                        else m.sensor_positions_m, float)
        scf = m.sensor_coil_field() if callable(m.sensor_coil_field) else m.sensor_coil_field
        mom = m.moment_a_m2() if callable(m.moment_a_m2) else m.moment_a_m2
        sha = m.design_sha256() if callable(m.design_sha256) else m.design_sha256
        lo, hi = (np.asarray(b, float) for b in m.bounds)
        # plausible positions: the map's box widened (the magnet model is analytic; outside the
        # box the runner fails safe on its own 'out_of_box' test), never below the upper board
        box_lo = lo - [0.015, 0.015, 0.0]
        box_hi = hi + [0.015, 0.015, 0.02]
        box_lo[2] = max(lo[2], float(sp[0, :, 2].max()) + 0.002)
        if magnet_size_m is None and "magnet_radius_m" in m.meta and "magnet_length_m" in m.meta:
            magnet_size_m = (m.meta["magnet_radius_m"], m.meta["magnet_length_m"])
        if octupole_m2 is None:
            if magnet_size_m is not None:
                a, length = (float(x) for x in magnet_size_m)
                octupole_m2 = (length / 2) ** 2 - 0.75 * a * a
            else:
                octupole_m2 = float(m.meta.get("magnet_octupole_m2", 0.0))
        # the coils' field gradient at every sensor (the map's SENSOR_COIL_GRAD: the sensors sit
        # below the box of A) for calibrate() to recover their position errors
        grad = np.asarray(m.sensor_coil_gradient(), float)
        known = np.ones(sp.shape[:2], bool)
        model = SensorModel(sp, np.asarray(scf, float), np.asarray(mom, float), str(sha),
                            float(octupole_m2),
                            # the induced term is a small correction: outside the map's box the
                            # nearest box point is safer than extrapolating its polynomials
                            lambda p: m.sensor_induced_field(np.clip(p, lo, hi)),
                            box_lo, box_hi, magnet_size_m, grad, known)
        learned = (LearnedInverse.load(weights) if weights is not None
                   else kw.pop("learned", None))
        if calibration is not None and not isinstance(calibration, (SensorCalibration, tuple)):
            calibration = SensorCalibration.load(calibration)
        return cls(model, method, learned=learned, calibration=calibration, **kw)

    @property
    def sensor_positions_m(self) -> np.ndarray:
        """(2, n, 3) m: upper array, lower array, in the order :meth:`locate` expects."""
        return self.model.sensor_positions_m.copy()

    def reset(self) -> None:
        """Forget the warm start and the filter state."""
        self._last = None
        if self.kalman is not None:
            self.kalman.reset()

    def predict(self, time_s: float) -> np.ndarray:
        """Kalman-extrapolated position (3,) m at ``time_s`` (method 'kalman')."""
        if self.kalman is None:
            raise BadInputError("method", "'kalman' for predict()", self.method)
        return self.kalman.predict(time_s)

    # -- the estimate ------------------------------------------------------------------------
    def locate(self, top, bottom, currents=None, *, time_s: float | None = None) -> Estimate:
        """Estimate the magnet's position from one frame.

        Parameters
        ----------
        top, bottom : array-like, shape (n, 3), T; NaN marks a missing or saturated sensor
        currents : array-like, shape (n_coils,), A -- commanded currents ('model'; optional else)
        time_s : float, frame time for 'kalman' (default: one ``frame_period_s`` per call)
        """
        n = self.model.n_sensors
        top = _check_frame("top", top, n)
        bottom = _check_frame("bottom", bottom, n)
        i = None
        if currents is not None:
            i = np.asarray(currents, dtype=float)
            if i.shape != (self.model.n_coils,) or not np.all(np.isfinite(i)):
                raise BadInputError("currents", f"{self.model.n_coils} finite values, A",
                                    f"shape {i.shape}" if i.shape != (self.model.n_coils,)
                                    else i.tolist())
        meas = np.stack([top, bottom])
        if self.calibration is not None:
            cal = self.calibration
            meas = np.matmul(cal.gain_inverse, (meas - cal.offsets_t)[..., None])[..., 0]
        method = self.method
        if method == "model" and i is None:
            raise BadInputError("currents", f"{self.model.n_coils} commanded currents, A, for "
                                "method 'model'", None)
        if method == "kalman":
            method = "model" if i is not None else "dipole"
        if method == "learned":
            est = self._learned(meas)
        else:
            est = self._fit(meas, i if method == "model" else None, method)
        if self.kalman is not None:
            t = time_s if time_s is not None else (
                (self.kalman.t + self.frame_period_s) if self.kalman.t is not None else 0.0)
            pos, vel = self.kalman.update(est.position_m, t, est.ok)
            est = Estimate(pos, est.residual, est.ok, est.n_used, est.iterations, "kalman",
                           vel, est.reason)
        return est

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
        sig2n = self.noise_t**2
        mag2 = np.einsum("asi,asi->as", meas, meas)
        if currents is None:
            d = meas[0] - np.matmul(self._mirror, meas[1][..., None])[..., 0]
            # a row sum is NaN when any component is (|B| <= 1 T: no overflow)
            use = np.isfinite(d.sum(1))
            s2 = 2 * sig2n + self.rel**2 * (mag2[0] + mag2[1])
        else:
            d = (meas - self._coil @ currents).reshape(-1, 3)
            use = np.isfinite(d.sum(1))
            s2 = sig2n + self.rel**2 * mag2.reshape(-1)
        if self.mount_position_m:
            s2 = s2 + self._mount_var(d)
        return d, use, np.sqrt(s2)

    def _exact_part(self, p):
        """The exact cylinder's field minus the multipole at the sensors near p, and its
        Jacobian (central differences, h = 0.1 mm, all in one vectorized call): (2n, 3) T,
        (2n, 3, 3) T/m. The l >= 5 terms the multipole misses fall as (size / r)^4 of the
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
            shifts = np.r_[np.zeros((1, 3)), -h * _EYE, h * _EYE]
            pts = (self._pts[near][None] + shifts[:, None]).reshape(-1, 3)
            d = (cylinder_field(pts, p, m.moment_a_m2, a, length)
                 - multipole_field(pts, p, m.moment_a_m2, m.octupole_m2)).reshape(7, -1, 3)
            val[near] = d[0]
            jac[near] = np.stack([(d[1 + k] - d[4 + k]) / (2 * h) for k in range(3)], -1)
        return val, jac

    def _induced_part(self, p):
        return self.model.induced(p).reshape(-1, 3)

    def _extra(self, p) -> np.ndarray:
        """(2n, 3) T: what the multipole misses at the sensors -- the exact cylinder's field minus
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
                        / (2 * h) for e in _EYE], -1)
        self._pj = p
        return val, jac

    def _within(self, p, tol) -> bool:
        """Is p close enough to every correction's linearization point (``tol``, or 1.5 times
        each one's reuse radius)?"""
        return all(_dist(p, c[0]) <= (tol if tol is not None else 1.5 * c[3])
                   for c in self._lin.values())

    def _linearized(self, p, tol=None):
        """(const (6n,) T, jacobian (6n, 3) T/m): the corrections to the multipole at the 2n
        sensors, affine in the position q near p: const + jacobian @ q. Each part keeps its own
        linearization point and reuse radius (adapted from the linearization's observed error):
        the exact magnet's part (cheap, curved near the sensors: value and Jacobian fresh at each
        refresh) and the map's core term (~0.2 ms a call; Jacobian by central differences
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
        corrections ``extra`` (2n, 3) T at the 2n sensors, mapped by the fit's own subtraction
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
            p = self._last if self._last is not None else 0.5 * (self.model.box_lower_m
                                                                 + self.model.box_upper_m)
            return Estimate(p.copy(), 0.0, False, n_used, 0, method,
                            reason=f"only {n_used} usable sensors (need 3)")
        # the whole weighted (and, for subtraction, mirrored) residual is one linear map of the
        # 2n sensors' field and Jacobian: op (3 m, 6 n), built once per frame
        if n_used == len(use):
            op, opm = self._ops[subtract]
            w3 = (1.0 / sig).repeat(3)[:, None]
            du = d.reshape(-1)
        else:
            op = (self._sub_op if subtract else self._id_op)[use].reshape(
                -1, 6 * self.model.n_sensors)
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
            return out[0], out[1], it, out[3]

        def cold():
            # the multipole alone from the grid's best candidates, then the full model
            cands = [self._lm(residuals(None), q0)
                     for q0 in self._global_starts(d, use, sig, subtract)]
            first = min(cands, key=lambda o: o[1])
            return solve(first[0], 0.25 * self.refresh_m) if has_extra else first

        if self._last is not None:
            best = solve(self._last, None)
            if not self._ok(best, n_used)[0]:
                # lost from the warm start: the global search once
                other = cold()
                if other[1] < best[1]:
                    best = other
        else:
            best = cold()
        p, cost, iters, converged = best
        dof = max(3 * n_used - 3, 1)
        rms = math.sqrt(cost / dof)
        ok, reason = self._ok(best, n_used)
        self._last = p.copy() if ok else None
        return Estimate(p, rms, ok, n_used, iters, method, reason=reason)

    def _ok(self, out, n_used):
        p, cost, _, converged = out
        dof = max(3 * n_used - 3, 1)
        rms = math.sqrt(cost / dof)
        if not converged:
            return False, "fit did not converge"
        lo, hi = self._box_lo, self._box_hi
        if not all(lo[k] + 1e-6 < p[k] < hi[k] - 1e-6 for k in range(3)):
            return False, "position at or outside the plausible box's edge"
        if rms > self.residual_limit:
            return False, f"residual {rms:.3g} > {self.residual_limit:g} (lost or implausible)"
        return True, ""

    def _global_starts(self, d, use, sig, subtract, keep: int = 3):
        """The best ``keep`` points of a coarse grid over the plausible box (dipole term only,
        all candidates in one vectorized pass)."""
        m = self.model
        c = self._candidates
        r = self._pts[None] - c[:, None]                          # (C, 2n, 3)
        rho = np.einsum("cij,cij->ci", r, r)
        u = m.moment_a_m2
        b = MU0 / (4 * math.pi) * (3 * r * (r @ u)[..., None] / rho[..., None] ** 2.5
                                   - u / rho[..., None] ** 1.5)
        n = m.n_sensors
        if subtract:
            b = b[:, :n] - np.einsum("sij,csj->csi", self._mirror, b[:, n:])
        res = (d[None, use] - b[:, use]) / sig[None, use, None]
        costs = np.einsum("cij,cij->c", res, res)
        costs[~np.isfinite(costs)] = np.inf
        return [c[k] for k in np.argsort(costs)[:keep]]

    def _make_eval(self, big):
        """p -> the Gram matrix of [J, -r] (4 x 4 nested lists) for :meth:`_lm`; big (3 m, 6 n + 4)
        = the weighted [mu0 op | A | -c] (see :meth:`_fit`)."""
        u, cc, k = self._mp
        pts = self._pts
        work = self._mp_work
        # one product: [mu0 op | A | -c] @ [[multipole rows (6n, 4)], [I, p], [0, 0, 0, 1]] =
        # op b(p) + A p - c next to op J(p) + A (A = 0 without corrections)
        stack = self._mp_stack
        buf = stack[:-4].reshape(-1, 3, 4)

        def evaluate(p):
            _multipole_rows(pts - p, u, cc, k, buf, work)
            stack[-4:-1, 3] = p
            y = big @ stack
            return (y.T @ y).tolist()
        return evaluate

    def _lm(self, evaluate, p0):
        """Levenberg-Marquardt on the position (3 unknowns: the 3 x 3 normal equations are
        solved in closed form on Python floats, the small-array numpy overhead dominates
        here). ``evaluate(p)`` -> the Gram matrix of [J, -r] (4 x 4 nested lists)."""
        p = np.array(p0, dtype=float)
        gm = evaluate(p)
        cost = gm[3][3]
        lam = 1e-6
        converged = False
        it = 0
        lo, hi = self._box_lo, self._box_hi
        for it in range(1, self.max_iterations + 1):
            a = gm
            g = (-gm[0][3], -gm[1][3], -gm[2][3])
            step = _solve3_damped(a, g, lam)
            if step is None:
                break
            # a Gauss-Newton step below 1/20 of the estimate's own noise (1 / sqrt(diag(J^T J))
            # per axis, <= the true standard deviation; 50 um at most): converged -- what it
            # leaves is far below that noise (and ~(step)^2 / 10 mm for exact data)
            xtol2 = min(0.0025 * (1.0 / (a[0][0] + 1e-300) + 1.0 / (a[1][1] + 1e-300)
                                  + 1.0 / (a[2][2] + 1e-300)), 2.5e-9)
            s2 = step[0] * step[0] + step[1] * step[1] + step[2] * step[2]
            if lam < 1e-4 and s2 < xtol2:
                p = p + step
                converged = True
                break
            # the position stays in the plausible box: far outside it the magnet's field vanishes
            # and a step could run away on the (bounded) induced term alone
            pn = np.array([min(max(p[k] + step[k], lo[k]), hi[k]) for k in range(3)])
            gn = evaluate(pn)
            cn = gn[3][3]
            if math.isfinite(cn) and cn <= cost:
                p, gm = pn, gn
                # 0.1 um or a negligible cost decrease: far below what the noise allows
                small = s2 < 1e-14 or cost - cn <= 1e-7 * cost
                cost = cn
                lam = max(lam * 0.2, 1e-9)
                if small:
                    converged = True
                    break
            else:
                lam *= 10.0
                if lam > 1e8:
                    converged = s2 < 1e-12
                    break
        return p, cost, it, converged

    def _learned(self, meas) -> Estimate:
        n = self.model.n_sensors
        d, use, sig = self._data(meas, None)
        if not use.any():
            return Estimate(np.zeros(3), 0.0, False, 0, 0, "learned",
                            reason="no usable sensor pair")
        mag = np.where(use, np.linalg.norm(np.nan_to_num(d), axis=1), -1.0)
        k = int(np.argmax(mag))
        rel, inside = self.learned(d[k])
        p = self.model.sensor_positions_m[0, k] + rel
        b = self._subtracted_model(p, self._extra(p) if (self._exact or self.cores) else None)
        r = ((d[use] - b[use]) / sig[use, None]).reshape(-1)
        rms = math.sqrt(float(r @ r) / max(r.size - 3, 1))
        ok, reason = inside, "" if inside else "outside the learned inverse's training box"
        if ok and rms > self.residual_limit:
            ok, reason = False, f"residual {rms:.3g} > {self.residual_limit:g}"
        return Estimate(p, rms, ok, int(use.sum()), 0, "learned", reason=reason)


@dataclass(frozen=True)
class SensorCalibration:
    """What :func:`calibrate` recovers for each sensor (upper array, then lower).

    gain_inverse : (2, n, 3, 3) -- corrected reading = gain_inverse @ (reading - offset), in the
        array frame (undoes gain and mounting rotation)
    offsets_t : (2, n, 3) T -- zero-field reading (chip offset + any static background)
    shift_m : (2, n, 3) m -- the sensor's position minus its nominal one (0 where the map gives
        no field gradient at the sensor)
    coil_field_t_per_a : (2, n, 3, n_coils) T/A -- the coils' field at the sensors as measured
        (after the gain correction); the estimators use it instead of the map's
    """

    gain_inverse: np.ndarray
    offsets_t: np.ndarray
    shift_m: np.ndarray
    coil_field_t_per_a: np.ndarray | None = None

    @classmethod
    def coerce(cls, value, n: int, n_coils: int) -> "SensorCalibration":
        """A SensorCalibration from itself or the (gain_inverse, offsets) pair; shapes checked."""
        if isinstance(value, cls):
            cal = value
        else:
            try:
                gi, off = value
            except (TypeError, ValueError):
                raise BadInputError("calibration", "a SensorCalibration or (gain_inverse, "
                                    "offsets_t)", type(value).__name__) from None
            cal = cls(np.asarray(gi, float), np.asarray(off, float), np.zeros((2, n, 3)))
        shapes = {"gain_inverse": (2, n, 3, 3), "offsets_t": (2, n, 3), "shift_m": (2, n, 3)}
        if cal.coil_field_t_per_a is not None:
            shapes["coil_field_t_per_a"] = (2, n, 3, n_coils)
        for name, shape in shapes.items():
            a = np.asarray(getattr(cal, name), float)
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise BadInputError(f"calibration.{name}", f"finite, shape {shape}",
                                    f"shape {a.shape}")
        return cal

    def save(self, path) -> None:
        arrays = {"gain_inverse": self.gain_inverse, "offsets_t": self.offsets_t,
                  "shift_m": self.shift_m}
        if self.coil_field_t_per_a is not None:
            arrays["coil_field_t_per_a"] = self.coil_field_t_per_a
        np.savez(path, format=np.array("designkit-sensor-calibration"), **arrays)

    @classmethod
    def load(cls, path) -> "SensorCalibration":
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                if str(z["format"]) != "designkit-sensor-calibration":
                    raise ValueError(f"format {str(z['format'])!r}")
                return cls(z["gain_inverse"].astype(float), z["offsets_t"].astype(float),
                           z["shift_m"].astype(float),
                           z["coil_field_t_per_a"].astype(float)
                           if "coil_field_t_per_a" in z.files else None)
        except (KeyError, ValueError, OSError, EOFError) as exc:
            raise BadInputError("calibration", "a sensor calibration .npz written by "
                                f"SensorCalibration.save ({type(exc).__name__}: {exc})",
                                str(p)) from None


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def calibrate(frames_top, frames_bottom, currents, model: SensorModel, *,
              noise_t: float = DEFAULT_NOISE_T, prior_gain: float = 0.02,
              prior_angle_deg: float = 2.0, prior_shift_m: float = 0.5e-3,
              fit_shift: bool = True, iterations: int = 10) -> SensorCalibration:
    """Per-sensor calibration from frames with the coils driven and the magnet away.

    The device runs it at start-up with the finger magnet away from the arrays: drive the
    coils with known currents (each coil alone at +-3 A, then random patterns, every sensor
    below 130 mT), read both arrays, ~1000 frames. Per sensor, least squares over the frames
    gives the measured response ``reading = K I + o`` (K (3, n_coils) T/A; o = the offset: the
    magnet-free offset capture, Earth's field included). The map predicts K from the sensor's
    nominal pose; the sensor's gains g (3), mounting rotation w (3, small angles) and position
    error d (3) follow from ``K = diag(g) (I - [w]x) C(p_nominal + d)`` by regularized
    Gauss-Newton: the residuals weighted by the noise of K, plus the priors g = 1 +- prior_gain,
    |w| ~ prior_angle_deg, d ~ prior_shift_m per axis (the tolerances, not the realization:
    directions the coils' fields do not excite -- the lateral gains, mostly -- stay near the
    prior instead of fitting the noise). C and its gradient come from ``model.coil_rows`` at the
    shifted position where given, else from the linearization about the nominal position with
    ``model.coil_gradient_t_per_a_m`` (from_map: the map's SENSOR_COIL_GRAD), wherever
    ``model.gradient_known``; elsewhere d = 0. The estimators then use gain_inverse = G^-1, the
    offsets, the sensors at nominal + d for the magnet's field and G^-1 K as the coils' field.

    Parameters
    ----------
    frames_top, frames_bottom : (k, n, 3) T -- readings; rows with NaN (saturated) are skipped
    currents : (k, n_coils) A -- each frame's currents; together they must excite every coil
        independently (rank n_coils + 1 with the offset)
    model : SensorModel
    noise_t : float, T rms per axis of one reading
    prior_gain, prior_angle_deg, prior_shift_m : prior standard deviations (see above)

    Returns
    -------
    SensorCalibration
    """
    meas = np.stack([np.asarray(frames_top, float), np.asarray(frames_bottom, float)], 1)
    i = np.asarray(currents, float)
    k, _, n, _ = meas.shape
    nc = model.n_coils
    if i.shape != (k, nc) or not np.all(np.isfinite(i)):
        raise BadInputError("currents", f"finite, shape ({k}, {nc}), A", f"shape {i.shape}")
    for name, val in (("noise_t", noise_t), ("prior_gain", prior_gain),
                      ("prior_angle_deg", prior_angle_deg), ("prior_shift_m", prior_shift_m)):
        if not (math.isfinite(val) and val > 0):
            raise BadInputError(name, "a finite number > 0", val)
    gi = np.empty((2, n, 3, 3))
    off = np.empty((2, n, 3))
    shift = np.zeros((2, n, 3))
    coil = np.empty((2, n, 3, nc))
    for a in range(2):
        for s in range(n):
            ok = np.all(np.isfinite(meas[:, a, s]), axis=1)
            x = np.c_[i[ok], np.ones(ok.sum())]
            if ok.sum() < nc + 1 or np.linalg.matrix_rank(x) < nc + 1:
                raise BadInputError("currents", f"frames that excite sensor {a}:{s} with every "
                                    "coil independently (rank n_coils + 1)", f"{ok.sum()} frames")
            coef, *_ = np.linalg.lstsq(x, meas[ok, a, s], rcond=None)
            kk = coef[:nc].T                          # (3, nc) measured response
            off[a, s] = coef[nc]
            # noise of K's entries: sigma sqrt(diag((X^T X)^-1)), the same for the 3 rows
            w = 1.0 / (noise_t * np.sqrt(np.diag(np.linalg.inv(x.T @ x))[:nc]))
            shifts = (fit_shift and model.gradient_known is not None
                      and bool(model.gradient_known[a, s]))
            c_nom = model.coil_field_t_per_a[a, s]
            exact = shifts and model.coil_rows is not None
            if exact:
                c0 = _field_gradient(model.coil_rows(model.sensor_positions_m[a, s][None]))[0][0]
            theta = np.zeros(9 if shifts else 6)      # gains - 1, angles, shift
            prior = np.r_[np.full(3, prior_gain), np.full(3, math.radians(prior_angle_deg)),
                          np.full(3, prior_shift_m)][:theta.size]
            for _ in range(iterations):
                g = 1.0 + theta[:3]
                rot = np.eye(3) - _skew(theta[3:6])
                if exact:
                    cc, gg = _field_gradient(model.coil_rows(
                        (model.sensor_positions_m[a, s] + theta[6:])[None]))
                    # SENSOR_COIL at d = 0 plus the change: no interpolation offset
                    c, dc = c_nom + cc[0] - c0, gg[0]
                elif shifts:  # linearized: C(p + d) = C(p) + grad C d
                    dc = model.coil_gradient_t_per_a_m[a, s]
                    c = c_nom + np.einsum("ijk,j->ik", dc, theta[6:])
                else:
                    c = c_nom
                rc = rot @ c
                pred = g[:, None] * rc
                cols = [np.eye(3)[q][:, None] * rc for q in range(3)]
                for q in range(3):
                    cols.append(g[:, None] * (-_skew(np.eye(3)[q]) @ c))
                if shifts:
                    for q in range(3):
                        cols.append(g[:, None] * (rot @ dc[:, q, :]))
                jac = np.stack([cc_.ravel() for cc_ in cols], 1) * np.tile(w, 3)[:, None]
                res = ((kk - pred) * w[None]).ravel()
                ja = np.r_[jac, np.diag(1.0 / prior)]
                ra = np.r_[res, -theta / prior]
                step, *_ = np.linalg.lstsq(ja, ra, rcond=None)
                theta = theta + step
                if np.all(np.abs(step) < 1e-6 * prior):
                    break
            g_mat = (1.0 + theta[:3])[:, None] * (np.eye(3) - _skew(theta[3:6]))
            gi[a, s] = np.linalg.inv(g_mat)
            if shifts:
                shift[a, s] = theta[6:]
            coil[a, s] = gi[a, s] @ kk
    return SensorCalibration(gi, off, shift, coil)
