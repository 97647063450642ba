"""Numerical conditioning and degenerate geometry."""

from __future__ import annotations

import numpy as np
import pytest

import photogeom as pg
from photogeom import ExteriorOrientation, InteriorOrientation, project
from photogeom.errors import DegenerateGeometryError, InputError

IO_MM = InteriorOrientation(f=35.0, unit="mm")
EO_TRUE = ExteriorOrientation(100.0, -50.0, 400.0, 0.02, -0.03, 0.4)


def _three_points(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(-200, 300, 3), rng.uniform(-250, 150, 3), rng.uniform(0, 50, 3)]
    return g, project(g, IO_MM, EO_TRUE)


@pytest.mark.parametrize("seed", [0, 3, 7, 11])
def test_resection_with_a_repeated_point_is_three_points_not_four(seed):
    # Three distinct points and one of them listed twice: up to four exterior orientations
    # fit exactly. Before: one was returned silently (hundreds of metres off for 2/3 of
    # random cases), sigma0 ~1e-14, redundancy 2. Now: the three-point error, naming it.
    g, im = _three_points(seed)
    g4, im4 = np.r_[g, g[:1]], np.r_[im, im[:1]]
    sols = pg.p3p(g, im, IO_MM)
    if len(sols) == 1:
        fit = pg.space_resection(g4, im4, IO_MM)
        assert abs(fit.exterior.X0 - EO_TRUE.X0) < 1e-6
        return
    with pytest.raises(InputError, match=r"only 3 distinct ground positions.*initial="):
        pg.space_resection(g4, im4, IO_MM)
    fit = pg.space_resection(g4, im4, IO_MM, initial=EO_TRUE)
    assert abs(fit.exterior.X0 - EO_TRUE.X0) < 1e-6


def test_resection_many_repeats_of_three_points_never_returns_a_wrong_orientation():
    for seed in range(60):
        g, im = _three_points(seed)
        g9, im9 = np.r_[g, g, g], np.r_[im, im, im]
        try:
            fit = pg.space_resection(g9, im9, IO_MM)
        except InputError:
            continue
        assert np.hypot(fit.exterior.X0 - EO_TRUE.X0, fit.exterior.Y0 - EO_TRUE.Y0) < 1e-6


def test_resection_with_two_distinct_positions_names_the_repeat():
    g, im = _three_points(1)
    g4, im4 = np.r_[g[:2], g[:2]], np.r_[im[:2], im[:2]]
    with pytest.raises(DegenerateGeometryError, match="only 2 distinct ground position"):
        pg.space_resection(g4, im4, IO_MM)


# --- terrain-dependent RPC fit: control that cannot determine the coefficients -------------


def _ikonos_points(n: int, seed: int, heights=None):
    from photogeom.rpc import RPC

    vendor = RPC.from_file(pg.datasets.path("ikonos"))
    rng = np.random.default_rng(seed)
    cols, rows = rng.uniform(0, 12000, n), rng.uniform(0, 10000, n)
    h = rng.uniform(0, 100, n) if heights is None else rng.choice(heights, n)
    lon, lat = vendor.localize(cols, rows, h)
    return np.column_stack([lon, lat, h]), np.column_stack([cols, rows])


def test_rpc_fit_to_repeated_points_is_refused_by_name():
    # Before: 4 positions x 10 fitted order 1 (7 coefficients per coordinate) with
    # sigma0 7e-11, redundancy 66 and standard deviations 1e-8, but 7675 px off elsewhere.
    from photogeom.rpc import fit_rpc_to_points

    G, im = _ikonos_points(4, 1)
    with pytest.raises(DegenerateGeometryError, match="only 4 distinct ground positions"):
        fit_rpc_to_points(np.repeat(G, 10, axis=0), np.repeat(im, 10, axis=0), order=1)


def test_rpc_fit_at_two_heights_refuses_the_quadratic_height_term():
    # Before: order 2 at two heights fitted to rmse 1e-5 px and was 3874 px off between them.
    from photogeom.rpc import fit_rpc_to_points

    G, im = _ikonos_points(60, 2, heights=[0.0, 100.0])
    assert fit_rpc_to_points(G, im, order=1).rmse < 1.0
    for order in (2, 3):
        with pytest.raises(DegenerateGeometryError, match=r"only \d height.*order=1"):
            fit_rpc_to_points(G, im, order=order)


