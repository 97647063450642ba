"""photogeom's errors pickle and copy with their message and attributes: an error raised in a
worker process (concurrent.futures, multiprocessing, Dask) is pickled there and rebuilt in
the caller. TooFewPointsError and UnstableFitError, whose ``__init__`` takes other arguments
than their message, could not be rebuilt (TypeError: missing positional arguments), so a
ProcessPoolExecutor reported 'BrokenProcessPool: A process in the process pool was terminated
abruptly' instead of 'affine2d: 2 point(s) given, at least 3 needed'; OutputError lost its
errno (28 became None)."""

from __future__ import annotations

import copy
import pickle

import numpy as np
import pytest

from photogeom.errors import (
    ConvergenceError,
    DegenerateGeometryError,
    FileFormatError,
    GimbalLockError,
    InputError,
    OutputError,
    PhotogeomError,
    ReflectionError,
    TooFewPointsError,
)
from photogeom.estimation import estimate_transform
from photogeom.orientation.relative_start import PointsBehindError
from photogeom.rpc.fitting import UnstableFitError

ERRORS = [
    PhotogeomError("base"),
    InputError("bad input"),
    TooFewPointsError("affine2d", 2, 3, "6 parameters, 2 equations per point"),
    DegenerateGeometryError("collinear"),
    ConvergenceError("diverged", iterations=7, result=(1.0, 2.0)),
    ReflectionError("a reflection"),
    FileFormatError("x.csv: no header"),
    GimbalLockError("phi = 90 deg"),
    OutputError("cannot write out.csv: No space left on device", errno=28),
    UnstableFitError("RPC fit", 1.5e-4, 40, 3, 0.0),
    PointsBehindError("points behind the images"),
]


def _same(a: BaseException, b: BaseException) -> None:
    assert type(a) is type(b)
    assert str(a) == str(b)
    assert a.args == b.args
    assert vars(a) == vars(b)


@pytest.mark.parametrize("exc", ERRORS, ids=lambda e: type(e).__name__)
def test_pickle_and_copy_keep_message_and_attributes(exc):
    _same(exc, pickle.loads(pickle.dumps(exc)))
    _same(exc, copy.copy(exc))
    _same(exc, copy.deepcopy(exc))


def test_too_few_points_from_an_estimate_survives_a_process_boundary():
    p = np.array([[0.0, 0.0], [1.0, 0.5]])
    with pytest.raises(TooFewPointsError) as info:
        estimate_transform("affine2d", p, p + 1.0)
    back = pickle.loads(pickle.dumps(info.value))
    assert isinstance(back, InputError)
    assert str(back) == str(info.value)
    assert str(back).startswith("affine2d: 2 point(s) given, at least 3 needed")
    assert (back.have, back.need) == (2, 3)


def test_output_error_keeps_its_errno():
    back = pickle.loads(pickle.dumps(ERRORS[8]))
    assert back.errno == 28
    assert str(back) == "cannot write out.csv: No space left on device"


def test_unstable_fit_keeps_the_details_for_the_callers_wording():
    back = pickle.loads(pickle.dumps(ERRORS[9]))
    assert back.details == ("RPC fit", 1.5e-4, 40, 3, 0.0)
    assert isinstance(back, DegenerateGeometryError)
