"""Image volumes: the container, readers and writers for medical formats.

World coordinates are LPS millimetres throughout (see docs/volumes.md).
"""

from cutkit.volumes.describe import describe_volume
from cutkit.volumes.registry import FORMATS, VolumeFormat, read_volume, register_format, write_volume
from cutkit.volumes.volume import Volume

__all__ = ["Volume", "read_volume", "write_volume", "describe_volume", "register_format", "VolumeFormat", "FORMATS"]
