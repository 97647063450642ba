"""RPC model: projection vs the spec formula, Jacobian, conventions, corrections, input checks."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import photogeom as pg
from photogeom.errors import FileFormatError, InputError
from photogeom.rpc import RPC, RPCExtrapolationWarning

NAMES = ("quickbird", "ikonos", "skysat", "pleiades", "worldview2")


@pytest.fixture(scope="module", params=NAMES)
def rpc(request) -> RPC:
    return RPC.from_file(pg.datasets.path(request.param))


def spec_projection(rpc: RPC, lon: float, lat: float, h: float) -> tuple[float, float]:
    """The spec's formula written out term by term (independent of the library's code)."""
    L = (lon - rpc.long_off) / rpc.long_scale
    P = (lat - rpc.lat_off) / rpc.lat_scale
    H = (h - rpc.height_off) / rpc.height_scale
    t = [1, L, P, H, L * P, L * H, P * H, L**2, P**2, H**2, P * L * H, L**3, L * P**2,
         L * H**2, L**2 * P, P**3, P * H**2, L**2 * H, P**2 * H, H**3]  # fmt: skip

    def ratio(num, den):
        return sum(a * b for a, b in zip(num, t)) / sum(a * b for a, b in zip(den, t))

    row = rpc.line_scale * ratio(rpc.line_num, rpc.line_den) + rpc.line_off
    col = rpc.samp_scale * ratio(rpc.samp_num, rpc.samp_den) + rpc.samp_off
    return col, row


def ground_sample(rpc: RPC, n: int, seed: int = 0) -> np.ndarray:
    g = np.random.default_rng(seed).uniform(-1, 1, (n, 3))
    return np.column_stack([
        g[:, 0] * rpc.long_scale + rpc.long_off,
        g[:, 1] * rpc.lat_scale + rpc.lat_off,
        g[:, 2] * rpc.height_scale + rpc.height_off,
    ])  # fmt: skip


def test_projection_matches_spec_formula(rpc):
    G = ground_sample(rpc, 25)
    col, row = rpc.project(G[:, 0], G[:, 1], G[:, 2])
    for i in range(G.shape[0]):
        c, r = spec_projection(rpc, *G[i])
        assert col[i] == pytest.approx(c, abs=1e-7)
        assert row[i] == pytest.approx(r, abs=1e-7)


def test_projection_of_many_points_in_blocks_matches_single_points(rpc):
    # more points than one evaluation block: block boundaries must not matter
    G = ground_sample(rpc, 20000, seed=1)
    col, row = rpc.project(G[:, 0], G[:, 1], G[:, 2])
    for i in (0, 8191, 8192, 16383, 16384, 19999):
        c, r = rpc.project(G[i, 0], G[i, 1], G[i, 2])
        assert col[i] == pytest.approx(c, abs=1e-9) and row[i] == pytest.approx(r, abs=1e-9)


def test_offsets_map_to_the_image_offset_at_zero_normalised_ground(rpc):
    # at L = P = H = 0 every term but the constant vanishes
    col, row = rpc.project(rpc.long_off, rpc.lat_off, rpc.height_off)
    assert col == pytest.approx(
        rpc.samp_scale * rpc.samp_num[0] / rpc.samp_den[0] + rpc.samp_off, abs=1e-9
    )
    assert row == pytest.approx(
        rpc.line_scale * rpc.line_num[0] / rpc.line_den[0] + rpc.line_off, abs=1e-9
    )


def test_jacobian_matches_central_differences(rpc):
    G = ground_sample(rpc, 7, seed=2)
    J = rpc.jacobian(G[:, 0], G[:, 1], G[:, 2])
    steps = (1e-6 * rpc.long_scale, 1e-6 * rpc.lat_scale, 1e-6 * rpc.height_scale)
    for j, hstep in enumerate(steps):
        d = np.zeros(3)
        d[j] = hstep
        cp, rp = rpc.project(*(G + d).T)
        cm, rm = rpc.project(*(G - d).T)
        fd = np.column_stack([(cp - cm), (rp - rm)]) / (2 * hstep)
        scale = np.abs(J[:, :, j]).max() + 1e-300
        np.testing.assert_allclose(J[:, :, j], fd, atol=1e-6 * scale)


def test_shapes_and_scalars():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    c, r = rpc.project(-56.17, -34.9, 30.0)
    assert np.ndim(c) == 0 and np.ndim(r) == 0
    lon = np.full((3, 4), -56.17)
    c, r = rpc.project(lon, -34.9, np.array([0.0, 10.0, 20.0, 30.0]))
    assert c.shape == (3, 4) and r.shape == (3, 4)
    lo, _ = rpc.localize(c, r, np.array([0.0, 10.0, 20.0, 30.0]))
    assert lo.shape == (3, 4)
    np.testing.assert_allclose(lo, lon, atol=1e-10)


def test_missing_or_invalid_heights_are_errors():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    with pytest.raises(InputError, match="no height"):
        rpc.project(-56.17, -34.9, None)
    with pytest.raises(InputError, match="height without a value"):
        rpc.project([-56.17, -56.18], [-34.9, -34.9], [10.0, np.nan])
    with pytest.raises(InputError, match="no height"):
        rpc.localize(100.0, 100.0, None)
    with pytest.raises(InputError, match="NaN or infinite"):
        rpc.project([np.inf], [-34.9], [1.0])
    with pytest.raises(InputError, match="broadcast"):
        rpc.project([1.0, 2.0, 3.0], [1.0, 2.0], 0.0)


def test_far_outside_the_domain_warns():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    with pytest.warns(RPCExtrapolationWarning, match="extrapolate"):
        rpc.project(rpc.long_off + 3 * rpc.long_scale, rpc.lat_off, rpc.height_off)
    with pytest.warns(RPCExtrapolationWarning, match="height"):
        rpc.project(rpc.long_off, rpc.lat_off, rpc.height_off + 10 * rpc.height_scale)
    with pytest.warns(RPCExtrapolationWarning, match="column"):
        rpc.localize(rpc.samp_off + 5 * rpc.samp_scale, rpc.line_off, rpc.height_off)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rpc.project(rpc.long_off + 1.2 * rpc.long_scale, rpc.lat_off, rpc.height_off)
        rpc.project(rpc.long_off + 3 * rpc.long_scale, rpc.lat_off, 0.0, domain_limit=None)


def test_constructor_checks_coefficient_counts_and_scales():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    d = rpc.to_dict()
    d["LINE_NUM_COEFF"] = d["LINE_NUM_COEFF"][:19]
    with pytest.raises(FileFormatError, match="LINE_NUM_COEFF has 19 coefficient"):
        RPC.from_dict(d)
    fields = {k: getattr(rpc, k) for k in ("line_off", "samp_off", "lat_off", "long_off",
              "height_off", "line_scale", "samp_scale", "lat_scale", "long_scale",
              "height_scale", "line_den", "samp_num", "samp_den")}  # fmt: skip
    with pytest.raises(InputError, match="21 coefficient"):
        RPC(**fields, line_num=np.zeros(21))
    d = rpc.to_dict()
    d["LAT_SCALE"] = 0.0
    with pytest.raises(FileFormatError, match="LAT_SCALE is 0"):
        RPC.from_dict(d)


def test_correction_is_applied_after_projection_and_inverted_in_localisation():
    rpc = RPC.from_file(pg.datasets.path("worldview2"))
    D = np.array([[2e-4, -1e-4, 12.5], [3e-5, 1.5e-4, -8.0]])
    cor = rpc.with_correction(D)
    G = ground_sample(rpc, 50, seed=3)
    c, r = rpc.project(*G.T)
    cc, rc = cor.project(*G.T)
    np.testing.assert_allclose(cc, c + 12.5 + 2e-4 * c - 1e-4 * r, atol=1e-9)
    np.testing.assert_allclose(rc, r - 8.0 + 3e-5 * c + 1.5e-4 * r, atol=1e-9)
    lon, lat = cor.localize(cc, rc, G[:, 2])
    np.testing.assert_allclose(lon, G[:, 0], atol=1e-11)
    np.testing.assert_allclose(lat, G[:, 1], atol=1e-11)
    # Jacobian of the corrected model includes the affine part
    J = cor.jacobian(*G[:3].T)
    J0 = rpc.jacobian(*G[:3].T)
    np.testing.assert_allclose(J, np.einsum("ij,njk->nik", np.eye(2) + D[:, :2], J0), rtol=1e-12)
    # composition: two corrections equal their composed affine map
    D2 = np.array([[0.0, 0.0, -1.0], [0.0, 1e-4, 2.0]])
    twice = cor.with_correction(D2)
    c2, r2 = twice.project(*G.T)
    np.testing.assert_allclose(c2, cc - 1.0, atol=1e-9)
    np.testing.assert_allclose(r2, rc + 2.0 + 1e-4 * rc, atol=1e-9)
    assert twice.uncorrected.correction is None


def test_shift_and_scale_corrections_fold_exactly_into_offsets():
    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    cor = rpc.with_correction([[1e-4, 0.0, 3.25], [0.0, -2e-4, -1.5]])
    folded = cor.with_correction_folded()
    assert folded.correction is None
    G = ground_sample(rpc, 30, seed=4)
    np.testing.assert_allclose(
        np.array(folded.project(*G.T)), np.array(cor.project(*G.T)), atol=1e-8
    )
    with pytest.raises(InputError, match="cross terms"):
        rpc.with_correction([[0.0, 1e-4, 0.0], [0.0, 0.0, 0.0]]).with_correction_folded()


def test_image_bounds_and_summary():
    wv = RPC.from_file(pg.datasets.path("worldview2"))
    assert wv.image_size == (28244, 20289)
    assert wv.image_bounds == (0.0, 28243.0, 0.0, 20288.0)
    text = wv.summary()
    assert "centre of the first pixel" in text and "28244 x 20289" in text
    fp = wv.footprint()
    assert fp.shape == (4, 2)
    # the corners of the WorldView product lie within a few pixels of its IMD corner list
    assert abs(fp[0, 0] - (-0.38829375)) < 1e-3 and abs(fp[0, 1] - 45.69999975) < 1e-3


@settings(max_examples=40, deadline=None)
@given(
    u=st.floats(-1, 1), v=st.floats(-1, 1), w=st.floats(-1, 1),
    name=st.sampled_from(NAMES),
)  # fmt: skip
def test_property_project_then_localize_is_identity(u, v, w, name):
    rpc = _cached(name)
    lon = rpc.long_off + u * 0.9 * _half_footprint(rpc)[0]
    lat = rpc.lat_off + v * 0.9 * _half_footprint(rpc)[1]
    h = rpc.height_off + w * rpc.height_scale
    c, r = rpc.project(lon, lat, h, domain_limit=None)
    lo, la = rpc.localize(c, r, h, domain_limit=None)
    assert abs(lo - lon) < 1e-9 and abs(la - lat) < 1e-9


_CACHE: dict[str, RPC] = {}


def _cached(name: str) -> RPC:
    if name not in _CACHE:
        _CACHE[name] = RPC.from_file(pg.datasets.path(name))
    return _CACHE[name]


def _half_footprint(rpc: RPC) -> tuple[float, float]:
    fp = rpc.footprint()
    return (np.ptp(fp[:, 0]) / 2, np.ptp(fp[:, 1]) / 2)
