# SHIM: old path, removed at integration
from .sensor_headroom import sensor_headroom  # noqa: F401
