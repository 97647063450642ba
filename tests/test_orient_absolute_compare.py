"""``orient absolute --compare`` exited 0 when a method failed: it runs every
method, as a batch command runs its items, so a failed method now ends the command with
``error: K of N methods failed ...`` and exit code 1 (docs/cli.md), after the table, the
JSON and the report."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from photogeom import datasets


@pytest.fixture
def nearly_collinear(tmp_path: Path) -> Path:
    """Four points 0.1 mm off a 300 m line: the closed form refuses them, the others solve."""
    rng = np.random.default_rng(1)
    x = np.array([[0, 0, 0], [1, 0, 0], [2, 1e-3, 0.0], [3, 0, 1e-3]]) * 100
    X = 2 * x + np.array([10.0, 20.0, 30.0]) + rng.normal(size=x.shape) * 1e-6
    lines = ["id,x,y,z,X,Y,Z"]
    for k, (a, b) in enumerate(zip(x.tolist(), X.tolist()), start=1):
        lines.append(",".join([str(k), *map(repr, a), *map(repr, b)]))
    f = tmp_path / "pairs.csv"
    f.write_text("\n".join(lines) + "\n")
    return f


def test_a_failed_method_exits_1_after_the_table(cli, nearly_collinear: Path):
    code, out, err = cli("orient", "absolute", nearly_collinear, "--compare")
    assert code == 1
    assert "closed-form: failed:" in out and "gauss-markov" in out
    assert "error: 1 of 6 methods failed: closed-form" in err


def test_json_and_report_are_written_before(cli, nearly_collinear: Path, tmp_path: Path):
    import json

    report = tmp_path / "cmp.html"
    code, out, err = cli("orient", "absolute", nearly_collinear, "--compare", "--json",
                         "--report", report)
    assert code == 1
    assert json.loads(out)["methods"]
    assert report.is_file()
    assert "1 of 6 methods failed" in err and "see the report" in err


def test_all_methods_solving_still_exits_0(cli):
    code, _, err = cli("orient", "absolute", datasets.path("kraus_absolute_orientation"),
                       "--compare")
    assert code == 0, err


def _parameter_cells(out: str, names) -> dict:
    """First value cell after each parameter name of a printed parameter table."""
    cells = {}
    for line in out.splitlines():
        words = line.split()
        if len(words) >= 2 and words[0] in names and words[0] not in cells:
            cells[words[0]] = words[1]
    return cells


@pytest.mark.parametrize("convention", ["transposed", "direct"])
def test_compare_digits_follow_the_std_and_zero_differences_are_0(cli, convention):
    # before: the scale with 10 decimals (8071.8438023223, 14 significant digits for a std
    # of 0.30) and the reference's differences to itself as 0.00e+00
    path = datasets.path("kraus_absolute_orientation")
    common = ("--angle-unit", "gon", "--convention", convention)
    code, single, err = cli("orient", "absolute", path, "--method", "gauss-markov", *common)
    assert code == 0, err
    code, out, err = cli("orient", "absolute", path, "--compare", *common)
    assert code == 0, err
    want = _parameter_cells(single, ("tx", "ty", "tz", "scale", "omega", "phi", "kappa"))
    assert want["scale"] == "8071.844"
    rows = [line.split() for line in out.splitlines() if line.split()[:1] == ["gauss-markov"]]
    params, diffs = rows
    # the reference's row has the digits of its own parameter table: shifts and scale, and
    # the angles in the table's convention (the direct ones: of the printed direct std)
    assert params[1:5] == [want[n] for n in ("tx", "ty", "tz", "scale")]
    if convention == "transposed":
        assert params[5:8] == [want[n] for n in ("omega", "phi", "kappa")]
    else:
        std = re.search(r"std. dev. of these angles \(a posteriori\): omega (\S+) gon, phi (\S+) "
                        r"gon, kappa (\S+) gon", single).groups()  # fmt: skip
        decimals = [2 - math.floor(math.log10(float(s))) for s in std]
        assert [len(c.split(".")[1]) for c in params[5:8]] == decimals == [5, 5, 5]
    assert diffs[1:4] == ["0", "0", "0"]
    assert "0.00e+00" not in out and "8071.8438" not in out


def test_reference_std_of_direct_angles_matches_sampling():
    """The direct convention's angle std (propagated through numerical derivatives) against
    the spread of the direct angles of rotations sampled from the transposed angles'
    covariance."""
    import photogeom as pg
    from photogeom.rotation import angles_from_rotation, rotation_from_angles

    _, x, X = datasets.point_pairs("lidar_wang2014", None)
    cmp = pg.compare_absolute_methods(x, X, convention="direct", angle_unit="deg", timing=False)
    fit = cmp.row("gauss-markov").fit
    names = list(fit.parameter_names)
    idx = [names.index(a) for a in ("omega", "phi", "kappa")]
    mean = np.array([fit.params[a] for a in ("omega", "phi", "kappa")])
    cov = np.asarray(fit.covariance)[np.ix_(idx, idx)]
    draws = np.random.default_rng(4).multivariate_normal(mean, cov, 20000)
    direct = np.column_stack(
        angles_from_rotation(rotation_from_angles(*draws.T), "direct", unit="deg")
    )
    sampled = direct.std(axis=0)
    std = cmp.reference_std()
    got = np.array([std["omega"], std["phi"], std["kappa"]])
    assert got == pytest.approx(sampled, rel=0.03)
    assert not np.allclose(got, np.degrees(np.sqrt(np.diag(cov))), rtol=0.03)


def test_examples_text_has_the_digits_of_the_compare_table():
    # before: 'examples run absolute-kraus' printed the scale as 8071.8438023223 and the
    # reference's differences to itself as 0.00e+00, beside a --compare table of other digits
    import photogeom as pg

    _, x, X = datasets.point_pairs("kraus_absolute_orientation", None)
    cmp = pg.compare_absolute_methods(x, X, angle_unit="gon", timing=False)
    text = cmp.to_text()
    rows = {ln.split()[0]: ln.split() for ln in text.splitlines()[2:] if "shift:" not in ln}
    for r in cmp.display_rows():
        assert rows[r[0]][1:9] == [*r[4:8], *r[8:12]]
    assert rows["gauss-markov"][1] == "8071.844"
    assert rows["gauss-markov"][5:8] == ["0", "0", "0"]
    assert "gauss-markov shift: (-1424.406, 3715.597, 213.753) m" in text
    assert "0.00e+00" not in text
