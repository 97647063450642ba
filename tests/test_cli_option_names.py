"""Errors of the library raised under a command name the command's options, not the
library's keywords (`sigma_target must be ...` where the user typed --sigma-target), and
`orient absolute` refuses --sigma-source and --initial where --method does not use them."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets
from photogeom.cli._common import keywords_as_options

LIDAR = str(datasets.path("lidar_wang2014"))
FID = str(datasets.path("lecture_fiducials"))
IKONOS = str(datasets.path("lecture_fiducials").parent / "rpc" / "rpc_IKONOS.txt")
CAMERA = ["--f", "152.14", "--x0", "0.008", "--y0", "-0.12"]
PYTHON_NAME = re.compile(r"\b[a-z]+_[a-z0-9_]+\b|\b\w+=")


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    import photogeom as pg

    d = tmp_path_factory.mktemp("f")
    io = pg.InteriorOrientation(152.14, 0.008, -0.12)
    eos = [pg.ExteriorOrientation.from_degrees(1000, 800, 1600, 2, 3, 10),
           pg.ExteriorOrientation.from_degrees(1600, 820, 1620, -1, 2, 8)]
    rng = np.random.default_rng(0)
    g = np.column_stack([rng.uniform(1050, 1550, 12), rng.uniform(750, 1100, 12),
                         rng.uniform(100, 300, 12)])
    (d / "ground.csv").write_text("id,X,Y,Z\n" + "".join(
        f"P{i},{float(g[i, 0])!r},{float(g[i, 1])!r},{float(g[i, 2])!r}\n" for i in range(12)))
    xy = [pg.project(g, io, eo) + rng.normal(0, 0.003, (12, 2)) for eo in eos]
    for k in range(2):
        (d / f"img{k}.csv").write_text("id,x,y\n" + "".join(
            f"P{i},{float(xy[k][i, 0])!r},{float(xy[k][i, 1])!r}\n" for i in range(12)))
    (d / "matches.csv").write_text("id,x1,y1,x2,y2\n" + "".join(
        f"P{i}," + ",".join(repr(float(c)) for c in (*xy[0][i], *xy[1][i])) + "\n"
        for i in range(12)))
    (d / "px.csv").write_text("id,col,row\n1,100,200\n")
    return {p.stem: p for p in d.iterdir()}


CASES = [
    # (arguments, text the message must contain)
    (("orient", "absolute", LIDAR, "-m", "gauss-markov", "--sigma-target", "-1"),
     "--sigma-target must be"),
    (("orient", "absolute", LIDAR, "-m", "gauss-helmert", "--sigma-source", "-0.01"),
     "--sigma-source must be"),
    (("orient", "absolute", LIDAR, "-m", "svd", "--sigma-source", "0.01"),
     "add --method gauss-helmert"),
    (("orient", "absolute", LIDAR, "-m", "gauss-markov", "--initial", "foo"),
     "--initial foo: give a direct method"),
    (("orient", "absolute", LIDAR, "-m", "svd", "--initial", "svd"),
     "--method svd is direct"),
    (("transform", "estimate", "similarity2d", FID, "--sigma0-prior", "-1"),
     "--sigma0-prior must be"),
    (("transform", "estimate", "polynomial2d", FID, "--order", "0"), "--order must be"),
    (("transform", "estimate", "similarity2d", FID, "--order", "2"), "--order applies"),
    (("transform", "estimate", "similarity2d", FID, "--errors-in", "both"),
     "--errors-in both is offered"),
    (("orient", "resection", "{ground}", "{img0}", *CAMERA, "--sigma", "-1"), "--sigma:"),
    (("orient", "resection", "{ground}", "{img0}", *CAMERA, "--calibrate", "foo"),
     "--calibrate:"),
    (("orient", "resection", "{ground}", "{img0}", "--f", "152", "--pixel",
      "--pixel-size", "-1"), "--pixel-size must be"),
    (("orient", "relative", "{matches}", *CAMERA, "--sigma", "-1"), "--sigma:"),
    (("orient", "relative", "{matches}", *CAMERA, "--threshold", "-1"), "--threshold must be"),
    (("camera", "project", "{ground}", "--f", "152", "--pixel", "--pixel-size", "-1",
      "--eo", "1000,800,1600,2,3,10"), "--pixel-size must be"),
    (("rpc", "localize", IKONOS, "{px}", "--height", "30", "--tol", "-1"), "--tol must be"),
    (("rpc", "localize", IKONOS, "{px}", "--height", "30", "--max-iter", "0"),
     "--max-iter must be"),
    (("bundle", "simulate", "{tmp}/b", "--sigma", "-1"), "--sigma must be"),
    (("bundle", "simulate", "{tmp}/b", "--strips", "0"), "--strips >= 1"),
    (("bundle", "simulate", "{tmp}/b", "--images-per-strip", "1"), "--images-per-strip >= 2"),
    (("bundle", "simulate", "{tmp}/b", "--gcp-sigma", "nan"), "--gcp-sigma must be"),
    (("bundle", "simulate", "{tmp}/b", "--checks", "foo"), "--checks: unknown layout"),
    (("bundle", "simulate", "{tmp}/b", "--size", "huge"), "--size must be"),
    (("bundle", "simulate", "{tmp}/b", "--local-field", "-1"), "--local-field must be"),
    (("bundle", "simulate", "{tmp}/b", "--blunder-size", "-1"), "--blunder-size must be"),
]


@pytest.mark.parametrize(("args", "expected"), CASES, ids=[" ".join(c[0][:2]) + " " + c[1]
                                                             for c in CASES])
def test_errors_name_the_options(cli, files, tmp_path: Path, args, expected):
    args = [a.format(tmp=tmp_path, **{k: str(v) for k, v in files.items()}) for a in args]
    code, _, err = cli(*args)
    assert code == 2
    assert err.startswith("error: ") and expected in err, err
    assert not PYTHON_NAME.search(err.replace("gauss-", "")), err


@pytest.mark.parametrize(("message", "expected"), [
    ("the image size must be known", "the image size must be known"),  # prose stays
    ("polynomial2d of order 9: 4 point(s)", "polynomial2d of order 9: 4 point(s)"),
    ("x: order must be >= 1", "x: --order must be >= 1"),
    ("errors_in='both' needs method=\"gauss-helmert\"",
     "--errors-in both needs --method gauss-helmert"),
    ("give sigma0_prior or weights", "give --sigma0-prior or weights"),
])
def test_keywords_as_options(message, expected):
    names = {"order": "--order", "size": "--size", "errors_in": "--errors-in",
             "method": "--method", "sigma0_prior": "--sigma0-prior"}
    assert keywords_as_options(message, names) == expected
