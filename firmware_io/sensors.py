# SHIM: old path, removed at integration
from .hw.sensors import ArraysReading, SensorArrays, SensorSlot, default_sensor_layout  # noqa: F401
