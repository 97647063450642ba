"""Small synthetic blocks with known truth for the bundle-adjustment tests (independent of
the simulator package: a grid of nadir images over a hilly surface)."""

from __future__ import annotations

import numpy as np

from photogeom import MetashapeCalibration, opk_matrix
from photogeom.bundle import Block
from photogeom.camera.frame_kernel import project_rows

TRUE_CAL = MetashapeCalibration(
    3000, 2000, 2400.0, cx=14.0, cy=-9.0, k1=-0.08, k2=0.03, k3=-0.005, p1=4e-4, p2=-3e-4
)


def grid_block(
    seed=0,
    rows=3,
    cols=4,
    n_points=250,
    noise=0.0,
    height=100.0,
    n_control=6,
    n_check=3,
    gnss_sigma=None,
    cal=TRUE_CAL,
    oblique=0.0,
):
    """Truth block, observed pixels (with ``noise`` px Gaussian noise)."""
    rng = np.random.default_rng(seed)
    base = 0.35 * height * cal.width / cal.f
    xs, ys = np.meshgrid(np.arange(cols) * base, np.arange(rows) * base * 0.9)
    m = rows * cols
    C = np.column_stack([xs.ravel(), ys.ravel(), np.full(m, height)]) + rng.normal(0, 1, (m, 3))
    ang = rng.normal(0, 0.02, (m, 3))
    ang[:, 2] += rng.uniform(-0.2, 0.2, m)
    if oblique:
        ang[::2, 0] += oblique
        ang[1::2, 1] -= oblique
    M = opk_matrix(ang[:, 0], ang[:, 1], ang[:, 2])
    ext = xs.max() * 1.1 + base * 0.3, ys.max() * 1.1 + base * 0.3
    X = np.column_stack(
        [rng.uniform(-base * 0.3, ext[0], n_points), rng.uniform(-base * 0.3, ext[1], n_points)]
    )
    Z = 8 * np.sin(X[:, 0] / 40) * np.cos(X[:, 1] / 55) + rng.normal(0, 1, n_points)
    P = np.column_stack([X, Z])
    cv = np.array(
        [getattr(cal, n) for n in ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")]
    )
    ii, jj = np.meshgrid(np.arange(m), np.arange(n_points), indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    pr = project_rows(
        P[jj],
        M[ii],
        C[ii],
        np.tile(cv, (ii.size, 1)),
        np.tile([cal.width, cal.height], (ii.size, 1)),
        jacobian=False,
    )
    # the Brown polynomial folds far-off points back into the frame: keep points whose
    # ideal (undistorted) direction lies inside the field of view
    pc = np.einsum("nij,nj->ni", M[ii], P[jj] - C[ii])
    xn, yn = pc[:, 0] / -pc[:, 2], pc[:, 1] / -pc[:, 2]
    inside = (
        (pr.depth > 0)
        & (np.abs(xn) < 0.5 * cal.width / cal.f)
        & (np.abs(yn) < 0.5 * cal.height / cal.f)
        & (pr.uv[:, 0] > 10)
        & (pr.uv[:, 0] < cal.width - 10)
        & (pr.uv[:, 1] > 10)
        & (pr.uv[:, 1] < cal.height - 10)
    )
    ii, jj, uv = ii[inside], jj[inside], pr.uv[inside]
    counts = np.bincount(jj, minlength=n_points)
    keep_pt = counts >= 2
    sel = keep_pt[jj]
    ii, jj, uv = ii[sel], jj[sel], uv[sel]
    pids = np.flatnonzero(keep_pt)
    role = np.full(n_points, "tie", dtype="<U7")
    # control and check points among well-observed points
    good = pids[np.argsort(-counts[pids])]
    spread = good[rng.permutation(min(good.size, 60))]
    role[spread[:n_control]] = "control"
    role[spread[n_control : n_control + n_check]] = "check"
    uv_obs = uv + rng.normal(0, noise, uv.shape) if noise else uv.copy()
    psig = np.where(role[:, None] == "tie", np.nan, 0.01)
    kw = {}
    if gnss_sigma is not None:
        kw = {
            "gnss": C + rng.normal(0, gnss_sigma, C.shape) if noise else C.copy(),
            "gnss_sigma": np.full((m, 3), gnss_sigma),
        }
    truth = Block.from_arrays(
        cameras={"cam": cal},
        image_ids=[f"img{k:03d}" for k in range(m)],
        image_camera=["cam"] * m,
        exterior=np.column_stack([C, ang]),
        point_ids=pids,
        xyz=P[pids],
        role=role[pids],
        point_sigma=np.broadcast_to(psig[pids], (pids.size, 3)),
        obs_image_ids=[f"img{k:03d}" for k in ii],
        obs_point_ids=jj,
        uv=uv_obs,
        sigma=max(noise, 1e-3) if noise else 0.5,
        **kw,
    )
    return truth


def perturbed(truth: Block, seed=1, pos=2.0, ang=0.02, cal_rel=0.05, pt=1.0):
    """A start: metres, radians and a relative change of the calibration."""
    from dataclasses import replace as dreplace

    rng = np.random.default_rng(seed)
    ext = truth.exterior.copy()
    ext[:, :3] += rng.normal(0, pos, (truth.n_images, 3))
    ext[:, 3:] += rng.normal(0, ang, (truth.n_images, 3))
    xyz = truth.xyz.copy()
    tie = truth.role == "tie"
    xyz[tie] += rng.normal(0, pt, (int(tie.sum()), 3))
    c = truth.calibrations[0]
    c0 = dreplace(
        c, f=c.f * (1 + cal_rel), cx=c.cx + 5, cy=c.cy - 5, k1=0.0, k2=0.0, k3=0.0, p1=0.0, p2=0.0
    )
    return truth.replace(exterior=ext, xyz=xyz, calibrations=(c0,))


def far_point_block(n_moved: int = 20, factor: float = 1.6):
    """The simulated ILCE-7RM2 block (seed 1, 3 x 7 images, 200 tie points per image) and
    the same block with ``n_moved`` of its two-ray tie points moved to ``factor`` times
    their distance from their first image's centre (170-220 m along their first ray at
    the defaults, as nearly parallel rays of a GNSS/IMU start triangulate them), and the
    moved points' indices."""
    import photogeom as pg

    sim = pg.simulate.uav_block(
        "ILCE-7RM2", seed=1, strips=3, images_per_strip=7, tie_points_per_image=200
    )
    b = sim.block
    rays = np.bincount(b.obs_point, minlength=b.n_points)
    two = np.flatnonzero((b.role == "tie") & (rays == 2))
    moved = two[:: two.size // n_moved][:n_moved]
    first = np.array([np.flatnonzero(b.obs_point == j)[0] for j in moved])
    C = b.exterior[b.obs_image[first], :3]
    xyz = b.xyz.copy()
    xyz[moved] = C + factor * (xyz[moved] - C)
    return b, b.replace(xyz=xyz), moved
