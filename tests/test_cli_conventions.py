"""The command line as a user meets it: version, ``python -m``, completion, plain help, quick
start-up (nothing heavy imported before a command needs it), errors in option words, big
files streamed with a progress bar on terminals only, extrapolated RPC localisations,
resection with tie points, RANSAC outliers by id."""

from __future__ import annotations

import ast
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.cli import _stream
from photogeom.io import PointBlocks, read_points, write_points

IKONOS = str(pg.datasets.path("ikonos"))


def _run(*args: str, code: str | None = None) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-c", code] if code else [sys.executable, "-m", "photogeom", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


# --- conventions of a command line ------------------------------------------------------------


def test_version_and_python_dash_m():
    proc = _run("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"photogeom {pg.__version__}"
    proc = _run("transform", "--help")
    assert proc.returncode == 0 and "estimate" in proc.stdout


def test_shell_completion_is_offered(cli):
    _, out, _ = cli("--help")
    assert "--install-completion" in out and "--show-completion" in out


def test_flags_are_shown_as_flags(cli):
    code, out, _ = cli("transform", "estimate", "--help")
    assert code == 0
    assert "<bool>" not in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("--json"))
    assert line.split()[:2] == ["--json", "Print"]


def test_nothing_heavy_is_imported_before_it_is_needed():
    heavy = ["numpy", "scipy", "matplotlib", "pyarrow", "rich", "pandas", "pyproj", "laspy", "dask"]
    probe = (
        "import sys, photogeom, photogeom.cli.main; "
        f"print([m for m in {heavy!r} if m in sys.modules])"
    )
    proc = _run(code=probe)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "[]"
    proc = _run(code="import photogeom as pg, sys; pg.opk_matrix(0, 0, 0); "
                "print('matplotlib' in sys.modules, 'scipy.stats' in sys.modules)")  # fmt: skip
    assert proc.stdout.split() == ["False", "False"]


def _loaded_by(args: list[str], modules: tuple[str, ...]) -> list[str]:
    """Which of ``modules`` the command ``photogeom ARGS`` imported (run in a fresh process)."""
    probe = (
        "import runpy, sys\n"
        "sys.argv = ['photogeom'] + sys.argv[1:]\n"
        "try:\n"
        "    runpy.run_module('photogeom', run_name='__main__')\n"
        "except SystemExit as e:\n"
        "    assert not e.code, e.code\n"
        f"print(sorted(m for m in {modules!r} if m in sys.modules), file=sys.stderr)\n"
    )
    proc = subprocess.run([sys.executable, "-c", probe, *map(str, args)], capture_output=True,
                          text=True, timeout=120)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return ast.literal_eval(proc.stderr.strip().splitlines()[-1])


def test_commands_without_blocks_do_not_load_the_bundle_package(tmp_path, xy_pairs):
    # checking the output options (--output-params, -o) and fitting or applying grids to a
    # CSV must not import the block readers, writers and the adjustment (0.25-0.4 s of CPU:
    # a quarter of a small 'transform estimate')
    params, out = tmp_path / "t.json", tmp_path / "out.csv"
    rng = np.random.default_rng(5)
    uv = rng.uniform(1, 999, (600, 2))
    rows = [f"IMG_{k // 300},{u:.3f},{v:.3f},{rng.normal(0, 0.3):.4f},{rng.normal(0, 0.3):.4f}"
            for k, (u, v) in enumerate(uv)]  # fmt: skip
    residuals, grids = tmp_path / "residuals.csv", tmp_path / "grids.npz"
    residuals.write_text("image_id,u,v,rx,ry\n" + "\n".join(rows) + "\n")
    for args in (
        ["transform", "estimate", "similarity2d", xy_pairs, "--output-params", params],
        ["transform", "apply", params, xy_pairs, "-o", out, "--cols", "x,y"],
        ["grid", "fit", residuals, "--image-size", "1000x1000", "--spacing", "250", "-o", grids],
        ["grid", "apply", grids, residuals, "-o", tmp_path / "corrected.csv"],
    ):
        assert _loaded_by(args, ("photogeom.bundle", "photogeom.simulate")) == [], args
    assert out.read_text().count("\n") >= 7


