"""``--alpha`` of every estimating command whose residual table tests the
residuals (``transform estimate``, ``orient absolute``, ``orient resection``, ``camera dlt
estimate``, ``rpc fit``, ``rpc refine``). They tested at a fixed 0.001 (critical w 3.29);
the level given now reaches the table, ``--json`` (``snooping``) and ``--report``, and the
components flagged are those the library flags at that level."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.adjust.snooping import tau_critical_value
from photogeom.rpc import RPC, fit_rpc_to_points, refine_rpc

W_005 = 1.959963984540054  # the standard normal quantile 1 - 0.05 / 2
IKONOS = RPC.from_file(pg.datasets.path("ikonos"))


def ikonos_points(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` ground points (lon, lat deg, h m) of the bundled IKONOS RPC and their image
    points (col, row px), drawn over the image and its height range."""
    c0, c1, r0, r1 = IKONOS.image_bounds
    cols, rows = rng.uniform(c0, c1, n), rng.uniform(r0, r1, n)
    h = rng.uniform(*IKONOS.height_range, n)
    lon, lat = IKONOS.localize(cols, rows, h)
    return np.column_stack([lon, lat, h]), np.column_stack([cols, rows])


def _csv(path: Path, ids, columns: str, values: np.ndarray) -> Path:
    path.write_text(f"id,{columns}\n" + "".join(
        f"{i}," + ",".join(repr(float(v)) for v in row) + "\n" for i, row in zip(ids, values)
    ))  # fmt: skip
    return path


def _flagged(part) -> set:
    return {(f["id"], f["component"]) for f in (part or {}).get("flagged", [])}


def _library_flagged(fit, alpha: float, sigma: str) -> set:
    sn = fit.snooping(alpha=alpha, sigma=sigma)
    res = np.asarray(fit.residuals)
    rows, cols = np.nonzero(np.asarray(sn.flagged).reshape(res.shape))
    return {(str(fit.ids[k]), fit.residual_labels[j]) for k, j in zip(rows, cols)}


def _check_levels(cli, args, fit) -> dict:
    """The JSON at the default level and at --alpha 0.05: levels, critical values and the
    flagged components against the library's ``fit`` tested at 0.05."""
    code, out, err = cli(*args, "--json")
    assert code == 0, err
    default = json.loads(out)["snooping"]
    assert default["alpha"] == 0.001
    assert default["w"]["critical_value"] == pytest.approx(3.2905267, abs=1e-6)
    code, out, err = cli(*args, "--alpha", "0.05", "--json")
    assert code == 0, err
    sn = json.loads(out)["snooping"]
    assert sn["alpha"] == 0.05
    assert sn["w"]["critical_value"] == pytest.approx(W_005, abs=1e-12)
    assert sn["tau"]["critical_value"] == pytest.approx(
        tau_critical_value(0.05, fit.redundancy), abs=1e-12
    )
    assert _flagged(sn["w"]) == _library_flagged(fit, 0.05, "prior")
    assert _flagged(sn["tau"]) == _library_flagged(fit, 0.05, "posterior")
    # the level changes what is flagged: the test is not a fixed 0.001 under a new label
    assert len(_flagged(sn["w"])) > len(_flagged(default["w"]))
    return sn


def _check_text(cli, args) -> None:
    code, out, err = cli(*args, "--alpha", "0.05")
    assert code == 0, err
    flat = " ".join(out.split())
    assert "critical value 1.960 at alpha = 0.05" in flat
    assert "alpha = 0.001" not in flat


def test_transform_estimate(cli, tmp_path):
    rng = np.random.default_rng(3)
    src = rng.uniform(0, 100, (40, 2))
    tgt = src @ np.array([[1.01, 0.02], [-0.03, 0.99]]).T + [5.0, -2.0]
    tgt = tgt + rng.normal(0, 0.01, tgt.shape)
    ids = [f"P{i}" for i in range(40)]
    s = _csv(tmp_path / "s.csv", ids, "x,y", src)
    t = _csv(tmp_path / "t.csv", ids, "X,Y", tgt)
    args = ("transform", "estimate", "affine2d", s, t, "--sigma0-prior", "0.01")
    s2 = np.loadtxt(s, delimiter=",", skiprows=1, usecols=(1, 2))
    t2 = np.loadtxt(t, delimiter=",", skiprows=1, usecols=(1, 2))
    fit = pg.estimate_transform("affine2d", s2, t2, sigma0_prior=0.01, ids=ids)
    _check_levels(cli, args, fit)
    _check_text(cli, args)
    rep = tmp_path / "r.html"
    code, _, err = cli(*args, "--alpha", "0.05", "--report", rep)
    assert code == 0, err
    assert "alpha = 0.05" in rep.read_text() and "alpha = 0.001" not in rep.read_text()


