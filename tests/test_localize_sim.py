"""The simulated TLV493D reads its field from designkit.localize; the study's smoke test."""

from __future__ import annotations

import numpy as np
import pytest

from designkit.localize import TLV_LSB_T, magnet_field
from firmware_io.devices import TLV493D
from firmware_io.sim import SimBus, SimClock, SimTLV493D


def test_sim_tlv493d_reads_a_field_source():
    """The chip's 12-bit codes of the magnet's exact field at the sensor, through the driver."""
    sensor_m = np.array([0.0, 0.0, 0.014])
    magnet = {"p": np.array([0.01, -0.005, 0.045])}

    def source():
        return magnet_field(sensor_m[None], magnet["p"], (0, 0, 0.909), 0.005, 0.010)[0]

    clock = SimClock()
    bus = SimBus(clock=clock)
    sim = bus.attach(SimTLV493D())
    sim.field_source = source
    tlv = TLV493D(bus, 0x5E, sleep=clock.sleep)
    tlv.configure()
    tlv.read()
    b = np.array(tlv.read())
    expected = np.rint(source() / TLV_LSB_T) * TLV_LSB_T
    assert np.allclose(b, expected, atol=1e-12) and np.abs(b).max() > 1e-3
    # master-controlled mode: a read returns the conversion made after the previous read
    magnet["p"] = np.array([0.0, 0.0, 0.03])
    tlv.read()
    b2 = np.array(tlv.read())
    assert np.allclose(b2, np.rint(source() / TLV_LSB_T) * TLV_LSB_T, atol=1e-12)
    assert tlv.status == "ok"


@pytest.mark.slow
def test_localization_study_smoke(tmp_path):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "studies" / "localization.py"
    spec = importlib.util.spec_from_file_location("loc_study", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    res = mod.run(tmp_path, n=4, quick=True, n_workspace=3)
    assert len(res["rows"]) == 2 * len(mod.CASES) * len(mod.METHODS)
    assert all(np.isfinite(r["mae_mm"]) for r in res["rows"])
    assert res["benchmark"]["dipole-naive"]["median_us"] > 0
    for name in ("localization.png", "subtraction_error.png", "localization.json",
                 "localization_table.txt", "learned_inverse.npz"):
        assert (tmp_path / name).is_file()
