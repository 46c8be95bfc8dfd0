"""What crosses from the sensors to the sensor side and from the sensor side to the control
step: one :class:`SensorFrame` in, one :class:`Fix` out (SI units).

Sensors are one flat list in the map's sensor order (``sensor_positions_m``), whatever boards
they sit on.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SensorFrame:
    """One pass over every sensor.

    Attributes
    ----------
    readings_t : ndarray, shape (n_sensors, 3), T -- NaN where a sensor gave no value
    status : tuple of str, one per sensor (:data:`firmware_io.hw.tlv493d.SensorStatus`)
    t_s : float, s -- when the frame's field was sampled
    """

    readings_t: np.ndarray
    status: tuple
    t_s: float


@dataclass
class Fix:
    """What the sensor side publishes for one frame (SI).

    Attributes
    ----------
    position_m : ndarray (3,), m -- the estimator's position
    moment_a_m2 : ndarray (3,), A m^2 -- the moment it found (array frame)
    ok : bool -- the estimator trusts the pose
    frame_t_s : float, s -- when the frame's field was sampled
    problems : tuple of (fault name, detail) -- sensor faults raised by this frame
    excluded : ndarray (n_sensors,) bool -- sensors left out before the fit (unhealthy,
        predicted beyond the linear range, latched faulty)
    fit_s : float, s -- compute time of the checks and the fit
    covariance_m2 : ndarray (3, 3) m^2 or None -- the position's covariance
    protection_level_m : float, m -- bound on the position error at the estimator's integrity
        risk
    reacquired : bool -- the fit started from the global search at the loop's request
    fault_excluded : tuple of int -- sensors the estimator's fault detection excluded
    saturating : tuple of int -- sensors dropped because the model predicts them beyond
        :data:`firmware_io.runner.headroom.EXPECTED_SATURATION` of their linear range
    reason : str -- why not ok ('' when ok)
    background_t : ndarray (3,), T -- the estimated uniform ambient field
    pose_covariance : ndarray (k, k) or None -- the estimate's covariance: the position (m^2),
        then (k = 5) two rotations of the moment's direction about its tangent axes
        (:func:`firmware_io.localization.pose.tangent_axes`, rad^2)
    acquired : bool -- trusted by the acquisition rule (:class:`firmware_io.runner.pipeline.
        Acquisition`) on its fault-free protection level, not by the estimator's own verdict
    prior_used : bool -- fitted with the track's prediction as the prior
    candidate : bool -- not trusted, but a consistent fix the acquisition rule would trust
        but for its protection levels: an acquiring tracker takes it as the next frame's
        prior (nothing renders on it)
    """

    position_m: np.ndarray
    moment_a_m2: np.ndarray
    ok: bool
    frame_t_s: float
    problems: tuple
    excluded: np.ndarray
    fit_s: float
    covariance_m2: np.ndarray | None = None
    protection_level_m: float = 0.0
    reacquired: bool = False
    fault_excluded: tuple = ()
    saturating: tuple = ()
    reason: str = ""
    background_t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    pose_covariance: np.ndarray | None = None
    acquired: bool = False
    prior_used: bool = False
    candidate: bool = False
