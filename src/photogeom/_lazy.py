"""Deferred imports: a module object that imports its module on first attribute access.

The command line imports numpy, scipy, matplotlib and pyarrow only when a command needs them,
so that ``photogeom --help`` and the commands that do little start at once.
"""

from __future__ import annotations

import importlib
from types import ModuleType


class LazyModule(ModuleType):
    """Stands for the module ``name``; the first attribute access imports it.

    Examples
    --------
    >>> np = LazyModule("numpy")   # nothing imported yet
    >>> np.zeros(2)                # numpy is imported here
    array([0., 0.])
    """

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.__dict__["_lazy_target"] = None

    def _load(self) -> ModuleType:
        target = self.__dict__["_lazy_target"]
        if target is None:
            target = importlib.import_module(self.__name__)
            self.__dict__["_lazy_target"] = target
        return target

    def __getattr__(self, attr: str):
        return getattr(self._load(), attr)

    def __dir__(self) -> list[str]:
        return dir(self._load())
