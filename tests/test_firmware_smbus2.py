"""The real smbus2.SMBus class, end to end, with the kernel side faked.

smbus2's only contact with the OS is ``os.open`` / ``os.close`` on /dev/i2c-N and
``fcntl.ioctl`` (I2C_FUNCS, I2C_SLAVE, I2C_SMBUS, I2C_RDWR). Those are replaced by
SimI2cDevFile, which unpacks the real ctypes structures smbus2 builds and runs them on the
simulated chips, so the bytes are checked where the kernel would put them on the wire.
"""

import pytest

import smbus2  # noqa: E402  (a required dependency: no skip)
import smbus2.smbus2 as smbus2_impl  # noqa: E402

from firmware_io import open_bus  # noqa: E402
from firmware_io.hw import bus as fio_bus  # noqa: E402
from firmware_io.hw import PCA9685, TCA9548A, TLV493D  # noqa: E402
from firmware_io.errors import BadInputError  # noqa: E402
from firmware_io.hw.sim import SimBus, SimClock, SimI2cDevFile, SimPCA9685, SimTCA9548A, SimTLV493D  # noqa: E402


@pytest.fixture
def system(monkeypatch):
    clock = SimClock()
    sim = SimBus(clock=clock)
    chip = sim.attach(SimPCA9685(0x40))
    mux = sim.attach(SimTCA9548A(0x71))
    sensor = mux.attach(3, SimTLV493D(field_t=(0.02, -0.0049, 0.1)))
    dev = SimI2cDevFile(sim)
    monkeypatch.setattr(smbus2_impl, "os", dev.os_namespace())
    monkeypatch.setattr(smbus2_impl, "ioctl", dev.ioctl)
    real = open_bus(1)
    yield real, sim, chip, sensor, dev, clock
    real.close()


def test_open_bus_is_the_real_class(system):
    real, sim, chip, sensor, dev, _ = system
    assert type(real) is smbus2.SMBus
    assert dev.opened == ["/dev/i2c-1"] and real.funcs == SimI2cDevFile.FUNCS


def test_pca9685_through_real_smbus2(system):
    real, sim, chip, sensor, dev, clock = system
    pca = PCA9685(real, 0x40, sleep=clock.sleep)
    pca.initialize(1526)
    assert chip.regs[0xFE] == 0x03 and chip.regs[0x00] == 0x20
    assert pca.set_pwm_frequency(200) == pytest.approx(25e6 / (4096 * 31))
    assert chip.regs[0xFE] == 0x1E
    sim.clear_log()
    pca.set_channels({n: 256 * n + 1 for n in range(16)})  # 64 data bytes: I2C_RDWR
    pca.set_channels({0: "on", 1: 7})                     # 8 data bytes: I2C_SMBUS block write
    assert [t.api for t in sim.log] == ["ioctl I2C_RDWR", "ioctl I2C_SMBUS size=8 rw=0"]
    assert sim.log[0].messages[0].data == bytes([0x06]) + b"".join(
        bytes([0, 0, (256 * n + 1) & 0xFF, (256 * n + 1) >> 8]) for n in range(16))
    assert sim.log[1].messages[0].data == bytes([0x06, 0, 0x10, 0, 0, 0, 0, 7, 0])
    assert chip.duty(0) == 1.0 and chip.duty(1) == 7 / 4096 and chip.duty(15) == 3841 / 4096
    assert dev.slave == 0x40 and sim.violations() == []


def test_tlv493d_behind_mux_through_real_smbus2(system):
    real, sim, chip, sensor, dev, clock = system
    TCA9548A(real, 0x71).select(3)
    tlv = TLV493D(real, 0x5E, sleep=clock.sleep)
    tlv.configure()  # the general-call reset NACKs inside real smbus2 and is ignored
    assert sensor.mode == "master_controlled"
    b = tlv.read()
    assert tlv.status == "ok"
    lsb = 0.098e-3
    assert b == pytest.approx((round(0.02 / lsb) * lsb, -50 * lsb, round(0.1 / lsb) * lsb), abs=1e-12)
    assert sim.log[-1].api == "ioctl I2C_RDWR" and len(sim.log[-1].messages[0].data) == 6


def test_open_bus_rejects_bad_ids():
    with pytest.raises(BadInputError):
        open_bus(-1)
    with pytest.raises(BadInputError):
        open_bus(1.5)


def test_fallback_message_class_works_with_the_sim(monkeypatch):
    monkeypatch.setattr(fio_bus, "_MSG_CLASS", fio_bus._FallbackI2cMsg)
    sim = SimBus()
    chip = sim.attach(SimPCA9685(0x40))
    pca = PCA9685(sim, 0x40, sleep=lambda s: None)
    pca.initialize()
    pca.set_channels({n: 100 for n in range(16)})
    assert chip.channel_bytes(15) == bytes([0, 0, 100, 0])
    fio_bus.raw_write(sim, 0x40, [0xFE])  # register pointer, then a pointer-less read
    assert fio_bus.raw_read(sim, 0x40, 1) == bytes([0x03])