def test_rpc_fit_on_one_vertical_plane_is_refused():
    from photogeom.rpc import RPC, fit_rpc_to_points

    vendor = RPC.from_file(pg.datasets.path("ikonos"))
    G, _ = _ikonos_points(60, 3)
    G[:, 1] = G[0, 1] + (G[:, 0] - G[0, 0]) * 0.7  # lon and lat on one line
    im = np.column_stack(vendor.project(G[:, 0], G[:, 1], G[:, 2]))
    with pytest.raises(DegenerateGeometryError, match="terms L, P"):
        fit_rpc_to_points(G, im, order=1)


def test_rpc_fit_command_names_the_order_option(tmp_path, cli):
    G, im = _ikonos_points(60, 2, heights=[0.0, 100.0])
    path = tmp_path / "gcp.csv"
    rows = [f"P{i},{lo:.9f},{la:.9f},{h:.3f},{c:.3f},{r:.3f}" for i, ((c, r), (lo, la, h))
            in enumerate(zip(im, G))]  # fmt: skip
    path.write_text("id,lon,lat,h,col,row\n" + "\n".join(rows) + "\n")
    code, _out, err = cli("rpc", "fit", path, "--order", "2", "--output", tmp_path / "o.rpb")
    assert code != 0
    assert "only 2 height(s)" in err and "--order 1" in err, err


# --- relative orientation: repeated tie points --------------------------------------------

EO_LEFT = ExteriorOrientation(0.0, 0.0, 400.0)
EO_RIGHT = ExteriorOrientation(150.0, 5.0, 402.0, 0.01, -0.02, 0.03)


