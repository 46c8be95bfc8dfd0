"""Per-sensor calibration from frames with the coils driven and the magnet away: :func:`calibrate`.

Per sensor, least squares over the frames gives the measured response ``reading = K I + o``
(K (3, n_coils) T/A, o the offset T); the sensor's gains, mounting rotation (small angles, rad)
and position error (m) then follow from ``K = diag(g) (I - [w]x) C(p_nominal + d)`` by
regularized Gauss-Newton against the coils' field C of the map. The result,
:class:`SensorCalibration`, is what the estimators (:mod:`.estimator`) apply: corrected reading
= gain_inverse @ (reading - offset) in the sensor's nominal frame, sensors moved by the shift,
the measured coil field in place of the map's. Sensors are a flat list (:class:`SensorModel`). Method and accuracy: docs/localization.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import BadInputError
from ..mapfile import gradient_tensor
from .sensor_model import DEFAULT_NOISE_T, SensorModel



UNCALIBRATED_RELATIVE_ERROR = 0.02
"""Relative model error of an uncalibrated sensor's reading: the TLV493D's gain spread and a
degree of mounting error (docs/localization.md "Integrity")."""

CALIBRATED_RELATIVE_ERROR = 0.001
"""Relative model error of a calibrated sensor's reading: what the start-up calibration (with
the coils' field gradient at the sensors) leaves of the gain, mounting and position errors
(docs/localization.md "Integrity")."""

@dataclass(frozen=True)
class SensorCalibration:
    """What :func:`calibrate` recovers for each of the n sensors (the model's flat list).

    gain_inverse : (n, 3, 3) -- corrected reading = gain_inverse @ (reading - offset), in the
        sensor's nominal frame (undoes gain and mounting rotation)
    offsets_t : (n, 3) T -- zero-field reading (chip offset + any static background)
    shift_m : (n, 3) m -- the sensor's position minus its nominal one (0 where the map gives
        no field gradient at the sensor)
    coil_field_t_per_a : (n, 3, n_coils) T/A -- the coils' field at the sensors as measured
        (after the gain correction), array frame; the estimators use it instead of the map's
    response_design_inverse : (n, n_coils + 1, n_coils + 1), or None -- (X^T X)^-1 of the
        frames' currents and the offset column (1/A^2, 1/A, 1): the measured coils' field plus
        offset at currents I has the variance sigma^2 x^T D x, x = (I, 1), sigma the reading's
        noise per axis (the estimators add it to each reading's variance: the response is
        estimated from noisy frames once, its error is common to every later frame)
    """

    gain_inverse: np.ndarray
    offsets_t: np.ndarray
    shift_m: np.ndarray
    coil_field_t_per_a: np.ndarray | None = None
    response_design_inverse: np.ndarray | None = None

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
            cal = cls(np.asarray(gi, float), np.asarray(off, float), np.zeros((n, 3)))
        shapes = {"gain_inverse": (n, 3, 3), "offsets_t": (n, 3), "shift_m": (n, 3)}
        if cal.coil_field_t_per_a is not None:
            shapes["coil_field_t_per_a"] = (n, 3, n_coils)
        if cal.response_design_inverse is not None:
            shapes["response_design_inverse"] = (n, n_coils + 1, n_coils + 1)
        for name, shape in shapes.items():
            a = np.asarray(getattr(cal, name), float)
            if a.shape != shape or not np.all(np.isfinite(a)):
                raise BadInputError(f"calibration.{name}", f"finite, shape {shape}",
                                    f"shape {a.shape}")
        return cal

    def save(self, path) -> None:
        arrays = {"gain_inverse": self.gain_inverse, "offsets_t": self.offsets_t,
                  "shift_m": self.shift_m}
        for name in ("coil_field_t_per_a", "response_design_inverse"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
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
                           *(z[name].astype(float) if name in z.files else None
                             for name in ("coil_field_t_per_a", "response_design_inverse")))
        except (KeyError, ValueError, OSError, EOFError) as exc:
            raise BadInputError("calibration", "a sensor calibration .npz written by "
                                f"SensorCalibration.save ({type(exc).__name__}: {exc})",
                                str(p)) from None


def _skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])



def _field_gradient(rows: np.ndarray):
    """Rows (k, 8, n_coils) (Bx, By, Bz, dBx/dx, dBx/dy, dBx/dz, dBy/dy, dBy/dz) -> field
    (k, 3, n_coils) and full gradient (k, 3, 3, n_coils), [.., i, j, ..] = dB_i/dx_j
    (:func:`firmware_io.mapfile.gradient_tensor`)."""
    g = gradient_tensor(np.moveaxis(rows[:, 3:8], 1, -1))  # (k, n_coils, 3, 3)
    return rows[:, :3], np.moveaxis(g, 1, -1)


@dataclass(frozen=True)
class CalibrationSettings:
    """The options of :func:`calibrate`, checked when made.

    noise_t : T rms per axis of one reading
    prior_gain : the gains' prior standard deviation (relative, about 1)
    prior_angle_deg : the mounting angles' prior standard deviation, degrees
    prior_shift_m : the position errors' prior standard deviation per axis, m
    fit_shift : fit the sensors' position errors where the map gives the coils' field gradient
    iterations : Gauss-Newton iterations at most, per sensor
    """

    noise_t: float = DEFAULT_NOISE_T
    prior_gain: float = 0.02
    prior_angle_deg: float = 2.0
    prior_shift_m: float = 0.5e-3
    fit_shift: bool = True
    iterations: int = 10

    def __post_init__(self):
        for name in ("noise_t", "prior_gain", "prior_angle_deg", "prior_shift_m"):
            val = getattr(self, name)
            if not (isinstance(val, (int, float, np.integer, np.floating))
                    and math.isfinite(val) and val > 0):
                raise BadInputError(name, "a finite number > 0", val)
        if not (isinstance(self.iterations, (int, np.integer)) and self.iterations >= 1):
            raise BadInputError("iterations", "an integer >= 1", self.iterations)

    @property
    def prior(self) -> np.ndarray:
        """(9,) the priors' standard deviations: gains - 1 (3), angles (3) rad, shift (3) m."""
        return np.r_[np.full(3, self.prior_gain), np.full(3, math.radians(self.prior_angle_deg)),
                     np.full(3, self.prior_shift_m)]


