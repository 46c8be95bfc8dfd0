# SHIM: old path, removed at integration
from .hw.bus import (I2C_M_RD, I2CBus, i2c_msg_class, open_bus, raw_read, raw_write,  # noqa: F401
                     transaction_bits, transaction_wire_time_s, write_block)
