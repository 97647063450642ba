"""LocalDistortionField.random names its own parameters in its errors.

Before, it worded them with uav_block's option names (``local_field_modes must be >= 1``
for ``modes=0``), and a bad correlation named no parameter at all, neither from
LocalDistortionField.random nor from uav_block; ``modes=2.5`` was taken silently.
"""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.errors import InputError
from photogeom.simulate import LocalDistortionField, uav_block


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(rms=1.0, modes=0), r"^modes must be a whole number >= 1, got 0"),
    (dict(rms=1.0, modes=2.5), r"^modes must be a whole number >= 1, got 2.5"),
    (dict(rms=-1.0), r"^rms must be >= 0 \(RMS, pixels\), got -1"),
    (dict(rms=1.0, static=2.0), r"^static must be in \[0, 1\], got 2"),
    (dict(rms=1.0, slope=-1.0), r"^slope must be >= 0, got -1"),
    (dict(rms=1.0, correlation=1.0), r"^correlation must be in \[0, 1\) \(the correlation"),
])  # fmt: skip
def test_random_names_its_own_parameters(kwargs, message):
    with pytest.raises(InputError, match=message) as e:
        LocalDistortionField.random(np.random.default_rng(0), [1, 2], 100, 80, **kwargs)
    assert "local_field" not in str(e.value)


def test_random_refuses_an_empty_image():
    with pytest.raises(InputError, match=r"width and height must be > 0"):
        LocalDistortionField.random(np.random.default_rng(0), [1, 2], 0, 80, rms=1.0)


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(local_field_modes=0), r"^local_field_modes must be a whole number >= 1"),
    (dict(local_field_correlation=1.0), r"^local_field_correlation must be in \[0, 1\)"),
    (dict(local_field_static=-0.5), r"^local_field_static must be in \[0, 1\]"),
    (dict(calibration_variation=1.0, calibration_correlation=1.5),
     r"^calibration_correlation must be in \[0, 1\)"),
])  # fmt: skip
def test_uav_block_keeps_its_option_names(kwargs, message):
    with pytest.raises(InputError, match=message):
        uav_block("FC300S", **kwargs)


def test_cli_names_its_option(cli, tmp_path):
    code, _, err = cli("bundle", "simulate", tmp_path / "b", "--local-field", "-1")
    assert code == 2 and "--local-field must be >= 0" in err
