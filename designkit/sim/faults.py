"""Faults the simulated device can suffer, on a schedule: which, when, and how each is injected.

A :class:`FaultSchedule` lists (time s, fault type); :func:`inject` puts one on the simulated
PWM boards and sensors (or on the runner's environment). A PWM NACK, an overrun or an
over-limit command shows only in a running loop: the plant injects it at the next running
step (designkit.sim.loop.RUNNING_FAULTS). The runner's response to each
(safe state, resume policy) is described in docs/runner.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import BadInputError

FAULT_TYPES = ("pwm_nack", "sensor_stuck", "sensor_dead", "sensor_saturated", "sensor_value",
               "out_of_box", "overrun", "over_limit", "thermal")
"""Fault types the plant can inject (``--faults default`` injects each once, in this order;
thermal last because a coil over its I^2 t budget stays off until it has cooled, minutes).
``sensor_value``: the top sensor above the centre coil keeps converting (its frame counter
runs) but repeats its values."""

EXTRA_FAULT_TYPES = ("sensor_zero", "sensor_offset")
"""Injectable by name, not in ``default``: the same sensor reads 0 on every axis
(``sensor_zero``), or reads 2 mT too much on x with an ok status (``sensor_offset``: only the
estimator's fault detection can see it)."""

FAULT_STATE = {"sensor_zero": "sensor_value", "sensor_offset": "sensor_value"}
"""The runner state an injected fault should end in, where its name is not that state."""

FAULT_CLEARS_S = {"pwm_nack": 0.0, "sensor_stuck": 0.0, "sensor_dead": 0.3,
                  "sensor_saturated": 0.2, "sensor_value": 0.0, "sensor_zero": 0.0,
                  "sensor_offset": 0.0, "out_of_box": 0.3, "overrun": 0.0,
                  "over_limit": 0.0, "thermal": None}
"""How long after its injection each fault's cause is gone, s: a dead sensor answers again, a
saturated one reads in range, the finger is back in the box; 0 for a one-step defect (one NACK,
one slow step, one over-limit command) and for the stuck sensor, which stays stuck (the runner
recovers with it excluded), and for the value faults (it stays faulty: the runner recovers
with it excluded); None: the coil must cool (minutes). Time to recover is counted from
there (:func:`designkit.sim.report.time_to_safe`)."""


@dataclass(frozen=True)
class FaultSchedule:
    """Faults to inject: ``events`` is a tuple of (time s, fault type), sorted by time."""

    events: tuple = ()

    @classmethod
    def parse(cls, text: str | None, duration_s: float) -> "FaultSchedule":
        """``None``/'none' -> no faults; 'default' -> each type once, spread evenly over the run
        (leaving the first and last 10 %); else 'TYPE@SECONDS,TYPE@SECONDS,...'."""
        if text is None or text.strip().lower() in ("", "none"):
            return cls(())
        if text.strip().lower() == "default":
            times = np.linspace(0.1, 0.9, len(FAULT_TYPES) + 2)[1:-1] * duration_s
            return cls(tuple((float(t), f) for t, f in zip(times, FAULT_TYPES)))
        events = []
        for item in text.split(","):
            name, _, when = item.strip().partition("@")
            if name not in FAULT_TYPES + EXTRA_FAULT_TYPES:
                raise BadInputError("faults", f"'default', 'none' or TYPE@SECONDS with TYPE in "
                                    f"{', '.join(FAULT_TYPES + EXTRA_FAULT_TYPES)}", item)
            try:
                t = float(when)
            except ValueError:
                raise BadInputError("faults", "TYPE@SECONDS (a time in s after @)", item) from None
            if not 0 <= t <= duration_s:
                raise BadInputError("faults", f"times within the run, [0, {duration_s}] s", item)
            events.append((t, name))
        return cls(tuple(sorted(events)))



def inject(device, runner, name: str, t_s: float, state: dict) -> None:
    """Put fault ``name`` on the simulated device (or the runner's environment) at ``t_s``."""
    n = device.array.n_coils
    if name == "pwm_nack":
        device.sim_boards[0].inject_nack(count=1)
    elif name == "sensor_stuck":
        device.tlv[n // 2].stuck_frame = True          # the top sensor above the centre coil
    elif name == "sensor_dead":
        device.tlv[n + 1].nack_always = True           # a bottom sensor stops answering
        state["dead_until"] = t_s + FAULT_CLEARS_S[name]
    elif name in ("sensor_value", "sensor_zero"):
        device.tlv[n // 2].value_fault = "frozen" if name == "sensor_value" else "zero"
    elif name == "sensor_offset":
        device.field_offset_t[n // 2] = (2e-3, 0.0, 0.0)
    elif name == "sensor_saturated":
        device.field_offset_t[0] = (0.0, 0.0, 0.3)     # past the 12-bit code range (+-200 mT)
        state["saturated_until"] = t_s + FAULT_CLEARS_S[name]
    elif name == "out_of_box":
        pass  # the trajectory itself leaves the box (see simulate)
    elif name == "overrun":
        state["overrun_step"] = True
    elif name == "thermal":
        # what a long overload leaves behind: one coil's I^2 t just over its budget
        runner.thermal.energy_a2s[n // 2] = 1.01 * runner.thermal.budget_a2s
    elif name == "over_limit":
        state["over_limit_step"] = True


