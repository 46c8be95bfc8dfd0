# SHIM: old path, removed at integration
from .sensor_sim import SensorSimulator, analog_reading  # noqa: F401