def calibrate(frames_t, currents, model: SensorModel,
              settings: CalibrationSettings = CalibrationSettings()) -> SensorCalibration:
    """Per-sensor calibration from frames with the coils driven and the magnet away.

    The device runs it at start-up with the finger magnet away from the arrays: drive the
    coils with known currents (each coil alone at +-3 A, then random patterns, every sensor
    below 130 mT), read the sensors, ~1000 frames. Per sensor, least squares over the frames
    gives the measured response ``reading = K I + o`` (K (3, n_coils) T/A; o = the offset: the
    magnet-free offset capture, Earth's field included). The map predicts K from the sensor's
    nominal pose (C in its nominal frame: R^T C); the sensor's gains g (3), mounting rotation w
    (3, small angles) and position error d (3) follow from ``K = diag(g) (I - [w]x) R^T
    C(p_nominal + d)`` by regularized Gauss-Newton: the residuals weighted by the noise of K,
    plus the priors g = 1 +- prior_gain, |w| ~ prior_angle_deg, d ~ prior_shift_m per axis (the
    tolerances, not the realization: directions the coils' fields do not excite -- the lateral
    gains, mostly -- stay near the prior instead of fitting the noise). C and its gradient come
    from ``model.coil_rows`` at the shifted position where given, else from the linearization
    about the nominal position with ``model.coil_gradient_t_per_a_m`` (from_map: the map's
    SENSOR_COIL_GRAD), wherever ``model.gradient_known``; elsewhere d = 0. The estimators then
    use gain_inverse = G^-1, the offsets, the sensors at nominal + d for the magnet's field and
    R G^-1 K as the coils' field.

    Parameters
    ----------
    frames_t : (k, n, 3) T -- readings, each in its sensor's frame; rows with NaN are skipped
    currents : (k, n_coils) A -- each frame's currents; together they must excite every coil
        independently (rank n_coils + 1 with the offset)
    model : SensorModel
    settings : CalibrationSettings -- the reading's noise, the priors' standard deviations (see
        above), whether to fit the position errors, the iterations

    Returns
    -------
    SensorCalibration
    """
    meas = np.asarray(frames_t, float)
    i = np.asarray(currents, float)
    n, nc = model.n_sensors, model.n_coils
    if meas.ndim != 3 or meas.shape[1:] != (n, 3):
        raise BadInputError("frames_t", f"shape (k, {n}, 3), T", f"shape {meas.shape}")
    k = len(meas)
    if i.shape != (k, nc) or not np.all(np.isfinite(i)):
        raise BadInputError("currents", f"finite, shape ({k}, {nc}), A", f"shape {i.shape}")
    st = settings
    prior_all = st.prior
    gi = np.empty((n, 3, 3))
    off = np.empty((n, 3))
    shift = np.zeros((n, 3))
    coil = np.empty((n, 3, nc))
    cov = np.empty((n, nc + 1, nc + 1))
    for s in range(n):
        kk, off[s], w, cov[s] = _measured_response(meas[:, s], i, st.noise_t, str(s))
        shifts = (st.fit_shift and model.gradient_known is not None
                  and bool(model.gradient_known[s]))
        theta = _fit_sensor_pose(model, s, kk, w, prior_all[:9 if shifts else 6], st.iterations)
        g_mat = (1.0 + theta[:3])[:, None] * (np.eye(3) - _skew(theta[3:6]))
        gi[s] = np.linalg.inv(g_mat)
        if shifts:
            shift[s] = theta[6:]
        coil[s] = model.sensor_orientations[s] @ gi[s] @ kk
    return SensorCalibration(gi, off, shift, coil, cov)


