"""OSSIM / Orfeo ToolBox keyword lists (``.geom``) with an ``ossimRpcModel``.

Before: refused (``LINE_NUM_COEFF_0 found, but an RPC00B polynomial has exactly 20
coefficients``). The files below are written by hand: the same RPC as a coefficient-list
text (RPC00B term order) and as ``.geom`` files in polynomial format B and A (RPC00A term
order: 1 L P H LP LH PH LPH L2 P2 H2 L3 L2P L2H LP2 P3 P2H LH2 PH2 H3), the A values moved
by hand from the B list by the terms' names.
"""

from __future__ import annotations

import numpy as np
import pytest

from photogeom.errors import FileFormatError
from photogeom.rpc import read_rpc

HEADER = {  # OSSIM keyword: value (the list text uses the GDAL names)
    "line_off": "5124", "samp_off": "6334", "lat_off": "-34.903", "long_off": "-56.1722",
    "height_off": "28", "line_scale": "5124", "samp_scale": "6334", "lat_scale": "0.0661",
    "long_scale": "0.0703", "height_scale": "82",
}  # fmt: skip
# RPC00B order: 1 L P H LP LH PH L2 P2 H2 PLH L3 LP2 LH2 L2P P3 PH2 L2H P2H H3
B = {
    "line_num": "0.001 0.02 -1.01 0.003 0.004 0.0005 0.0006 0.0007 0.0008 0.0009 "
                "0.0011 0.0012 0.0013 0.0014 0.0015 0.0016 0.0017 0.0018 0.0019 0.00021",
    "line_den": "1 0.001 0.002 0.0003 0.00004 0 0 0 0 0 0.00005 0 0 0 0.00006 0 0 0 0 0",
    "samp_num": "-0.002 1.02 0.03 -0.004 0.0021 0.0022 0.0023 0.0024 0.0025 0.0026 "
                "0.0027 0.0028 0.0029 0.0031 0.0032 0.0033 0.0034 0.0035 0.0036 0.0037",
    "samp_den": "1 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0.00007 0",
}  # fmt: skip
# the same polynomials in RPC00A order (LPH, L2P, L2H, LP2, P2H, LH2, PH2 moved by name)
A = {
    "line_num": "0.001 0.02 -1.01 0.003 0.004 0.0005 0.0006 0.0011 0.0007 0.0008 "
                "0.0009 0.0012 0.0015 0.0018 0.0013 0.0016 0.0019 0.0014 0.0017 0.00021",
    "line_den": "1 0.001 0.002 0.0003 0.00004 0 0 0.00005 0 0 0 0 0.00006 0 0 0 0 0 0 0",
    "samp_num": "-0.002 1.02 0.03 -0.004 0.0021 0.0022 0.0023 0.0027 0.0024 0.0025 "
                "0.0026 0.0028 0.0032 0.0035 0.0029 0.0033 0.0036 0.0031 0.0034 0.0037",
    "samp_den": "1 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 0.00007 0 0 0",
}  # fmt: skip


def _lists_text() -> str:
    lines = [f"{k.upper()}: {v}" for k, v in HEADER.items()]
    lines += [f"{k.upper()}_COEFF: {v}" for k, v in B.items()]
    return "\n".join(lines) + "\n"


def _geom_text(fmt: str, coeffs: dict, prefix: str = "") -> str:
    lines = ["// an OSSIM keyword list", "image_id:  scene", f"{prefix}type:  ossimRpcModel",
             f"{prefix}polynomial_format:  {fmt}", f"{prefix}bias_error:  0",
             f"{prefix}rand_error:  0", "support_data.sensor:  IKONOS-2"]  # fmt: skip
    lines += [f"{prefix}{k}:  {v}" for k, v in HEADER.items()]
    for name, values in coeffs.items():
        lines += [f"{prefix}{name}_coeff_{i:02d}:  {v}" for i, v in enumerate(values.split())]
    return "\n".join(lines) + "\n"


@pytest.fixture
def reference(tmp_path):
    p = tmp_path / "list_RPC.TXT"
    p.write_text(_lists_text())
    return read_rpc(p)


@pytest.mark.parametrize(("fmt", "coeffs", "prefix"), [
    ("B", B, ""), ("A", A, ""), ("A", A, "projection."),
])  # fmt: skip
def test_geom_reads_as_the_same_rpc(tmp_path, reference, fmt, coeffs, prefix):
    p = tmp_path / "scene.geom"
    p.write_text(_geom_text(fmt, coeffs, prefix))
    rpc = read_rpc(p)
    assert rpc.source == f"OSSIM keyword list (.geom), polynomial format {fmt}"
    for k in ("line_num", "line_den", "samp_num", "samp_den"):
        np.testing.assert_array_equal(getattr(rpc, k), getattr(reference, k), err_msg=k)
    assert (rpc.line_off, rpc.long_scale, rpc.height_off) == (5124.0, 0.0703, 28.0)
    assert rpc.err_bias is None  # OSSIM's 0: not given
    lon = np.array([-56.2, -56.15, -56.12])
    lat = np.array([-34.93, -34.9, -34.88])
    h = np.array([0.0, 40.0, 90.0])
    np.testing.assert_allclose(rpc.project(lon, lat, h), reference.project(lon, lat, h),
                               rtol=0, atol=1e-9)  # fmt: skip


def test_bad_geom_files_are_named(tmp_path):
    p = tmp_path / "x.geom"
    p.write_text(_geom_text("C", B))
    with pytest.raises(FileFormatError, match=r"polynomial_format: A .* or B"):
        read_rpc(p)
    text = _geom_text("B", B).replace("samp_den_coeff_07:  0\n", "")
    p.write_text(text)
    with pytest.raises(FileFormatError, match="missing samp_den_coeff_07"):
        read_rpc(p)
    p.write_text(_geom_text("B", B).replace("ossimRpcModel", "ossimLandSatModel"))
    with pytest.raises(FileFormatError, match="not an RPC model"):
        read_rpc(p)


def test_cli_reads_a_geom(cli, tmp_path):
    p = tmp_path / "scene.geom"
    p.write_text(_geom_text("A", A))
    code, out, err = cli("rpc", "info", p)
    assert code == 0, err
    assert "OSSIM keyword list" in out