def _absolute_points(tmp_path):
    rng = np.random.default_rng(5)
    x = rng.uniform(-50, 50, (30, 3))
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    X = 1.5 * x @ R.T + [1000.0, 2000.0, 100.0] + rng.normal(0, 0.01, (30, 3))
    ids = [f"P{i}" for i in range(30)]
    path = _csv(tmp_path / "ab.csv", ids, "x,y,z,X,Y,Z", np.column_stack([x, X]))
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(1, 7))
    return path, ids, data[:, :3], data[:, 3:]


def test_orient_absolute(cli, tmp_path):
    path, ids, x, X = _absolute_points(tmp_path)
    args = ("orient", "absolute", path, "--sigma-target", "0.01")
    fit = pg.absolute_orientation(x, X, "svd", sigma_target=0.01, ids=ids)
    _check_levels(cli, args, fit)
    _check_text(cli, args)


def test_orient_absolute_compare_tests_nothing_so_alpha_is_refused(cli, tmp_path):
    path, *_ = _absolute_points(tmp_path)
    code, _, err = cli("orient", "absolute", path, "--compare", "--alpha", "0.05")
    assert code == 2
    assert "--alpha 0.05" in err and "--compare" in err and "leave --alpha out" in err


def _camera_points(tmp_path):
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eo = pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10)
    rng = np.random.default_rng(2)
    n = 40
    g = np.column_stack([rng.uniform(1050, 1550, n), rng.uniform(750, 1100, n),
                         rng.uniform(100, 300, n)])  # fmt: skip
    xy = pg.project(g, io, eo) + rng.normal(0, 0.003, (n, 2))
    ids = [f"P{i}" for i in range(n)]
    path = _csv(tmp_path / "cam.csv", ids, "X,Y,Z,x,y", np.column_stack([g, xy]))
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(1, 6))
    return path, ids, io, data[:, :3], data[:, 3:]


def test_orient_resection(cli, tmp_path):
    path, ids, io, g, xy = _camera_points(tmp_path)
    args = ("orient", "resection", path, "--f", "152.14", "--x0", "0.008", "--y0", "-0.12",
            "--sigma", "0.003")  # fmt: skip
    fit = pg.space_resection(g, xy, io, sigma=np.full(len(ids), 0.003), ids=ids)
    _check_levels(cli, args, fit)
    _check_text(cli, args)


def test_camera_dlt_estimate(cli, tmp_path):
    path, ids, _, g, xy = _camera_points(tmp_path)
    args = ("camera", "dlt", "estimate", path, "--sigma", "0.003")
    fit = pg.estimate_dlt(g, xy, unit="mm", sigma=np.full(len(ids), 0.003), ids=ids)
    _check_levels(cli, args, fit)
    _check_text(cli, args)


def test_rpc_fit(cli, tmp_path):
    rng = np.random.default_rng(7)
    ground, image = ikonos_points(rng, 60)
    image = image + rng.normal(0, 0.5, image.shape)
    ids = [f"Q{i}" for i in range(60)]
    path = _csv(tmp_path / "ctl.csv", ids, "lon,lat,h,col,row", np.column_stack([ground, image]))
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(1, 6))
    args = ("rpc", "fit", path, "--sigma", "0.5")
    fit = fit_rpc_to_points(data[:, :3], data[:, 3:], order=1, sigma=0.5, ids=ids)
    _check_levels(cli, args, fit)
    _check_text(cli, args)


def test_rpc_refine(cli, tmp_path):
    rng = np.random.default_rng(11)
    ground, image = ikonos_points(rng, 40)
    image = image + np.array([2.0, -1.5]) + rng.normal(0, 0.3, image.shape)
    ids = [f"R{i}" for i in range(40)]
    path = _csv(tmp_path / "ctl.csv", ids, "lon,lat,h,col,row", np.column_stack([ground, image]))
    data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=range(1, 6))
    rpc_file = pg.datasets.path("ikonos")
    args = ("rpc", "refine", rpc_file, path, "--sigma", "0.3")
    fit = refine_rpc(IKONOS, data[:, :3], data[:, 3:], model="affine", sigma=0.3, ids=ids)
    _check_levels(cli, args, fit)
    _check_text(cli, args)


@pytest.mark.parametrize("value", ["0", "1", "nan", "-0.1"])
@pytest.mark.parametrize(
    "command",
    [
        ("transform", "estimate", "affine2d"),
        ("orient", "absolute"),
        ("orient", "resection"),
        ("camera", "dlt", "estimate"),
        ("rpc", "fit"),
    ],
)
def test_alpha_outside_0_1_is_refused_by_its_name_before_reading(cli, tmp_path, command, value):
    code, _, err = cli(*command, tmp_path / "missing.csv", "--alpha", value)
    assert code == 2
    assert f"--alpha must be in (0, 1), got {float(value)}" in err


# --- a level given where no test runs is refused, not silently ignored ----------------------


