"""Image volumes: the container, readers and writers for medical formats."""

from cutkit.volumes.volume import Volume

__all__ = ["Volume"]