def _measured_response(readings, currents, noise_t: float, label: str):
    """One sensor's response to the coils by least squares over the frames.

    Parameters
    ----------
    readings : (k, 3) T; rows with NaN are skipped
    currents : (k, n_coils) A
    noise_t : float, T rms per axis
    label : str, the sensor's index for the error message

    Returns
    -------
    kk : (3, n_coils) T/A, the measured response
    offset : (3,) T
    w : (n_coils,) A/T, the inverse noise of K's entries (the same for the 3 rows)
    design_inverse : (n_coils + 1, n_coils + 1), (X^T X)^-1 (the covariance of one row of (K,
        offset) is noise^2 times it)
    """
    nc = currents.shape[1]
    ok = np.all(np.isfinite(readings), axis=1)
    x = np.c_[currents[ok], np.ones(ok.sum())]
    if ok.sum() < nc + 1 or np.linalg.matrix_rank(x) < nc + 1:
        raise BadInputError("currents", f"frames that excite sensor {label} with every "
                            "coil independently (rank n_coils + 1)", f"{ok.sum()} frames")
    coef, *_ = np.linalg.lstsq(x, readings[ok], rcond=None)
    # noise of K's entries: sigma sqrt(diag((X^T X)^-1)), the same for the 3 rows
    d_inv = np.linalg.inv(x.T @ x)
    w = 1.0 / (noise_t * np.sqrt(np.diag(d_inv)[:nc]))
    return coef[:nc].T, coef[nc], w, d_inv


def _fit_sensor_pose(model: SensorModel, s: int, kk, w, prior, iterations: int):
    """Regularized Gauss-Newton for sensor ``s``: theta = (gains - 1 (3), mounting angles (3)
    rad[, position error (3) m when ``prior`` has 9 entries]) so that diag(g) (I - [w]x) R^T
    C(p + d) matches the measured response ``kk`` (3, n_coils) T/A, residuals weighted by ``w``
    (n_coils,) A/T, plus the priors theta ~ 0 +- ``prior``."""
    shifts = prior.size == 9
    rt = model.sensor_orientations[s].T
    c_nom = rt @ model.coil_field_t_per_a[s]
    pos = model.sensor_positions_m[s]
    exact = shifts and model.coil_rows is not None
    if exact:
        c0 = _field_gradient(model.coil_rows(pos[None]))[0][0]
    theta = np.zeros(prior.size)      # gains - 1, angles, shift
    for _ in range(iterations):
        g = 1.0 + theta[:3]
        rot = np.eye(3) - _skew(theta[3:6])
        if exact:
            cc, gg = _field_gradient(model.coil_rows((pos + theta[6:])[None]))
            # SENSOR_COIL at d = 0 plus the change: no interpolation offset
            c, dc = c_nom + rt @ (cc[0] - c0), np.einsum("ij,jkl->ikl", rt, gg[0])
        elif shifts:  # linearized: C(p + d) = C(p) + grad C d
            dc = np.einsum("ij,jkl->ikl", rt, model.coil_gradient_t_per_a_m[s])
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
    return theta
