"""The pymavlink dialect of the project: MAVLink 2, common message set.

pymavlink chooses its dialect and protocol version from environment variables read at import:
MAVLINK20=1 and MAVLINK_DIALECT=common are set here (if unset) before pymavlink is imported, and
the common MAVLink 2 dialect module is imported directly. Every other module takes `mavlink2`
(message classes, enums, constants) from here.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")

from pymavlink.dialects.v20 import common as mavlink2

__all__ = ["mavlink2"]
