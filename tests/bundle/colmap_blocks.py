"""Blocks and pycolmap reconstructions of the COLMAP model tests (text and binary)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from photogeom.bundle import Block, projected_pixels
from photogeom.bundle.io_colmap import COLMAP_MODELS
from photogeom.camera.metashape import MetashapeCalibration

W, H = 4000, 3000
CALS = {
    "SIMPLE_PINHOLE": MetashapeCalibration(W, H, 3100.0, cx=12.3, cy=-8.1),
    "PINHOLE": MetashapeCalibration(W, H, 3100.0, cx=12.3, cy=-8.1, b1=5.5),
    "SIMPLE_RADIAL": MetashapeCalibration(W, H, 3100.0, cx=12.3, cy=-8.1, k1=-0.05),
    "RADIAL": MetashapeCalibration(W, H, 3100.0, cx=-4.0, cy=7.25, k1=-0.05, k2=0.02),
    "OPENCV": MetashapeCalibration(
        W, H, 3100.0, cx=12.3, cy=-8.1, b1=-3.2, k1=-0.05, k2=0.02, p1=3e-4, p2=-2e-4
    ),
    "FULL_OPENCV": MetashapeCalibration(
        W, H, 3100.0, cx=12.3, cy=-8.1, b1=-3.2, k1=-0.05, k2=0.02, k3=-0.01, p1=3e-4, p2=-2e-4
    ),
}


def random_block(
    rng, cameras, *, m=5, p=20, image_ids=None, point_ids=None, free=None
) -> Block:
    """Images looking down on points, every camera group used, observations with noise."""
    gids = list(cameras)
    pts = rng.uniform([-40, -30, -5], [40, 30, 5], size=(p, 3))
    ext = [
        [
            *rng.uniform(-10, 10, 2),
            120 + rng.uniform(-5, 5),
            *rng.uniform(-0.2, 0.2, 2),
            rng.uniform(-3, 3),
        ]
        for _ in range(m)
    ]
    img = list(range(m)) if image_ids is None else image_ids
    pid = list(range(p)) if point_ids is None else point_ids
    ii, jj = np.meshgrid(np.arange(m), np.arange(p), indexing="ij")
    keep = rng.random(ii.size) < 0.8
    keep[:p] = True  # every point in the first image
    b0 = Block.from_arrays(
        cameras=cameras,
        image_ids=img,
        image_camera=[gids[i % len(gids)] for i in range(m)],
        exterior=ext,
        point_ids=pid,
        xyz=pts,
        obs_image_ids=np.array(img)[ii.ravel()[keep]],
        obs_point_ids=np.array(pid)[jj.ravel()[keep]],
        uv=np.zeros((int(keep.sum()), 2)),
        sigma=1.0,
        free=free,
    )
    uv, _ = projected_pixels(b0)
    return b0.with_observations(uv=uv + rng.normal(0, 0.3, uv.shape))


def pycolmap_reconstruction(pycolmap, rng, *, unlinked: bool = False):
    """A reconstruction built in pycolmap: one camera of each model (trivial rigs), one
    image per camera (trivial frames), 12 points seen in every image with noisy 2D points;
    ``unlinked``: one more 2D point per image (the fourth) without a 3D point."""
    rec = pycolmap.Reconstruction()
    models = list(COLMAP_MODELS)
    values = {"k": -0.04, "k1": -0.04, "k2": 0.01, "k3": 0.01, "p1": 2e-4, "p2": 2e-4,
              "fy": 3004.0, "cx": W / 2 + 11.0}  # fmt: skip
    for cid, model in enumerate(models, start=1):
        cam = pycolmap.Camera.create_from_model_name(cid, model, 3000.0, W, H)
        params = np.array(cam.params)
        for k, nm in enumerate(COLMAP_MODELS[model]):
            params[k] = values.get(nm, params[k])
        cam.params = params
        rec.add_camera_with_trivial_rig(cam)
    pts = rng.uniform([-30, -20, 100], [30, 20, 140], size=(12, 3))  # in front of z forward
    for iid in range(1, len(models) + 1):
        R = Rotation.from_rotvec(rng.uniform(-0.1, 0.1, 3))
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(R.as_quat()), rng.uniform(-2, 2, 3))
        xy = rec.cameras[iid].img_from_cam(np.array([pose * x for x in pts]))
        im = pycolmap.Image(name=f"view_{iid}.png", camera_id=iid, image_id=iid)
        p2d = [pycolmap.Point2D(q + rng.normal(0, 0.2, 2)) for q in xy]
        if unlinked:
            p2d.insert(3, pycolmap.Point2D(np.array([5.25, 7.5])))
        im.points2D = pycolmap.Point2DList(p2d)
        rec.add_image_with_trivial_frame(im, pose)
    for j, X in enumerate(pts):
        track = pycolmap.Track()
        idx = j + (unlinked and j >= 3)
        for iid in range(1, len(models) + 1):
            track.add_element(iid, idx)
        pid = rec.add_point3D(X, track)
        for iid in range(1, len(models) + 1):
            rec.image(iid).set_point3D_for_point2D(idx, pid)
    return rec


def text_model(directory, cameras, images=None, points=None):
    """A COLMAP text model in ``directory`` (by default two images, one point seen in both)."""
    directory.mkdir(exist_ok=True)
    (directory / "cameras.txt").write_text(cameras)
    (directory / "images.txt").write_text(
        images
        if images is not None
        else "1 1 0 0 0 0 0 5 1 a.jpg\n10 20 7 30 40 -1\n2 1 0 0 0 1 0 5 1 b.jpg\n11 21 7\n"
    )
    (directory / "points3D.txt").write_text(
        points if points is not None else "7 0 0 20 0 0 0 -1 1 0 2 0\n"
    )
    return directory