def test_orient_absolute_loads_matplotlib_only_for_a_report(tmp_path):
    rng = np.random.default_rng(2)
    x = rng.uniform(0, 100, (8, 3))
    X = 1.2 * x + 5 + rng.normal(0, 0.01, x.shape)
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("id,x,y,z,X,Y,Z\n" + "".join(
        f"{i},{','.join(f'{v:.4f}' for v in (*x[i], *X[i]))}\n" for i in range(8)))  # fmt: skip
    for extra in ([], ["--output-params", tmp_path / "p.json"], ["--compare"]):
        assert _loaded_by(["orient", "absolute", pairs, *extra], ("matplotlib",)) == [], extra
    report = tmp_path / "r.html"
    args = ["orient", "absolute", pairs, "--compare", "--report", report]
    assert _loaded_by(args, ("matplotlib",)) == ["matplotlib"]
    assert "<svg" in report.read_text() or "<img" in report.read_text()


def test_bundle_adjust_loads_matplotlib_only_for_a_report(tmp_path):
    block = tmp_path / "block"
    assert _loaded_by(["bundle", "simulate", block, "--strips", "1", "--images-per-strip", "3",
                       "--tie-points-per-image", "60"], ("matplotlib",)) == []  # fmt: skip
    result = tmp_path / "result.json"
    assert _loaded_by(["bundle", "adjust", block, "--result", result], ("matplotlib",)) == []
    assert json.loads(result.read_text())["format"] == "photogeom-bundle-result"
    report = tmp_path / "r.html"
    assert _loaded_by(["bundle", "report", result, "-o", report], ("matplotlib",)) == [
        "matplotlib"
    ]
    assert "<img" in report.read_text()


def test_a_small_estimate_does_not_import_scipy_optimize():
    # the minimal detectable bias of the snooping summary needs one scalar root, not
    # scipy.optimize (0.3-0.5 s of CPU to import, half again of an 8-point estimate)
    fiducials = pg.datasets.path("lecture_fiducials")
    for model in ("similarity2d", "affine2d"):
        args = ["transform", "estimate", model, fiducials]
        assert _loaded_by(args, ("scipy.optimize",)) == [], model


def test_public_names_import_as_before():
    for name in pg.__all__:
        assert getattr(pg, name) is not None, name
    from photogeom import RPC, Similarity3D, space_resection  # noqa: F401
    from photogeom.report import Report, print_fit  # noqa: F401

    assert set(pg.__all__) <= set(dir(pg))


def test_cli_methods_list_matches_the_library():
    from photogeom.cli.orient_absolute import METHODS as CLI_METHODS
    from photogeom.orientation import METHODS

    assert tuple(CLI_METHODS) == tuple(METHODS)


def test_snooping_quantiles_match_scipy_stats():
    from scipy import stats

    from photogeom.adjust.snooping import tau_critical_value

    for alpha, r in [(0.001, 2), (0.05, 7), (0.001, 400)]:
        t = stats.t.ppf(1 - alpha / 2, r - 1)
        assert tau_critical_value(alpha, r) == pytest.approx(t * np.sqrt(r / (r - 1 + t * t)))


# --- errors in the words of the command line ------------------------------------------------


@pytest.fixture
def xy_pairs(tmp_path) -> Path:
    p = tmp_path / "xy.csv"
    p.write_text(
        "id,x,y,X,Y\n1,0,0,10,10\n2,1,0,11,10\n3,0,1,10,11\n4,1,1,11,11.1\n5,2,1,12,11\n"
        "6,1,2,11,12.1\n7,2,2,12,12\n"
    )
    return p


