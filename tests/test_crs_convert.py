"""`crs convert`: the CRS of the input is --from or the file's '# crs:' line, never both
contradicting each other.

It used to convert with a --from that contradicted the file's line (silently wrong
coordinates) and demanded --from even when the file records its CRS.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

pyproj = pytest.importorskip("pyproj")

LONLATH = np.array([[8.5, 47.1, 500.0], [8.51, 47.105, 530.0]])


def _write(path, header, rows, crs=None):
    lines = ([f"# crs: {crs}"] if crs else []) + [header]
    lines += [f"p{i}," + ",".join(repr(float(v)) for v in r) for i, r in enumerate(rows)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _coords(out: str) -> tuple[list[str], np.ndarray]:
    lines = out.splitlines()
    rows = [ln.split(",") for ln in lines if ln and not ln.startswith("#")][1:]
    return lines, np.array([[float(v) for v in r[1:4]] for r in rows])


def _utm() -> np.ndarray:
    t = pyproj.Transformer.from_crs(4979, 32632, always_xy=True)
    return np.column_stack(t.transform(*LONLATH.T))


def test_from_defaults_to_the_files_line(cli, tmp_path):
    pts = _write(tmp_path / "g.csv", "id,x,y,z", LONLATH, crs="EPSG:4979")
    code, out, err = cli("crs", "convert", pts, "--to", "EPSG:32632")
    assert code == 0, err
    lines, xyz = _coords(out)
    assert "# crs: EPSG:32632" in lines
    np.testing.assert_allclose(xyz, _utm(), atol=1e-6, rtol=0)
    code, out2, err = cli("crs", "convert", pts, "--from", "EPSG:4979", "--to", "EPSG:32632")
    assert code == 0, err
    assert out2 == out


@pytest.mark.parametrize(
    "line, option",
    [
        ("EPSG:4979", "EPSG:4326"),
        ("EPSG:32632", "EPSG:32633"),
        ("enu:47.1,8.5,500", "enu:47.1,8.5,501"),
        ("EPSG:4979", "enu"),
    ],
)
def test_a_contradicting_from_is_refused(cli, tmp_path, line, option):
    pts = _write(tmp_path / "g.csv", "id,x,y,z", LONLATH, crs=line)
    out_csv = tmp_path / "out.csv"
    code, out, err = cli("crs", "convert", pts, "--from", option, "--to", "EPSG:4978",
                         "--origin", "47.1,8.5,500", "-o", out_csv)  # fmt: skip
    assert code == 2 and out == "" and not out_csv.exists()
    assert err.startswith("error: ") and f"records the CRS {line}" in err
    assert "--from says" in err and "leave --from out" in err


def test_the_same_crs_spelled_differently_is_accepted(cli, tmp_path):
    pts = _write(tmp_path / "g.csv", "id,x,y,z", LONLATH, crs="EPSG:4979")
    code, out, err = cli("crs", "convert", pts, "--from", "epsg:4979", "--to", "EPSG:32632")
    assert code == 0, err
    np.testing.assert_allclose(_coords(out)[1], _utm(), atol=1e-6, rtol=0)
    enu = _write(tmp_path / "e.csv", "id,E,N,U", [[1, 2, 3]], crs="enu:47.1,8.5,500.0")
    code, _, err = cli("crs", "convert", enu, "--from", "enu", "--origin", "47.1,8.5,500",
                       "--to", "EPSG:4979")  # fmt: skip
    assert code == 0, err


def test_no_from_and_no_line_is_a_named_error(cli, tmp_path):
    pts = _write(tmp_path / "g.csv", "id,x,y,z", LONLATH)
    code, out, err = cli("crs", "convert", pts, "--to", "EPSG:32632")
    assert code == 2 and out == ""
    assert "records no CRS" in err and "--from" in err


def test_an_unreadable_line_is_named(cli, tmp_path):
    pts = _write(tmp_path / "g.csv", "id,x,y,z", LONLATH, crs="EPSG:99999")
    code, _, err = cli("crs", "convert", pts, "--to", "EPSG:32632")
    assert code == 2 and f"{pts} ('# crs:' line)" in err


@settings(
    max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.floats(-60, 60), st.floats(-170, 170), st.floats(-100, 3000))
def test_round_trip_through_the_recorded_line(cli, tmp_path_factory, lat, lon, h):
    """convert's output records its CRS; converting it back without --from restores the input."""
    d = tmp_path_factory.mktemp("rt")
    pts = _write(d / "g.csv", "id,x,y,z", [[lon, lat, h]], crs="EPSG:4979")
    code, out, err = cli("crs", "convert", pts, "--to", "enu", "--origin", f"{lat},{lon},0")
    assert code == 0, err
    (d / "enu.csv").write_text(out)
    code, back, err = cli("crs", "convert", d / "enu.csv", "--to", "EPSG:4979")
    assert code == 0, err
    np.testing.assert_allclose(_coords(back)[1], [[lon, lat, h]], atol=1e-7)