@pytest.mark.parametrize(
    ("args", "names"),
    [
        (("grid", "fit", "{d}/res.csv", "-o", "{d}/g.npz", "--alpha", "0.01"),
         ("--alpha 0.01", "is off without --snooping", "add --snooping", "leave --alpha out")),
        (("bundle", "adjust", "{d}/blk", "--no-snooping", "--alpha", "0.05"),
         ("--alpha 0.05", "--no-snooping turns off", "leave out --no-snooping or --alpha")),
    ],
)  # fmt: skip
def test_alpha_without_snooping_is_refused_naming_both_options(cli, tmp_path, args, names):
    code, out, err = cli(*(a.format(d=tmp_path) for a in args))
    assert code == 2, (out, err)
    for words in names:
        assert words in err
    assert not (tmp_path / "g.npz").exists()


def test_grid_fit_alpha_with_snooping_still_sets_the_level(cli, tmp_path):
    rng = np.random.default_rng(1)
    uv = rng.uniform(0, [999, 799], (300, 2))
    r = rng.normal(scale=0.3, size=(300, 2))
    _csv(tmp_path / "res.csv", ["A"] * 300, "u,v,rx,ry", np.column_stack([uv, r]))
    (tmp_path / "res.csv").write_text(
        (tmp_path / "res.csv").read_text().replace("id,u,v", "image_id,u,v", 1)
    )
    base = ("grid", "fit", tmp_path / "res.csv", "-o", tmp_path / "g.npz", "--image-size",
            "1000x800", "--sigma-obs", "0.3", "--folds", "0", "--json")  # fmt: skip
    code, out, err = cli(*base)  # no --alpha, no --snooping: as before
    assert code == 0, err
    assert "snooping" not in json.loads(out)
    code, out, err = cli(*base, "--snooping", "--alpha", "0.05")
    assert code == 0, err
    sn = json.loads(out)["snooping"]
    assert sn["alpha"] == 0.05 and sn["critical_value"] == pytest.approx(W_005, abs=1e-12)


_GRID = ("grid", "fit", "{d}/res.csv", "-o", "{d}/g.npz", "--snooping")
_BUNDLE = ("bundle", "adjust", "{d}/blk")
_RELATIVE = ("orient", "relative", "{d}/m.csv")


@pytest.mark.parametrize(
    ("command", "upper", "value"),
    [(c, "1", v) for c in (_GRID, _RELATIVE) for v in ("0", "1", "nan")]
    + [(_BUNDLE, "0.5", v) for v in ("0", "0.5", "nan")],
)
def test_every_alpha_is_refused_in_the_same_words(cli, tmp_path, command, upper, value):
    code, _, err = cli(*(a.format(d=tmp_path) for a in command), "--alpha", value)
    assert code == 2
    assert f"--alpha must be in (0, {upper}), got {float(value)}" in err


def test_snooping_absolute_orientation_records_its_level(tmp_path):
    """Snooping at 0.05 removed four points while the fit's residual table and
    ``to_dict()["snooping"]`` said alpha 0.001, critical value 3.29."""
    from photogeom.orientation import snooping_absolute_orientation
    from photogeom.report.format import residual_table

    _, ids, x, X = _absolute_points(tmp_path)
    X[4] += [0.04, 0.0, 0.0]
    fit = snooping_absolute_orientation(x, X, alpha=0.05, sigma="prior", sigma_target=0.01,
                                        ids=ids)  # fmt: skip
    assert fit.extras["removed"][0] == 4 and fit.extras["alpha"] == 0.05
    d = fit.to_dict()["snooping"]
    assert d["alpha"] == 0.05 and d["w"]["critical_value"] == pytest.approx(W_005, abs=1e-12)
    assert "critical value 1.960 at alpha = 0.05" in residual_table(fit).footer[1]


def test_fit_snooping_defaults_to_the_level_the_fit_was_tested_at(tmp_path):
    """``Fit.snooping()`` tested at 0.001 whatever the fit's estimator recorded, while the
    same fit's tables and ``to_dict()`` tested at the recorded level: a fit of
    ``snooping_absolute_orientation(alpha=0.05)`` gave two answers to "which points fail"."""
    from photogeom.orientation import snooping_absolute_orientation

    _, ids, x, X = _absolute_points(tmp_path)
    X[4] += [0.04, 0.0, 0.0]
    fit = snooping_absolute_orientation(x, X, alpha=0.05, sigma="prior", sigma_target=0.01,
                                        ids=ids)  # fmt: skip
    assert fit.test_level == 0.05
    sn = fit.snooping()
    assert sn.alpha == 0.05 and sn.critical_value == pytest.approx(W_005, abs=1e-12)
    rows, cols = np.nonzero(np.asarray(sn.flagged).reshape(np.shape(fit.residuals)))
    by_default = {(str(fit.ids[k]), fit.residual_labels[j]) for k, j in zip(rows, cols)}
    assert by_default == _flagged(fit.to_dict()["snooping"]["w"])
    # an explicit level still wins, and a fit that records none tests at 0.001
    assert fit.snooping(alpha=0.001).critical_value == pytest.approx(3.2905267, abs=1e-6)
    plain = snooping_absolute_orientation(x, X, sigma="prior", sigma_target=0.01, ids=ids)
    assert plain.test_level == 0.001 and plain.snooping().alpha == 0.001