def test_errors_name_options_not_python_arguments(cli, tmp_path, xy_pairs):
    code, _, err = cli("transform", "estimate", "polynomial2d", xy_pairs)
    assert code == 2 and "--order 1, 2, 3" in err and "order=" not in err
    args = ("transform", "estimate", "similarity2d", xy_pairs)
    code, _, err = cli(*args, "--source-system", "pixel")
    assert code == 2 and "--source-system and --target-system" in err and "_system" not in err
    behind = tmp_path / "behind.csv"
    behind.write_text("id,X,Y,Z\n1,1000,800,5000\n")
    code, _, err = cli("camera", "project", behind, "--f", "152", "--eo", "1000,800,1600,0,0,0")
    assert code == 2 and "--behind nan" in err and "behind='nan'" not in err
    assert "--angle-unit" in err and "radians" not in err


def test_rpc_errors_name_the_fix(cli, tmp_path):
    code, _, err = cli("rpc", "info", tmp_path)
    assert code == 2 and "is a directory" in err and "no such file" not in err
    p = tmp_path / "pix.csv"
    p.write_text("id,col,row\n1,100,200\n")
    code, _, err = cli("rpc", "localize", IKONOS, p)
    assert code == 2 and "--height" in err


# --- resection with tie points in the image file ----------------------------------------------


def test_resection_uses_the_points_in_both_files_and_lists_the_rest(cli, tmp_path):
    io_ = pg.InteriorOrientation(152.14, x0=0.008, y0=-0.12, unit="mm")
    eo = pg.ExteriorOrientation(1114.0, 862.0, 1600.0, *np.radians([2.0, 3.0, 10.0]))
    g = np.array([[1000, 800, 100], [1300, 650, 169], [1250, 950, 140], [950, 600, 120],
                  [1150, 700, 180], [1050, 1000, 110.0]])  # fmt: skip
    xy = pg.project(g, io_, eo)
    gcp = tmp_path / "gcp.csv"
    write_points(gcp, [*[f"G{i}" for i in range(6)], "G99"], np.vstack([g, [1, 2, 3]]),
                 ["X", "Y", "Z"])  # fmt: skip
    img = tmp_path / "img.csv"
    write_points(img, [*[f"G{i}" for i in range(6)], "T1", "T2"],
                 np.vstack([xy, [[1, 2], [3, 4]]]), ["x", "y"])  # fmt: skip
    args = ("orient", "resection", gcp, img, "--f", "152.14", "--x0", "0.008", "--y0", "-0.12")
    code, out, err = cli(*args)
    assert code == 0, err
    assert "tie points" in err and "T1, T2" in err and "G99" in err
    assert "6 control" in out
    code, out, err = cli(*args, "--json")
    data = json.loads(out)
    assert data["unmatched"] == {"image_only": ["T1", "T2"], "ground_only": ["G99"]}
    assert data["parameters"]["X0"]["value"] == pytest.approx(1114.0, abs=1e-6)


# --- RANSAC outliers by id --------------------------------------------------------------------


def test_ransac_outliers_are_named_in_text_json_and_html(cli, tmp_path):
    rng = np.random.default_rng(0)
    x = rng.uniform(-20, 20, (30, 3))
    X = x + np.array([5.0, 6.0, 7.0])
    X[[3, 11, 17]] += np.array([[4.0, 0, 0], [0, -6.0, 0], [0, 0, 9.0]])
    f = tmp_path / "pairs.csv"
    write_points(f, [f"p{i}" for i in range(30)], np.hstack([x, X]),
                 ["x", "y", "z", "X", "Y", "Z"])  # fmt: skip
    rep = tmp_path / "r.html"
    base = ("orient", "absolute", f, "--ransac", "--threshold", "0.01", "--seed", "2")
    code, out, err = cli(*base, "--report", rep)
    assert code == 0, err
    assert "RANSAC outliers (3" in out
    for pid, v in (("p3", "4.0000"), ("p11", "6.0000"), ("p17", "9.0000")):
        assert any(ln.split()[:1] == [pid] and v in ln for ln in out.splitlines())
    html = rep.read_text()
    assert "RANSAC outliers (3 of 30 pairs)" in html and "<td>p11</td>" in html.replace(" ", "")
    code, out, _ = cli(*base, "--json")
    d = json.loads(out)["ransac"]
    assert len(d["pair_ids"]) == 30 and len(d["inlier_ids"]) == 27
    assert [o["id"] for o in d["outliers"]] == ["p3", "p11", "p17"]
    np.testing.assert_allclose(d["outliers"][1]["v"], [0, 6.0, 0], atol=1e-9)
    assert json.loads(out)["inliers"].count(False) == 3


