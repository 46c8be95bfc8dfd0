"""Model-based cancellation, method 'model': :class:`ModelEstimator`.

The coils' field predicted from the frame's currents (the map's per-ampere field at the
sensors) is subtracted from every sensor, and the magnet's pose (with the field of the cores it
magnetizes and the room's) is fitted to all usable sensors: no subtraction of one array from
the other, so no doubled noise, and the lower array's weak magnet signal counts too. The fit
and its integrity: :mod:`.pose_fit`, :mod:`.fix`, docs/localization.md.
"""

from __future__ import annotations

from .fit_estimator import PoseFitEstimator


class ModelEstimator(PoseFitEstimator):
    """Method 'model' (module docstring); the :class:`Estimator` interface."""

    method = "model"
    needs_currents = True
    subtract = False
