"""Public functions document every parameter of their signature (docs run).

A parameter in the signature but not in the numpy-style ``Parameters`` section (or the
other way round) left its meaning and unit to guesswork; these were found so.
"""

from __future__ import annotations

import inspect
import re

import pytest

import photogeom as pg
import photogeom.calibration
import photogeom.distributed
import photogeom.report
import photogeom.simulate


def documented(obj) -> set[str]:
    """Names in the ``Parameters`` section of ``obj``'s docstring (``a, b : type`` lines)."""
    doc = inspect.getdoc(obj) or ""
    m = re.search(r"^Parameters\n-{3,}\n(.*?)(?:\n\n[A-Z][A-Za-z ]+\n-{3,}\n|\Z)", doc, re.S | re.M)
    assert m, f"{obj.__qualname__}: no Parameters section"
    names: set[str] = set()
    for line in m.group(1).splitlines():
        if line and not line[0].isspace():
            for part in line.split(";"):
                head = part.split(" : ")[0]
                names.update(n.strip().lstrip("*") for n in head.split(","))
    return names


FUNCTIONS = [
    pg.calibration.evaluate_readjustment,
    pg.calibration.sweep_spacings,
    pg.distributed.absolute_orientation,
    pg.distributed.localize_files,
    pg.distributed.resect_images,
    pg.bundle.Block.from_arrays,
    pg.MetashapeCalibration.unproject,
    pg.gauss_markov,
    pg.gauss_helmert,
    pg.image_rays,
    pg.ground_at_height,
    pg.quaternion_from_matrix,
    pg.snooping_absolute_orientation,
    photogeom.report.residual_figure,
    pg.simulate.uav_block,
    pg.calibration.fit_grid,
    pg.absolute_orientation,
    pg.crs.geodetic_to_ecef,
    pg.crs.ecef_to_geodetic,
    pg.crs.ecef_to_enu,
    pg.crs.enu_to_ecef,
    pg.crs.LocalFrame.at_centroid,
    pg.crs.LocalFrame.from_geodetic,
    pg.crs.LocalFrame.to_geodetic,
    pg.crs.LocalFrame.covariance_from_ecef,
    pg.crs.transform_points,
    pg.distributed.register_clouds,
]


@pytest.mark.parametrize("func", FUNCTIONS, ids=lambda f: f.__qualname__)
def test_every_parameter_is_documented(func):
    # also: the numpy-style section exists (documented() asserts it)
    sig = inspect.signature(func)
    params = {
        p.name
        for p in sig.parameters.values()
        if p.name not in ("self", "cls") and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    }
    missing = sorted(params - documented(func))
    assert not missing, f"{func.__qualname__}: not in the docstring's Parameters: {missing}"


@pytest.mark.parametrize(
    "method",
    [pg.simulate.SimulatedBlock.summary, pg.calibration.GridLayout.to_dict],
    ids=lambda m: m.__qualname__,
)
def test_public_methods_have_a_docstring(method):
    assert inspect.getdoc(method), f"{method.__qualname__} has no docstring"


@pytest.mark.parametrize("module", ["photogeom.crs", "photogeom.orientation.absolute_batch"])
def test_docstring_examples_run(module):
    # their examples used names never defined (lat, lon, h, adjusted_enu; src, dst): a
    # reader pasting them got NameError; they now run as doctests
    import doctest
    import importlib

    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
