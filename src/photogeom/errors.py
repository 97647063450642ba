"""Exceptions raised by photogeom.

Every error names the problem and, where there is one, what would fix it.
All derive from :class:`PhotogeomError` so that callers can catch the family,
and from the matching builtin (``ValueError``, ``RuntimeError``, ``OSError``)
so that generic handlers keep working.
"""

from __future__ import annotations


class PhotogeomError(Exception):
    """Base class of all photogeom errors.

    Instances pickle and copy with their message and attributes, whatever the signature of
    the subclass's ``__init__`` (an error raised in a worker process reaches the caller,
    e.g. through :class:`concurrent.futures.ProcessPoolExecutor`).
    """

    def __reduce__(self) -> tuple:
        return _rebuilt, (type(self), self.args), dict(self.__dict__) or None


def _rebuilt(cls: type[BaseException], args: tuple) -> BaseException:
    """An exception of class ``cls`` with ``args``, without calling its ``__init__`` (whose
    parameters need not be its ``args``): the unpickling half of
    :meth:`PhotogeomError.__reduce__`; the attributes follow from the pickled state."""
    exc = cls.__new__(cls)
    exc.args = args
    return exc


class InputError(PhotogeomError, ValueError):
    """Input values are malformed: wrong shape, NaN or infinite, duplicate ids, bad units."""


class TooFewPointsError(InputError):
    """Fewer observations than the model needs."""

    def __init__(self, what: str, have: int, need: int, hint: str = "") -> None:
        self.have = have
        self.need = need
        msg = f"{what}: {have} point(s) given, at least {need} needed"
        if hint:
            msg += f" ({hint})"
        super().__init__(msg)


class DegenerateGeometryError(PhotogeomError, ValueError):
    """The point configuration does not determine the parameters (collinear, coplanar, ...)."""


class ConvergenceError(PhotogeomError, RuntimeError):
    """An iterative method diverged or reached its iteration limit."""

    def __init__(self, message: str, iterations: int | None = None, result: object = None) -> None:
        self.iterations = iterations
        self.result = result
        super().__init__(message)


class ReflectionError(DegenerateGeometryError):
    """The best fit is a reflection (det = -1), not a rotation."""


class FileFormatError(PhotogeomError, ValueError):
    """A file could not be parsed: missing key or column, wrong count, unknown format."""


class GimbalLockError(PhotogeomError, ValueError):
    """Angles of a rotation are not unique at this attitude (e.g. phi = +-90 degrees)."""


class OutputError(PhotogeomError, OSError):
    """An output file cannot be written: read-only, a directory, disk full, size limit, ...

    ``errno`` is that of the underlying operating-system error (None when photogeom refused
    the file itself, e.g. a read-only destination).
    """

    def __init__(self, message: str, errno: int | None = None) -> None:
        super().__init__(message)
        self.errno = errno

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""

    def __reduce__(self) -> tuple:
        rebuild, args, state = super().__reduce__()
        # errno is a slot of OSError, not in the instance dict
        return rebuild, args, {**(state or {}), "errno": self.errno}


class SuspectResultWarning(UserWarning):
    """A result was returned but fails a plausibility check (the reason is in the message
    and in the result's notes): for example a sigma0 the a-priori sigma does not explain."""


class LostRecordWarning(UserWarning):
    """Something a later step needs is not kept by the output asked for: for example the
    record of a joint adjustment with grids (``Block.joint_adjustment``) in a block format
    without a place for it (the message names what is lost and how to keep it)."""


class PrecisionWarning(UserWarning):
    """Input in a low-precision type (float32) has already lost digits the result needs."""
