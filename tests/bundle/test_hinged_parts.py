"""A part of a block linked to the rest by one or two tie points can turn about them (two:
the rotation about their line; one: three rotations and the scale). Its control is in the
other part, so the datum check passes and the redundancy is large, but the normal
equations are singular: the adjustment must refuse it by name, never report standard
deviations of rounding noise."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom.camera.frame_kernel import project_rows
from photogeom.errors import DegenerateGeometryError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

#: the images of the part without control (columns 3-5 of the 2 x 6 grid)
PART_B = {"img003", "img004", "img005", "img009", "img010", "img011"}


def _in_part(b: pg.bundle.Block) -> tuple[np.ndarray, np.ndarray]:
    """Whether each point is observed in part A (columns 0-2), in part B (columns 3-5)."""
    a_img = np.arange(b.n_images) % 6 < 3
    in_a = np.zeros(b.n_points, bool)
    in_b = np.zeros(b.n_points, bool)
    np.logical_or.at(in_a, b.obs_point, a_img[b.obs_image])
    np.logical_or.at(in_b, b.obs_point, ~a_img[b.obs_image])
    return in_a, in_b


def hinged_block(links: int, seed: int = 0) -> tuple[pg.bundle.Block, pg.bundle.Block]:
    """A 2 x 6 grid of nadir images whose halves share ``links`` tie points, six control
    points in the first half only: the truth and a start (0.5 m, 0.3 degrees, 0.3 m off)."""
    t = grid_block(seed=seed, rows=2, cols=6, n_points=400, noise=0.3, n_control=0, n_check=0)
    in_a, in_b = _in_part(t)
    keep = ~(in_a & in_b)
    keep[np.flatnonzero(in_a & in_b)[:links]] = True
    t = t.select_points(keep)
    in_a, in_b = _in_part(t)
    only_a = np.flatnonzero(in_a & ~in_b)
    rays = np.bincount(t.obs_point, minlength=t.n_points)
    role = t.role.copy()
    role[only_a[np.argsort(-rays[only_a], kind="stable")][:6]] = "control"
    ctrl = (role == "control")[:, None]
    t = t.replace(
        role=role,
        point_sigma=np.where(ctrl, 0.01, np.nan) * np.ones((1, 3)),
        surveyed=np.where(ctrl, t.xyz, np.nan),
    )
    rng = np.random.default_rng(seed)
    ext = t.exterior.copy()
    ext[:, :3] += rng.normal(0, 0.5, (t.n_images, 3))
    ext[:, 3:] += rng.normal(0, 0.005, (t.n_images, 3))
    xyz = t.xyz.copy()
    tie = t.role == "tie"
    xyz[tie] += rng.normal(0, 0.3, (int(tie.sum()), 3))
    return t, t.replace(exterior=ext, xyz=xyz)


def dense_jacobian(b: pg.bundle.Block) -> np.ndarray:
    """The dense whitened Jacobian of all image observations (0.3 px) and control
    coordinates (0.01 m) by the exterior orientations (centre and a rotation increment on
    the left of ``M``, by numerical differences) and the points, at the block's values:
    (rows, 6 images + 3 points)."""
    m, p = b.n_images, b.n_points
    cal = b.calibrations[0]
    cv = np.array([getattr(cal, n) for n in pg.bundle.block.CALIBRATION_NAMES])
    i, j = b.obs_image, b.obs_point
    n = i.size
    size = np.tile([cal.width, cal.height], (n, 1))
    R = b.rotations()

    def uv(C, M, X):
        return project_rows(X[j], M[i], C[i], np.tile(cv, (n, 1)), size, jacobian=False).uv

    C, X = b.exterior[:, :3].copy(), b.xyz.copy()
    base = uv(C, R, X)
    J = np.zeros((2 * n, 6 * m + 3 * p))
    h = 1e-6
    for k in range(3):  # the three directions of each kind, not the points
        d = np.zeros(3)
        d[k] = h
        rows = np.arange(n)
        dv = (uv(C + d, R, X) - base) / h
        J[2 * rows, 6 * i + k], J[2 * rows + 1, 6 * i + k] = dv[:, 0], dv[:, 1]
        w = np.zeros(3)
        w[k] = h
        dv = (uv(C, _small_rotation(w) @ R, X) - base) / h
        J[2 * rows, 6 * i + 3 + k], J[2 * rows + 1, 6 * i + 3 + k] = dv[:, 0], dv[:, 1]
        dv = (uv(C, R, X + d) - base) / h
        J[2 * rows, 6 * m + 3 * j + k], J[2 * rows + 1, 6 * m + 3 * j + k] = dv[:, 0], dv[:, 1]
    ctrl = np.flatnonzero(b.role == "control")
    Jc = np.zeros((3 * ctrl.size, J.shape[1]))
    for k in range(3):
        Jc[3 * np.arange(ctrl.size) + k, 6 * m + 3 * ctrl + k] = 100.0  # 1 / 0.01 m
    return np.vstack([J / 0.3, Jc])


def jacobian_defect(b: pg.bundle.Block) -> int:
    """Columns minus the rank of :func:`dense_jacobian`, columns scaled to unit norm: its
    singular values are the square roots of the eigenvalues of its normal matrix."""
    Jt = dense_jacobian(b)
    Jt /= np.linalg.norm(Jt, axis=0)  # column scaling: the rank of the geometry
    s = np.sqrt(np.clip(np.linalg.eigvalsh(Jt.T @ Jt), 0.0, None))
    # differences of 1e-6 leave a null direction about 3e-9 of the largest singular
    # value, the weakest determined ones are 5e-4 of it
    return int(np.sum(s < 1e-6 * s.max()))


def _small_rotation(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the rotation vector ``w`` (rad), Rodrigues."""
    t = float(np.linalg.norm(w))
    k = w / t
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def test_the_hinge_of_two_points_is_a_rank_defect_three_points_none():
    # independent of the adjustment: the SVD rank of the dense Jacobian at the truth. One
    # link leaves the hinged half its three rotations and its scale; of the two links the
    # second is seen by one image of the controlled half, which fixes its ray, not its
    # position: two rotations stay free
    assert jacobian_defect(hinged_block(1)[0]) == 4
    assert jacobian_defect(hinged_block(2)[0]) == 2
    assert jacobian_defect(hinged_block(3)[0]) == 0


