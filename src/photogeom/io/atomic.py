"""Atomic file output; see :mod:`photogeom.atomicfile` (re-exported here for the I/O layer)."""

from ..atomicfile import atomic_write_bytes, atomic_write_text

__all__ = ["atomic_write_bytes", "atomic_write_text"]
