"""A residual grid whose use kills the process it is used in, but in the test's own.

For the Dask workers of tests/test_correct_folder_dead_worker.py (imported there by the
worker processes, which get the test's ``sys.path``): the worker dies as it would on an
image too large for its memory, or in a decoder's crash on a hostile file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

from photogeom.calibration import ResidualGrid

#: Environment variable with the process id of the test (the workers inherit it).
PARENT = "PHOTOGEOM_TEST_PARENT_PID"


@dataclass(frozen=True, eq=False)
class DyingGrid(ResidualGrid):
    """A grid whose ``image_size``, asked in another process than the test's, ends it."""

    @property
    def image_size(self) -> tuple[int, int]:
        if str(os.getpid()) != os.environ.get(PARENT):
            os._exit(70)
        return self.layout.width, self.layout.height