def test_two_linking_points_are_refused_naming_the_hinged_part():
    # the dense Cholesky of the reduced camera system passes here (rounding left the
    # rotations about the hinge a pivot of about 1e-15); before, the fit was reported with
    # sigma0 1.00 and standard deviations of 3.4e4 m and 290 rad in the hinged half
    _, start = hinged_block(2)
    with pytest.raises(DegenerateGeometryError, match="do not determine all free parameters") as e:
        pg.bundle_adjust(start, free=(), backend="dense")
    text = str(e.value)
    named = {w.split(" ")[0] for w in text.split("image(s) ")[1].split(". ")[0].split("; ")}
    named = {w for w in named if w.startswith("img")}
    assert named and named <= PART_B  # only images of the hinged half
    assert "fewer than three tie points" in text


def test_three_linking_points_determine_the_block():
    truth, start = hinged_block(3)
    fit = pg.bundle_adjust(start, free=(), backend="dense")
    assert fit.converged and 0.9 < fit.sigma0 < 1.1
    assert np.max(fit.exterior_std[:, :3]) < 1.0  # metres: a weak but determined hinge
    err = np.abs(fit.block.exterior[:, :3] - truth.exterior[:, :3])
    assert np.all(err < 5 * fit.exterior_std[:, :3] + 1e-3)


