"""Height steps between consecutive stereo models of a block (05-residual-grid.md, Evaluate).

Strips and models are chosen from the block's geometry:

* **overlap of two images**: ``1 - |b| / L`` with ``b`` the horizontal baseline between
  their projection centres and ``L`` the length of the first image's ground footprint along
  the baseline, ``L = GSD_i (width |e . x_i| + height |e . y_i|)`` (``e`` the baseline
  direction, ``x_i``, ``y_i`` the image axes in object space, ``GSD_i`` the mean depth over
  the focal length of the image's observations);
* **strips**: images in block order; an image continues the strip of the previous one when
  their overlap is at least ``min_overlap`` and the baseline turns by less than 30 degrees
  from the strip's previous baseline;
* **models**: in every strip the image offset ``k`` whose mean overlap ``overlap(i, i+k)``
  is closest to the target ``overlap`` (60 % by default, the study's) makes the models
  ``(i, i+k)``; two consecutive models ``(i, i+k)`` and ``(i+k, i+2k)`` share image ``i+k``;
* **step**: the points observed in all three images are intersected by each model's pair
  alone (:func:`photogeom.bundle.triangulate` with ``images=[a, b]``) and the step is the
  RMSE of the height differences divided by the block's GSD. The key of a step is the
  first model's image pair ``(i, i+k)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bundle.block import Block
from ..bundle.triangulate import triangulate
from ..errors import InputError

__all__ = ["StereoModels", "image_overlap", "model_steps", "stereo_models"]


def _image_gsd(block: Block) -> np.ndarray:
    """Mean depth / f of each image's observations (m,); NaN for images without any."""
    M = block.rotations()
    d = block.xyz[block.obs_point] - block.exterior[block.obs_image, :3]
    depth = np.abs(np.einsum("nj,nj->n", M[block.obs_image, 2, :], d))
    f = block.calibration_matrix()[block.obs_image, 0]
    s = np.bincount(block.obs_image, weights=depth / f, minlength=block.n_images)
    c = np.bincount(block.obs_image, minlength=block.n_images)
    with np.errstate(invalid="ignore", divide="ignore"):
        return s / c


