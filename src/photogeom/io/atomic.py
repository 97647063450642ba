"""Atomic file output; see :mod:`photogeom.atomicfile` (re-exported here for the I/O layer)."""

from ..atomicfile import (
    atomic_write_bytes,
    atomic_write_many,
    atomic_write_text,
    atomic_write_texts,
)

__all__ = ["atomic_write_bytes", "atomic_write_many", "atomic_write_text", "atomic_write_texts"]
