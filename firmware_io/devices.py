# SHIM: old path, removed at integration
from .hw.pca9685 import PCA9685, ChannelValue, pca9685_channel_bytes, pca9685_prescale  # noqa: F401
from .hw.tca9548a import TCA9548A  # noqa: F401
from .hw.tlv493d import (TLV493D, TLV493D_LINEAR_RANGE_T, TLV493D_LSB_T, TLVFrame,  # noqa: F401
                         tlv493d_address, tlv493d_decode, tlv493d_write_frame)