# --- big files: streamed, progress on terminals only, extrapolation flagged -----------------


def test_localize_flags_extrapolated_points(cli, tmp_path):
    p = tmp_path / "pix.csv"
    p.write_text("id,col,row,h\nin,6000,6000,5\nfar,-50000,3,0\n")
    code, out, err = cli("rpc", "localize", IKONOS, p)
    assert code == 0, err
    lines = [ln for ln in out.splitlines() if not ln.startswith("#")][1:]
    rows = {ln.split(",")[0]: ln.split(",")[-1] for ln in lines}
    assert rows == {"in": "converged", "far": "extrapolated"}
    assert "1 of 2 point(s) lie outside the domain" in err
    code, out, _ = cli("rpc", "localize", IKONOS, p, "--json")
    d = json.loads(out)
    assert d["counts"]["extrapolated"] == 1 and d["points"][1]["status"] == "extrapolated"


def test_streamed_jobs_equal_the_api_on_arrays(cli, tmp_path, monkeypatch):
    rpc = pg.RPC.from_file(IKONOS)
    c0, c1, r0, r1 = rpc.image_bounds
    rng = np.random.default_rng(5)
    n = 3000
    pix = np.column_stack([rng.uniform(c0, c1, n), rng.uniform(r0, r1, n), rng.uniform(0, 50, n)])
    src = tmp_path / "pix.csv"
    write_points(src, [f"q{i}" for i in range(n)], pix, ["col", "row", "h"])
    small_blocks = {**PointBlocks.__init__.__kwdefaults__, "block_bytes": 4096}
    monkeypatch.setattr(PointBlocks.__init__, "__kwdefaults__", small_blocks)
    out = tmp_path / "g.csv"
    code, _, err = cli("rpc", "localize", IKONOS, src, "-o", out)
    assert code == 0 and f"wrote {n} point(s)" in err
    assert "\x1b" not in err and "eta" not in err  # no progress bar off a terminal
    got = read_points(out, "lon,lat,h")
    lon, lat = rpc.localize(pix[:, 0], pix[:, 1], pix[:, 2])
    np.testing.assert_array_equal(got.coords[:, 0], lon)
    np.testing.assert_array_equal(got.coords[:, 1], lat)
    assert got.ids == tuple(f"q{i}" for i in range(n))
    back = tmp_path / "back.csv"
    code, _, err = cli("rpc", "project", IKONOS, out, "-o", back)
    assert code == 0, err
    col, row = rpc.project(lon, lat, pix[:, 2])
    np.testing.assert_array_equal(read_points(back, "col,row").coords, np.column_stack([col, row]))


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_only_on_terminals_and_for_big_files():
    big = _stream.PROGRESS_BYTES
    assert _stream._wants_progress(big, _Terminal())
    assert not _stream._wants_progress(big - 1, _Terminal())
    assert not _stream._wants_progress(big, io.StringIO())
    with _stream.progress_bar(1000, "job", force=False) as advance:
        advance(500, 10)  # a no-op off a terminal


def test_progress_bar_draws_on_a_terminal(monkeypatch):
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with _stream.progress_bar(1000, "rpc localize", force=True) as advance:
        advance(400, 1234)
        advance(1000, 1000)
    shown = term.getvalue()
    assert "rpc localize" in shown and "2,234 points" in shown


def test_busy_spinner_only_on_terminals(monkeypatch, tmp_path):
    big = tmp_path / "big.csv"
    big.write_bytes(b"x" * 10)
    with _stream.busy("reading", big) as step:  # small file, not a terminal: nothing drawn
        step("estimating")
    term = _Terminal()
    monkeypatch.setattr(sys, "stderr", term)
    with _stream.busy("reading big.csv", big, force=True) as step:
        step("estimating similarity3d from 1,000,000 point pairs")
    assert "estimating similarity3d" in term.getvalue() or "reading big.csv" in term.getvalue()
