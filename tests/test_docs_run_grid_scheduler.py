"""`photogeom grid correct-images --scheduler local[:N]` (docs run).

docs/crs-and-clouds.md gives the ``--scheduler`` values of the command line ('local',
'local:N', an address, ...). ``grid correct-images`` took only an address: ``--scheduler
local:1`` was read as host 'local', port 1, waited the 10 s connection limit and ended in
an error whose advice, '--scheduler local runs a cluster on this machine', failed in turn
('local' is not an address). Now 'local' / 'local:N' run the local cluster (as --dask),
addresses connect as before, and other forms are refused by the option's name.
"""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
import photogeom.calibration as calibration


@pytest.fixture
def grids_file(tmp_path):
    rng = np.random.default_rng(4)
    uv = rng.uniform([0, 0], [640, 480], (400, 2))
    grids = calibration.fit_grids(
        {"A": (uv, rng.normal(0, 0.3, (400, 2)))}, image_size=(640, 480), spacing=160
    )
    path = tmp_path / "grids.npz"
    calibration.save_grids(path, grids)
    (tmp_path / "images").mkdir()
    return path


@pytest.fixture
def calls(monkeypatch):
    seen = []

    def fake(src_dir, dst_dir, grids, *, workers=1, dask=False, **kwargs):
        seen.append((dask, workers))
        return calibration.FolderResult()

    monkeypatch.setattr(calibration, "correct_folder", fake)
    return seen


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--scheduler", "local:3"], (True, 3)),
        (["--scheduler", "local", "--workers", "2"], (True, 2)),
        (["--scheduler", "local:2", "--workers", "2"], (True, 2)),
        (["--scheduler", "tcp://127.0.0.1:8786"], ("tcp://127.0.0.1:8786", 1)),
        (["--scheduler", "127.0.0.1:8786"], ("tcp://127.0.0.1:8786", 1)),
        (["--dask", "--workers", "2"], (True, 2)),
        ([], (False, 1)),
    ],
)
def test_scheduler_values(cli, grids_file, calls, tmp_path, args, expected):
    code, _, err = cli(
        "grid", "correct-images", grids_file, tmp_path / "images", tmp_path / "out", *args
    )
    assert code == 0, err
    assert calls == [expected]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scheduler", "threads"], "--scheduler threads: grid correct-images resamples"),
        (["--scheduler", "foo"], "--scheduler 'foo': give 'local', 'local:N' or a scheduler"),
        (["--scheduler", "local:0"], "--scheduler 'local:0': 'local:N' needs"),
        (["--scheduler", "local:2", "--workers", "3"], "both give the number of workers"),
    ],
)
def test_bad_scheduler_values(cli, grids_file, calls, tmp_path, args, message):
    code, _, err = cli(
        "grid", "correct-images", grids_file, tmp_path / "images", tmp_path / "out", *args
    )
    assert code == 2
    assert message in err
    assert calls == []
    assert pg  # the package imported for its command line
