"""What this machine has, for the limits that protect it (memory guards and caches)."""

from __future__ import annotations

import os

__all__ = ["physical_memory"]


def physical_memory() -> int | None:
    """This machine's physical memory.

    Returns
    -------
    int or None
        Bytes; None where the system does not say (not POSIX).
    """
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, OSError, ValueError):  # pragma: no cover - not POSIX
        return None