def image_overlap(block: Block, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Forward overlap of image rows ``a`` with rows ``b`` (see the module).

    Parameters
    ----------
    block : Block
        The block (its exterior orientations, camera sizes and GSD).
    a, b : numpy.ndarray of int, shape (k,)
        Image rows of the pairs.

    Returns
    -------
    numpy.ndarray, shape (k,)
        Fractions (1 for coincident projection centres; negative without overlap).
    """
    return _overlap(block, np.asarray(a, int), np.asarray(b, int), _image_gsd(block))


def _overlap(block: Block, a: np.ndarray, b: np.ndarray, gsd: np.ndarray) -> np.ndarray:
    """:func:`image_overlap` with the images' GSD given (``_image_gsd(block)``, (m,)): it
    runs over every observation of the block, so a caller that asks for many pairs of
    images computes it once."""
    C = block.exterior[:, :3]
    base = C[b, :2] - C[a, :2]
    blen = np.linalg.norm(base, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        e = base / blen[:, None]
    M = block.rotations()
    # image x axis (columns) and y axis in object space: rows of M; v runs along -y
    xa, ya = M[a, 0, :2], M[a, 1, :2]
    size = block.image_sizes()[a]
    L = gsd[a] * (size[:, 0] * np.abs(np.sum(e * xa, 1)) + size[:, 1] * np.abs(np.sum(e * ya, 1)))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(blen > 0, 1.0 - blen / L, 1.0)


@dataclass(frozen=True)
class StereoModels:
    """Strips and stereo models of a block (see the module).

    Attributes
    ----------
    strips : list of lists of image ids, in block order.
    offsets : list of int, the model offset ``k`` of each strip (0: too short).
    models : list of (a, b) image id pairs.
    model_overlap : list of float, the overlap of each model.
    triples : list of (a, b, c): consecutive models (a, b) and (b, c).
    """

    strips: list
    offsets: list
    models: list
    model_overlap: list
    triples: list


def stereo_models(block: Block, *, overlap: float = 0.6, min_overlap: float = 0.2) -> StereoModels:
    """Strips, stereo models at about ``overlap`` forward overlap, and consecutive pairs.

    Parameters
    ----------
    block : Block
        The block, images in flight order.
    overlap : float, default 0.6
        Target forward overlap of the models, in (0, 1).
    min_overlap : float, default 0.2
        Consecutive images overlapping less (or turning by more than 30 deg) start a new
        strip; in [0, 1).

    Returns
    -------
    StereoModels

    Raises
    ------
    InputError
        For ``block`` not a Block or a fraction out of range.
    """
    if not isinstance(block, Block):
        raise InputError(f"model_steps needs a photogeom.bundle.Block, got {type(block).__name__}")
    if not (0 < overlap < 1):
        raise InputError(f"overlap must be a fraction in (0, 1), not {overlap!r}")
    if not (0 <= min_overlap < 1):
        raise InputError(f"min_overlap must be a fraction in [0, 1), not {min_overlap!r}")
    m = block.n_images
    ids = block.image_ids.tolist()
    if m < 3:
        return StereoModels([ids], [0], [], [], [])
    rows = np.arange(m)
    gsd = _image_gsd(block)  # once: every candidate offset of every strip needs it
    ov = _overlap(block, rows[:-1], rows[1:], gsd)
    C = block.exterior[:, :2]
    base = np.diff(C, axis=0)
    strips = [[0]]
    prev = None
    for i in range(m - 1):  # images, not points
        same = bool(ov[i] >= min_overlap)
        if same and prev is not None:
            cosang = np.dot(base[i], prev) / (np.linalg.norm(base[i]) * np.linalg.norm(prev))
            same = bool(cosang >= np.cos(np.radians(30.0)))
        if same:
            strips[-1].append(i + 1)
            prev = base[i]
        else:
            strips.append([i + 1])
            prev = None
    models, mov, triples, offsets = [], [], [], []
    for s in strips:
        s = np.asarray(s)
        best, best_d = 0, np.inf
        for k in range(1, max(1, s.size // 2) + 1):  # candidate offsets of the strip
            if s.size < 2 * k + 1:
                break
            o = float(np.nanmean(_overlap(block, s[:-k], s[k:], gsd)))
            if abs(o - overlap) < best_d:
                best, best_d = k, abs(o - overlap)
        offsets.append(best)
        if best == 0:
            continue
        k = best
        o = _overlap(block, s[:-k], s[k:], gsd)
        for a, b, oo in zip(s[:-k], s[k:], o):
            models.append((ids[a], ids[b]))
            mov.append(float(oo))
        for a, b, c in zip(s[: -2 * k], s[k:-k], s[2 * k :]):
            triples.append((ids[a], ids[b], ids[c]))
    return StereoModels([[ids[i] for i in s] for s in strips], offsets, models, mov, triples)


def model_steps(
    block: Block,
    *,
    overlap: float = 0.6,
    min_overlap: float = 0.2,
    min_points: int = 3,
    gsd: float | None = None,
    details: bool = False,
):
    """Height step between consecutive stereo models, in GSD (see the module).

    Parameters
    ----------
    block : Block
        An adjusted block (its cameras are used as they are).
    overlap : float
        Target forward overlap of a stereo model (the study: 0.6).
    min_overlap : float
        Consecutive images overlapping less start a new strip.
    min_points : int
        Model pairs with fewer common points (seen in all three images and intersected by
        both models) are left out.
    gsd : float, optional
        Ground sample distance (object units per pixel); default ``block.gsd()``.
    details : bool
        Also return, per key, the number of points and the mean height difference.

    Returns
    -------
    dict
        ``{(image a, image b): step}``, the key the first model's image pair, the step the
        RMSE of the height differences of the two models' intersections divided by the
        GSD; with ``details``, a second dict ``key -> {"n", "mean", "rmse", "models"}``
        (mean and RMSE in object units).
    """
    sm = stereo_models(block, overlap=overlap, min_overlap=min_overlap)
    g = float(block.gsd() if gsd is None else gsd)
    if not (g > 0):
        raise InputError(f"gsd must be positive, not {gsd!r}")
    row = {iid: i for i, iid in enumerate(block.image_ids.tolist())}
    # point rows observed per image: a boolean (m, p) would be large; use sorted keys
    key = block.obs_image.astype(np.int64) * block.n_points + block.obs_point
    key = np.unique(key)
    steps, info = {}, {}
    for a, b, c in sm.triples:  # models, not points
        pts = None
        for iid in (a, b, c):
            i = row[iid]
            lo, hi = np.searchsorted(key, [i * block.n_points, (i + 1) * block.n_points])
            p = key[lo:hi] - i * block.n_points
            pts = p if pts is None else np.intersect1d(pts, p, assume_unique=True)
        if pts.size < min_points:
            continue
        pid = block.point_ids[pts]
        t1 = triangulate(block, pid, images=[a, b])
        t2 = triangulate(block, pid, images=[b, c])
        ok = t1.ok & t2.ok
        if int(ok.sum()) < min_points:
            continue
        dz = t1.xyz[ok, 2] - t2.xyz[ok, 2]
        rmse = float(np.sqrt(np.mean(dz * dz)))
        steps[(a, b)] = rmse / g
        info[(a, b)] = {
            "n": int(ok.sum()),
            "mean": float(np.mean(dz)),
            "rmse": rmse,
            "models": ((a, b), (b, c)),
        }
    if details:
        return steps, info
    return steps