def test_inflation_factors_are_those_of_the_dense_normal_matrix():
    # the factors from the reduced camera system's covariance blocks against the diagonal
    # of the inverse of the dense normal matrix, at the truth of the determined block
    from photogeom.adjust.schur import covariance_blocks
    from photogeom.bundle.adjustment import Problem
    from photogeom.bundle.determined import inflation_factors

    truth, _ = hinged_block(3)
    problem = Problem(truth, pg.bundle.BundleOptions(free=()))
    state = problem.initial_state()
    lin = problem.linearize(state, np.ones(problem.obs_i.size))
    ne = problem.sys.normal_equations(lin)
    local, cal = inflation_factors(problem, lin, covariance_blocks(ne, ne.factor(), pairs=False))
    J = dense_jacobian(truth)
    N = J.T @ J
    vif = (np.diag(np.linalg.inv(N)) * np.diag(N))[: 6 * truth.n_images].reshape(-1, 6)
    assert local.max() > 1e4  # the hinge of three points is weak
    np.testing.assert_allclose(local, vif, rtol=1e-3)
    assert not np.any(cal)  # no free calibration


@pytest.mark.parametrize("backend", ["dense", "superlu"])
def test_one_linking_point_is_refused_naming_the_hinged_part_not_the_calibration(backend):
    # the factorisation fails here; before, its error advised to fix calibration parameters
    # (none are free) and named no image
    _, start = hinged_block(1)
    with pytest.raises(DegenerateGeometryError, match="do not determine all free parameters") as e:
        pg.bundle_adjust(start, free=(), backend=backend)
    text = str(e.value)
    named = {w.split(" ")[0] for w in text.split("image(s) ")[1].split(". ")[0].split("; ")}
    named = {w for w in named if w.startswith("img")}
    assert named and named <= PART_B
    assert "fewer than three tie points" in text and "calibration" not in text


def test_adjust_with_grids_refuses_the_hinge_of_two_points():
    # the joint system with residual grids factorised too, and the block came back with
    # its hinged half at whatever rotation the iteration left, without a word
    from photogeom.calibration.in_adjustment import adjust_with_grids

    _, start = hinged_block(2)
    with pytest.raises(DegenerateGeometryError, match="do not determine all free parameters") as e:
        adjust_with_grids(start, 1000.0, per="camera")
    text = str(e.value)
    named = {w.split(" ")[0] for w in text.split("image(s) ")[1].split(". ")[0].split("; ")}
    assert {w for w in named if w.startswith("img")} <= PART_B


@pytest.mark.parametrize("links", [1, 2])
def test_the_hinge_is_refused_before_the_first_iteration(links):
    # before, the whole Levenberg-Marquardt iteration ran (damped, it converged) and the
    # statistics refused the result; the tie points the halves share (found here from the
    # images of each half, not from the adjustment) are named
    from photogeom.bundle.adjustment import Problem

    _, start = hinged_block(links)
    with pytest.raises(DegenerateGeometryError, match="fewer than three tie points") as e:
        Problem(start, pg.bundle.BundleOptions(free=()))
    calls = []
    with pytest.raises(DegenerateGeometryError, match="fewer than three tie points"):
        pg.bundle_adjust(start, free=(), progress=lambda *a: calls.append(a))
    assert calls == []  # no iteration
    text = str(e.value)
    assert "do not determine all free parameters" in text
    named = {w.split(" ")[0] for w in text.split("image(s) ")[1].split(". ")[0].split("; ")}
    assert named <= PART_B and len(named) == 5 and "and 1 more" in text  # five named
    in_a, in_b = _in_part(start)
    shared = start.point_ids[in_a & in_b]
    assert shared.size == links
    listed = text.split("point(s) ")[1].split(")")[0].split(", ")
    assert sorted(listed) == sorted(map(str, shared.tolist()))


def test_three_linking_points_pass_the_check_before_the_iterations():
    # the truth of the determined block (SVD rank full) is not refused, nor its free network
    from photogeom.bundle.adjustment import Problem

    truth, _ = hinged_block(3)
    _, linking = Problem(truth, pg.bundle.BundleOptions(free=()))._held_parts()
    assert linking.size == 1  # one part: the halves share three points
    Problem(truth.without_datum_observations(), pg.bundle.BundleOptions(free=(), datum="free"))