def _five_ties(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    g = np.c_[rng.uniform(-100, 250, 5), rng.uniform(-150, 150, 5), rng.uniform(0, 80, 5)]
    return project(g, IO_MM, EO_LEFT), project(g, IO_MM, EO_RIGHT)


def test_relative_orientation_of_five_repeated_ties_is_the_five_point_case():
    # Before: five tie points and three of them listed again returned one of the five-point
    # solutions silently (100 random cases: 43 wrong, 34 right, 23 errors); exactly five
    # points raised the 'several orientations' error in all the ambiguous ones.
    truth = np.array([5.0 / 150.0, 2.0 / 150.0])
    for seed in range(12):
        x1, x2 = _five_ties(seed)
        y1, y2 = np.r_[x1, x1[:3]], np.r_[x2, x2[:3]]
        try:
            pg.relative_orientation(x1, x2, IO_MM)
            five_ok = True
        except DegenerateGeometryError:
            five_ok = False
        try:
            fit = pg.relative_orientation(y1, y2, IO_MM)
        except DegenerateGeometryError as exc:
            assert not five_ok, exc
            continue
        assert five_ok
        assert np.allclose(fit.parameters[:2], truth, atol=1e-6)


def test_relative_orientation_with_fewer_than_five_distinct_ties_names_the_repeat():
    # before: ConvergenceError 'iteration limit 50 reached ... raise max_iter'
    x1, x2 = _five_ties(0)
    with pytest.raises(pg.TooFewPointsError, match="only 4 distinct pairs"):
        pg.relative_orientation(np.r_[x1[:4], x1[:4]], np.r_[x2[:4], x2[:4]], IO_MM)


# --- angles near gimbal lock: the matrix from the angles is the matrix ---------------------


def _near_lock_rotations(count: int, dphi_deg: float, seed: int = 0) -> np.ndarray:
    """Rotations at phi = +-(90 - dphi) degrees, rounded through a quaternion (errors of
    1e-16 in every entry, as any computed rotation has)."""
    rng = np.random.default_rng(seed)
    phi = np.radians(90.0 - dphi_deg) * rng.choice([-1.0, 1.0], count)
    M = pg.opk_matrix(rng.uniform(-3, 3, count), phi, rng.uniform(-3, 3, count))
    return pg.matrix_from_quaternion(pg.quaternion_from_matrix(M))


@pytest.mark.parametrize("dphi_deg", [1e-3, 1e-5, 1e-7])
def test_opk_from_matrix_reproduces_the_matrix_near_gimbal_lock(dphi_deg):
    # before: 5e-12, 6e-10, 7e-8 (the textbook kappa = atan2(-m21, m11))
    M = _near_lock_rotations(200, dphi_deg)
    w, p, k = pg.opk_from_matrix(M)
    assert np.max(np.abs(pg.opk_matrix(w, p, k) - M)) < 5e-15
    for Mi in M[:20]:  # the scalar path and the exterior orientation built on it
        eo = ExteriorOrientation.from_matrix([0.0, 0.0, 0.0], Mi)
        assert np.max(np.abs(eo.matrix - Mi)) < 5e-15


def test_opk_from_matrix_unchanged_away_from_the_lock():
    rng = np.random.default_rng(1)
    a = rng.uniform(-1.4, 1.4, (3, 500))
    M = pg.opk_matrix(*a)
    w, p, k = pg.opk_from_matrix(M)
    m = M
    assert np.array_equal(k, np.arctan2(-m[:, 1, 0], m[:, 0, 0]))
    assert np.allclose(np.array([w, p, k]), a, atol=1e-14)


def test_absolute_orientation_angles_give_its_rotation_near_gimbal_lock():
    # before: the fitted omega, phi, kappa rebuilt R only to 2.9e-7 at phi = 90 - 1e-7 deg
    x = np.random.default_rng(2).uniform(-100, 100, (10, 3))
    for R in np.swapaxes(_near_lock_rotations(10, 1e-7, seed=3), 1, 2):
        X = 1.2 * x @ R.T + [5.0, 6.0, 7.0]
        for method in ("svd", "gauss-markov"):
            fit = pg.absolute_orientation(x, X, method=method)
            p = dict(zip(fit.parameter_names, fit.parameters))
            Rp = pg.opk_matrix(p["omega"], p["phi"], p["kappa"]).T
            assert np.max(np.abs(Rp - R)) < 1e-13


# --- space resection at phi = +-90 degrees ---------------------------------------------------


def _horizontal_camera(phi_deg: float, noise: float, seed: int):
    rng = np.random.default_rng(seed)
    eo = ExteriorOrientation.from_degrees(100.0, -50.0, 40.0, 10.0, phi_deg, 20.0)
    d = np.c_[rng.uniform(-0.4, 0.4, 20), rng.uniform(-0.3, 0.3, 20), -np.ones(20)]
    g = eo.position + (d * rng.uniform(50, 150, (20, 1))) @ eo.matrix
    return g, project(g, IO_MM, eo) + rng.normal(0, noise, (20, 2)), eo


@pytest.mark.parametrize("phi_deg", [90.0, -90.0])
def test_resection_started_at_gimbal_lock_converges(phi_deg):
    # Before: initial= at phi = +-90 deg raised 'omega, kappa are undetermined ... Add
    # observations with better geometry or fix those parameters' (the start's Jacobian is
    # singular); without initial= the same data gave the orientation.
    g, im, eo = _horizontal_camera(phi_deg, 0.001, 0)
    free = pg.space_resection(g, im, IO_MM)
    fit = pg.space_resection(g, im, IO_MM, initial=eo)
    assert np.max(np.abs(fit.exterior.matrix - free.exterior.matrix)) < 1e-9
    assert np.linalg.norm(fit.exterior.position - eo.position) < 0.02


def test_resection_converging_onto_gimbal_lock_says_so():
    g, im, eo = _horizontal_camera(90.0, 0.0, 1)
    with pytest.raises(DegenerateGeometryError, match=r"phi = \+-90 degrees.*turned about"):
        pg.space_resection(g, im, IO_MM, initial=eo)


# --- batched resections: degenerate problems --------------------------------------------------


def test_resection_batch_with_coinciding_control_names_the_problem():
    # before: numpy.linalg.LinAlgError 'Singular matrix'
    g = np.array([[10.0, 20.0, 30.0]] * 4)
    start = ExteriorOrientation(90.0, -40.0, 390.0, 0.0, 0.0, 0.3)
    im = np.broadcast_to(project(g, IO_MM, EO_TRUE), (2, 4, 2))
    with pytest.raises(DegenerateGeometryError, match=r"problem\(s\) 0, 1 .*coincide or lie"):
        pg.space_resection_batch(g, im, IO_MM, start)


def test_resection_batch_with_collinear_control_is_refused_not_converged():
    # before: parameters 60-80 m off, converged=True, std NaN (RuntimeWarning in sqrt)
    g = np.array([[10.0, 20, 30], [10, 20, 30], [50, 60, 10], [50, 60, 10]])
    good = np.c_[np.random.default_rng(0).uniform(-200, 300, (6, 2)), np.zeros(6)]
    start = ExteriorOrientation(90.0, -40.0, 390.0, 0.0, 0.0, 0.3)
    ground = np.stack([good[:4], g])
    im = np.stack([project(good[:4], IO_MM, EO_TRUE), project(g, IO_MM, EO_TRUE)])
    with pytest.raises(DegenerateGeometryError, match=r"problem\(s\) 1 \(1 in all\)"):
        pg.space_resection_batch(ground, im, IO_MM, start)


def test_resection_batch_agrees_with_space_resection_and_starts_off_the_lock():
    g, im, eo = _horizontal_camera(90.0, 0.001, 0)
    single = pg.space_resection(g, im, IO_MM)
    batch = pg.space_resection_batch(g, im[None], IO_MM, eo)
    assert batch.converged[0]
    assert np.max(np.abs(batch.exterior(0).matrix - single.exterior.matrix)) < 1e-9
    g2, im2, _ = _horizontal_camera(30.0, 0.001, 1)
    one = pg.space_resection(g2, im2, IO_MM)
    many = pg.space_resection_batch(g2, im2[None], IO_MM, one.exterior)
    assert np.allclose(many.parameters[0], one.parameters, rtol=0, atol=1e-9)
    assert np.allclose(many.std[0], list(one.std_errors.values()), rtol=1e-6)


def test_terrain_independent_rpc_grid_needs_order_plus_one_nodes_per_axis():
    # before: grid (9, 9, 2), order 2: rmse 1e-5 px on the grid, check RMSE 1310 px, no note
    from photogeom.rpc import fit_rpc

    bounds = [[10.98, 11.02], [47.99, 48.01], [0.0, 600.0]]
    io = pg.InteriorOrientation(f=10000.0, unit="px", origin_px=(3999.5, 2999.5))
    eo = pg.ExteriorOrientation(0.0, 0.0, 3000.0)

    def camera(g):  # a rough local tangent plane is enough here
        enu = np.column_stack([(g[:, 0] - 11.0) * 74500.0, (g[:, 1] - 48.0) * 111200.0,
                               g[:, 2]])  # fmt: skip
        return pg.project(enu, io, eo, system="pixel", behind="nan")

    msg = r"2 node\(s\) along height.*grid=\(9, 9, 3\)"
    with pytest.raises(DegenerateGeometryError, match=msg):
        fit_rpc(camera, bounds, grid=(9, 9, 2), order=2)
    with pytest.raises(DegenerateGeometryError, match="needs at least 4"):
        fit_rpc(camera, bounds, grid=(9, 9, 3), order=3)
    fit = fit_rpc(camera, bounds, grid=(9, 9, 3), order=2)
    assert fit.check_rmse < 1e-3
    assert fit_rpc(camera, bounds, grid=(9, 9, 2), order=1).check_rmse < 5.0


# --- DLT: repeated control points ------------------------------------------------------------


def _dlt_points(k: int, m: int):
    rng = np.random.default_rng(3)
    g = np.c_[rng.uniform(-200, 300, k), rng.uniform(-250, 150, k), rng.uniform(0, 50, k)]
    g = g[np.arange(m) % k]
    return g, project(g, IO_MM, EO_TRUE)


def test_constrained_dlt_of_five_distinct_points_listed_twice_works():
    # before: 'constrained DLT (linear): the observations do not determine the parameters
    # (L1, L2, ...)' although the same five points alone gave the orientation
    g, im = _dlt_points(5, 8)
    fit = pg.estimate_dlt(g, im, constrained=True)
    _, eo = pg.orientation_from_dlt(fit.model)
    assert np.max(np.abs(eo.position - EO_TRUE.position)) < 1e-6


def test_dlt_with_too_few_distinct_points_names_the_repeat():
    g, im = _dlt_points(5, 12)
    with pytest.raises(pg.TooFewPointsError, match="only 5 distinct ground positions"):
        pg.estimate_dlt(g, im)
    g, im = _dlt_points(4, 8)
    with pytest.raises(pg.TooFewPointsError, match="only 4 distinct ground positions"):
        pg.estimate_dlt(g, im, constrained=True)


# --- relative orientation: short base (base / distance below 1/50) ---------------------------


@pytest.mark.parametrize("base", [15.0, 10.0])
def test_relative_orientation_of_a_short_base_is_found(base):
    # Before: 'no essential matrix has five or more points in front of both cameras; check
    # the matches' for base / distance below 1/50 (OpenCV's recoverPose drops points farther
    # than 50 bases), although the parallaxes (0.35 mm at f = 35 mm for base 10 m at 1 km)
    # are 175 times the noise.
    rng = np.random.default_rng(5)
    e1 = ExteriorOrientation(0.0, 0.0, 1000.0)
    e2 = ExteriorOrientation(base, 0.0, 1000.0, 0.01, -0.02, 0.03)
    g = np.c_[rng.uniform(-300, 300, 50), rng.uniform(-300, 300, 50), rng.uniform(0, 100, 50)]
    x1 = project(g, IO_MM, e1) + rng.normal(0, 0.002, (50, 2))
    x2 = project(g, IO_MM, e2) + rng.normal(0, 0.002, (50, 2))
    fit = pg.relative_orientation(x1, x2, IO_MM, sigma=0.002)
    p = dict(zip(fit.parameter_names, fit.parameters))
    for name, truth in (("by", 0.0), ("bz", 0.0), ("omega2", 0.01), ("phi2", -0.02)):
        assert abs(p[name] - truth) < 4 * fit.std_errors[name], name


# --- RPCs on the antimeridian ------------------------------------------------------------------


def _antimeridian_rpc():
    from dataclasses import replace as dc_replace

    from photogeom.rpc import RPC

    vendor = RPC.from_file(pg.datasets.path("ikonos"))
    return dc_replace(vendor, long_off=179.99)  # the same scene moved onto the antimeridian


def test_rpc_projects_longitudes_given_on_either_side_of_the_antimeridian():
    # before: a point at lon -179.94 (= 180.06) projected 1.2e7 px off (an extrapolation
    # warning), and localize returned 180.06
    rpc = _antimeridian_rpc()
    c0, c1, r0, r1 = rpc.image_bounds
    cols = np.array([c0 + 10, c1 - 10, 0.5 * (c0 + c1)])
    rows = np.array([r0 + 10, r1 - 10, 0.5 * (r0 + r1)])
    h = np.full(3, rpc.height_off)
    lon, lat = rpc.localize(cols, rows, h)
    assert np.all(np.abs(lon) <= 180.0) and lon.min() < 0 < lon.max()
    col, row = rpc.project(lon, lat, h)
    assert np.max(np.abs(col - cols)) < 1e-6 and np.max(np.abs(row - rows)) < 1e-6
    east = lon < 0
    col2, _ = rpc.project(np.where(east, lon + 360.0, lon), lat, h)  # 180.06 works as well
    assert np.max(np.abs(col2 - cols)) < 1e-6


def test_rpc_fit_to_points_across_the_antimeridian():
    # before: the box of the points ran from -179.998 to 179.996 (LONG_OFF ~0, scale 180):
    # the fit was meaningless
    from photogeom.rpc import fit_rpc_to_points

    rpc = _antimeridian_rpc()
    rng = np.random.default_rng(0)
    c0, c1, r0, r1 = rpc.image_bounds
    cols, rows = rng.uniform(c0, c1, 40), rng.uniform(r0, r1, 40)
    h = rng.uniform(*rpc.height_range, 40)
    lon, lat = rpc.localize(cols, rows, h)
    assert lon.min() < -179.9 and lon.max() > 179.9
    fit = fit_rpc_to_points(np.c_[lon, lat, h], np.c_[cols, rows], order=1)
    assert abs(abs(fit.model.long_off) - 180.0) < 0.05 and fit.model.long_scale < 0.1
    assert fit.rmse < 1.0


# --- RPC inputs: masked, complex and low-precision arrays ----------------------------------------


def test_rpc_refuses_masked_heights_instead_of_using_the_hidden_values():
    # before: the masked -9999 m was used (a column 1250 px off, an extrapolation warning)
    from photogeom.errors import InputError as _InputError
    from photogeom.rpc import RPC

    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    h = np.ma.masked_array([100.0, 120.0, -9999.0], mask=[0, 0, 1])
    lon, lat = np.full(3, rpc.long_off), np.full(3, rpc.lat_off)
    with pytest.raises(_InputError, match="h: masked array"):
        rpc.project(lon, lat, h)
    with pytest.raises(_InputError, match="h: masked array"):
        rpc.localize(np.full(3, rpc.samp_off), np.full(3, rpc.line_off), h)
    with pytest.raises(_InputError, match="complex"):
        rpc.project(lon + 0j, lat, 100.0)
    obs = np.ma.masked_array(np.zeros((2, 2, 2)), mask=np.zeros((2, 2, 2), bool))
    obs.mask[0, 1] = True
    with pytest.raises(_InputError, match=r"NaN where an image does not see"):
        pg.intersect_rpc([rpc, rpc], obs)


def test_rpc_reports_float32_longitudes():
    # before: float32 lon/lat (resolution 3.8e-6 deg, 0.3 m) moved the column by 0.17 px silently
    from photogeom.errors import PrecisionWarning
    from photogeom.rpc import RPC

    rpc = RPC.from_file(pg.datasets.path("ikonos"))
    lon = np.float32([rpc.long_off]) + np.float32(0.01)
    with pytest.warns(PrecisionWarning, match="lon in float32"):
        rpc.project(lon, np.array([rpc.lat_off]), np.float32([100.0]))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", PrecisionWarning)
        rpc.project(np.float64(rpc.long_off), rpc.lat_off, np.float32(100.0))  # h: 7.6e-6 m


# --- apply / project paths read points like the estimators -------------------------------------


def test_apply_and_project_refuse_masked_points_and_report_float32():
    from photogeom.errors import InputError as _InputError
    from photogeom.errors import PrecisionWarning

    rng = np.random.default_rng(0)
    src = rng.uniform(-500, 500, (10, 3)) + np.array([500000.0, 5000000.0, 300.0])
    tf = pg.estimate_transform("similarity3d", src, src + 1.0).transform
    masked = np.ma.masked_array(src[:2], mask=[[0, 0, 0], [0, 0, 1]])
    eo = ExteriorOrientation(500100.0, 5000000.0, 1000.0, 0.02, -0.03, 0.4)
    calls = {
        "transform": lambda a: tf(a),
        "project": lambda a: project(a, IO_MM, eo),
        "dlt": lambda a: pg.DLT(pg.dlt_from_orientation(IO_MM, eo), "mm").project(a),
    }
    for call in calls.values():
        # before: the hidden value of the masked cell was used without a word
        with pytest.raises(_InputError, match="masked array"):
            call(masked)
        # before: float32 (0.5 m resolution at 5e6) passed silently
        with pytest.warns(PrecisionWarning, match="float32"):
            call(src.astype(np.float32))
    with pytest.raises(_InputError, match="masked array"):
        pg.ground_at_height(np.zeros((2, 2)), IO_MM, eo, np.ma.masked_array([0.0, 1.0], [0, 1]))
    io_px = pg.InteriorOrientation(f=35.0, unit="mm", pixel_size=0.005, origin_px=(100, 100))
    with pytest.raises(_InputError, match="masked array"):
        io_px.image_to_pixel(np.ma.masked_array([[0.0, 0.0], [1.0, 1.0]], [[0, 0], [0, 1]]))


def test_resection_with_control_on_a_line_says_so():
    # before: 'no start values found (... or the control is degenerate); pass initial=' and,
    # with initial=, 'X0, Y0, omega, phi are undetermined ... fix those parameters'
    t = np.random.default_rng(3).uniform(-1, 1, 20)
    g = np.c_[100 + 200 * t, 50 + 100 * t, 10 + 5 * t]
    im = project(g, IO_MM, EO_TRUE)
    for initial in (None, EO_TRUE):
        with pytest.raises(DegenerateGeometryError, match="lie on one line"):
            pg.space_resection(g, im, IO_MM, initial=initial)
