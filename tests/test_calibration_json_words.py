"""A camera JSON whose interior orientation is not in pixels is refused in the words of the
function called.

Before, ``calibration_from_json`` (``pg.camera.read_calibration_file`` of such a file) told
a Python caller "(a camera of a pixel calibration: --calibration, --principal-point and
--unit px)", options of the command line only; it now names
``InteriorOrientation.digital(..., unit='px')`` and gives the options as the command line's.
"""

from __future__ import annotations

import re

import pytest

from photogeom.camera import InteriorOrientation
from photogeom.camera.calibration_files import calibration_from_json
from photogeom.errors import FileFormatError


def test_an_interior_orientation_in_mm_names_the_python_fix():
    with pytest.raises(FileFormatError) as exc:
        calibration_from_json({"interior": {"f": 35.0, "x0": 0.0, "y0": 0.0, "unit": "mm"}})
    msg = str(exc.value)
    assert "InteriorOrientation.digital(f, col_pp, row_pp, unit='px')" in msg
    # options only where the text says they are the command line's
    python_words = re.sub(r"on the command line [^)]*", "", msg)
    assert not re.search(r"(?<![\w-])--[a-z]", python_words), msg
    # the fix it names gives a camera the function takes
    io = InteriorOrientation.digital(3000.0, 1999.5, 1499.5, unit="px", image_size=(4000, 3000))
    cal, _, _ = calibration_from_json({"interior": io.to_dict()})
    assert (cal.width, cal.height, cal.f) == (4000, 3000, 3000.0)
