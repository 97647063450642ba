"""Initial exterior orientations of a block without GNSS/IMU: models, strips, absolute orientation.

The classical chain, for each strip of images in flight order:

1. relative orientation of every consecutive pair (:func:`relative_orientation`, wrong
   matches removed by RANSAC and data snooping) and its model points by intersection; a
   pair that fails from the essential matrix's start (e.g. lens distortion the start
   calibration lacks, which looks like forward motion) is adjusted from the relative
   orientation of its neighbouring pair in the strip;
2. strip formation: model ``k`` is attached to the strip through the image it shares with
   model ``k - 1`` (that image's attitude and projection centre are made to coincide) and
   its scale is transferred from the points common to both models (the median of the
   ratios of their distances from the shared projection centre, robust to a few wrong
   matches);
3. absolute orientation of the strip (:func:`absolute_orientation`, a 3D similarity) to
   the ground control points it contains; a strip with fewer than three GCPs is oriented to
   the tie points it shares with strips already oriented; when no strip can be oriented
   that way, the strip with the most GCPs is first joined in model space to the strip it
   shares the most tie points with (a similarity on those points), and so on.

The result, every image's exterior orientation and every tie point's ground coordinates, is
the start of a bundle adjustment; strip deformation (bending, scale drift) is left for that
adjustment to remove.

With GNSS/IMU (the UAV case) the exterior orientations are known approximately and the tie
points follow by intersection: :func:`points_from_exteriors`.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..camera.exterior import ExteriorOrientation
from ..camera.interior import InteriorOrientation
from ..errors import (
    ConvergenceError,
    DegenerateGeometryError,
    InputError,
    PhotogeomError,
    TooFewPointsError,
)
from .relative import RelativeOrientationFit, relative_orientation

__all__ = ["BlockStart", "StripModel", "block_start", "orient_strip", "points_from_exteriors"]


@dataclass(frozen=True)
class StripModel:
    """A strip formed from its models, in the system of its first model.

    Attributes
    ----------
    images : tuple, image ids in flight order.
    exteriors : dict, image id -> ExteriorOrientation in the strip system.
    points : dict, point id -> (3,) strip coordinates (mean over the models that have it).
    relative : tuple of RelativeOrientationFit, one per consecutive pair.
    scales : tuple of float, scale transferred to each model (1 for the first).
    scale_spread : tuple of float, relative MAD of the distance ratios of each transfer.
    bridged : tuple of (int, int)
        ``(k, j)`` for every pair ``k`` (0-based: images ``k``, ``k + 1``) whose relative
        orientation failed from its own start (the essential matrix) and was adjusted from
        the relative orientation of the neighbouring pair ``j`` instead; empty when every
        pair oriented from its own start.
    """

    images: tuple
    exteriors: dict
    points: dict
    relative: tuple
    scales: tuple
    scale_spread: tuple
    bridged: tuple = ()


@dataclass(frozen=True)
class BlockStart:
    """Initial values of a block.

    Attributes
    ----------
    exteriors : dict, image id -> ExteriorOrientation in the ground system.
    points : dict, point id -> (3,) ground coordinates of every tie point (and GCP) seen in a
        model.
    strips : tuple of StripModel
    absolute : tuple of AbsoluteOrientationFit, one per strip (strip -> ground).
    control_used : tuple of tuple, per strip the ids used as control (GCPs, or tie points of
        strips oriented before).
    """

    exteriors: dict
    points: dict
    strips: tuple
    absolute: tuple
    control_used: tuple


def _pair_matches(obs1: Mapping, obs2: Mapping):
    ids = [p for p in obs1 if p in obs2]
    xy1 = np.array([obs1[p] for p in ids], dtype=float).reshape(-1, 2)
    xy2 = np.array([obs2[p] for p in ids], dtype=float).reshape(-1, 2)
    return ids, xy1, xy2


def orient_strip(
    images: Sequence[Hashable],
    interiors: Mapping[Hashable, InteriorOrientation],
    observations: Mapping[Hashable, Mapping[Hashable, Sequence[float]]],
    *,
    method: str = "independent",
    sigma=None,
    min_common: int = 3,
    seed: int | None = 0,
) -> StripModel:
    """Form one strip from the relative orientations of its consecutive image pairs.

    Parameters
    ----------
    images : sequence of image ids, in flight order (>= 2).
    interiors : mapping image id -> InteriorOrientation.
    observations : mapping image id -> {point id: (x, y)}
        Image coordinates (photogrammetric image system, unit of the interior orientation).
    method : {"independent", "dependent"}
        Parameterisation of each relative orientation (the strip does not depend on it; the
        default, independent, takes a base in any direction of the image plane).
    sigma : float, optional
        A-priori standard deviation of the image coordinates, in the unit of the interior
        orientations.
    min_common : int
        Points that two consecutive models must share for the scale transfer.
    seed : int or None
        RANSAC seed of the relative orientations.

    Returns
    -------
    StripModel
        Exterior orientations and points in the system of the first model, the relative
        orientations, the scale transfers and the pairs oriented from their neighbour's
        relative orientation (``bridged``).

    Raises
    ------
    TooFewPointsError
        Two consecutive images share fewer than 5 points, or three fewer than
        ``min_common``.
    DegenerateGeometryError, ConvergenceError
        A pair that cannot be oriented from the essential matrix nor from its neighbouring
        pair's relative orientation (the message names the pair, the strip and both
        failures), or whose points do not determine it.
    """
    imgs = tuple(images)
    if len(imgs) < 2:
        raise InputError("a strip needs at least two images")
    for i in imgs:
        if i not in interiors:
            raise InputError(f"image {i!r}: no interior orientation given")
        if i not in observations:
            raise InputError(f"image {i!r}: no image observations given")
    exteriors: dict = {}
    sums: dict = {}
    counts: dict = {}
    fits: list[RelativeOrientationFit] = []
    scales: list[float] = [1.0]
    spreads: list[float] = [0.0]
    bridged: list[tuple[int, int]] = []
    ahead: dict[int, RelativeOrientationFit] = {}  # pairs oriented before their turn
    prev_points: dict | None = None

    def pair(k: int, initial=None) -> RelativeOrientationFit:
        a, b = imgs[k], imgs[k + 1]
        ids, xy1, xy2 = _pair_matches(observations[a], observations[b])
        if len(ids) < 5:
            raise TooFewPointsError(f"relative orientation of images {a!r}, {b!r}", len(ids), 5)
        return relative_orientation(
            xy1,
            xy2,
            interiors[a],
            interiors[b],
            method=method,
            sigma=sigma,
            ids=ids,
            seed=seed,
            initial=initial,
        )

    def named(exc: PhotogeomError, k: int, extra: str = "") -> None:
        """Put the pair and the strip in the message of ``exc`` (keeping its type)."""
        if exc.args:
            a, b = imgs[k], imgs[k + 1]
            hint = (
                "; leave one of the two out of the strip, or delete it from the block"
                if "no base" in str(exc.args[0])
                else ""
            )
            exc.args = (
                f"images {a!r}, {b!r} (pair {k + 1} of the strip {imgs[0]!r} .. "
                f"{imgs[-1]!r}): {exc.args[0]}{hint}{extra}",
                *exc.args[1:],
            )

    for k in range(len(imgs) - 1):
        a, b = imgs[k], imgs[k + 1]
        n_common = sum(p in observations[b] for p in observations[a])
        if n_common < 5:
            raise TooFewPointsError(f"relative orientation of images {a!r}, {b!r}", n_common, 5)
        try:
            fit = ahead.pop(k) if k in ahead else pair(k)
        except (DegenerateGeometryError, ConvergenceError) as exc:
            # the essential matrix's start can fail where the pair itself is sound (a start
            # calibration without the lens distortion makes forward motion fit most matches):
            # a neighbouring pair of the strip, flown alike, gives the start instead
            j = k - 1 if k > 0 else k + 1
            neighbour = None
            if k > 0:
                neighbour = fits[k - 1]
            elif len(imgs) > 2:
                try:
                    neighbour = ahead[1] = pair(1)
                except PhotogeomError:
                    neighbour = None
            if neighbour is None:
                named(exc, k)
                raise
            try:
                fit = pair(k, initial=(neighbour.exterior1, neighbour.exterior2))
            except PhotogeomError as again:
                named(
                    exc,
                    k,
                    f" (started from the relative orientation of images {imgs[j]!r}, "
                    f"{imgs[j + 1]!r} instead, it failed too: {again})",
                )
                raise exc from again
            fit = replace(
                fit,
                notes=(
                    *fit.notes,
                    f"started from the relative orientation of images {imgs[j]!r}, "
                    f"{imgs[j + 1]!r}: its own start failed ({exc})",
                ),
            )
            bridged.append((k, j))
        except PhotogeomError as exc:  # which pair of which strip, in the error's own type
            named(exc, k)
            raise
        fits.append(fit)
        mp = fit.model_points()
        pts = mp.as_dict()
        ea, eb = fit.exterior1, fit.exterior2
        if k == 0:
            s, R, t = 1.0, np.eye(3), np.zeros(3)
        else:
            # the shared image a: its strip orientation and its model orientation coincide
            strip_a = exteriors[a]
            R = strip_a.matrix.T @ ea.matrix  # model -> strip rotation
            common = [p for p in pts if p in prev_points]
            if len(common) < min_common:
                raise TooFewPointsError(
                    f"scale transfer between models {imgs[k - 1]!r}-{a!r} and {a!r}-{b!r}",
                    len(common),
                    min_common,
                    "points seen in all three images",
                )
            P_strip = np.array([prev_points[p] for p in common])
            P_model = np.array([pts[p] for p in common])
            d_strip = np.linalg.norm(P_strip - strip_a.position, axis=1)
            d_model = np.linalg.norm(P_model - ea.position, axis=1)
            ratios = d_strip / d_model
            s = float(np.median(ratios))
            spreads.append(float(np.median(np.abs(ratios / s - 1.0))))
            scales.append(s)
            t = strip_a.position - s * R @ ea.position
        if k == 0:
            exteriors[a] = ea
        exteriors[b] = ExteriorOrientation.from_matrix(
            s * R @ eb.position + t, eb.matrix @ R.T, on_gimbal_lock="omega-zero"
        )
        strip_pts = {p: s * R @ x + t for p, x in pts.items()}
        for p, x in strip_pts.items():
            sums[p] = sums.get(p, 0.0) + x
            counts[p] = counts.get(p, 0) + 1
        prev_points = strip_pts
    points = {p: sums[p] / counts[p] for p in sums}
    return StripModel(
        imgs, exteriors, points, tuple(fits), tuple(scales), tuple(spreads), tuple(bridged)
    )


def block_start(
    strips: Sequence[Sequence[Hashable]],
    interiors: Mapping[Hashable, InteriorOrientation],
    observations: Mapping[Hashable, Mapping[Hashable, Sequence[float]]],
    control: Mapping[Hashable, Sequence[float]],
    *,
    method: str = "independent",
    sigma=None,
    min_common: int = 3,
    seed: int | None = 0,
) -> BlockStart:
    """Initial exterior orientations of every image of a block from GCPs alone.

    Parameters
    ----------
    strips : sequence of sequences of image ids, each strip in flight order.
    interiors : mapping image id -> InteriorOrientation.
    observations : mapping image id -> {point id: (x, y)} (image system, unit of the interior
        orientation).
    control : mapping point id -> (X, Y, Z) ground coordinates of the control points.
    method, sigma, min_common, seed
        As in :func:`orient_strip`.

    Returns
    -------
    BlockStart
        ``exteriors`` {image id: ExteriorOrientation} and ``points`` {point id: (3,)} in the
        ground system, with the strip models and absolute orientations.

    Raises
    ------
    TooFewPointsError
        Fewer than three control points observed in the strips' images (refused before
        any relative orientation is computed: the first strip needs three), or a strip
        with fewer than three control points and fewer than three tie points shared with
        the strips oriented before it.
    """

    if not strips:
        raise InputError("block_start needs at least one strip")
    ctrl = {p: np.asarray(x, dtype=float).reshape(3) for p, x in control.items()}
    seen = set().union(*(observations.get(i, {}).keys() for s in strips for i in s))
    n_ctrl = len(seen.intersection(ctrl))
    if n_ctrl < 3:
        raise TooFewPointsError(
            "block start: control points observed in the strips' images",
            n_ctrl,
            3,
            "the strips are oriented to them, and the first strip needs three not on a line; "
            f"{len(ctrl)} control point(s) given",
        )
    models = [
        orient_strip(
            s,
            interiors,
            observations,
            method=method,
            sigma=sigma,
            min_common=min_common,
            seed=seed,
        )
        for s in strips
    ]
    # units: strips (or strips joined in model space) oriented by one similarity each
    units = [
        {"strips": [k], "exteriors": dict(m.exteriors), "points": dict(m.points)}
        for k, m in enumerate(models)
    ]
    exteriors: dict = {}
    ground: dict = {}
    fits: list = [None] * len(models)
    used: list = [()] * len(models)
    pending = list(range(len(units)))

    def known(u):
        ids = [p for p in u["points"] if p in ctrl]
        if len(ids) < 3:
            ids += [p for p in u["points"] if p in ground and p not in ctrl]
        return ids

    def name(u):
        return ", ".join(f"strip {k + 1}" for k in u["strips"])

    while pending:
        counts = [len(known(units[k])) for k in pending]
        best = int(np.argmax(counts))
        if counts[best] >= 3:
            k = pending.pop(best)
            u = units[k]
            ids = known(u)
            src = np.array([u["points"][p] for p in ids])
            dst = np.array([ctrl[p] if p in ctrl else ground[p] for p in ids])
            try:
                fit = _strip_to_ground(src, dst, ids=[str(p) for p in ids])
            except DegenerateGeometryError as exc:
                raise DegenerateGeometryError(
                    f"absolute orientation of {name(u)}: {exc}; spread the control points"
                ) from exc
            for m in u["strips"]:
                fits[m], used[m] = fit, tuple(ids)
            sc, R, t = fit.scale, fit.rotation, fit.translation
            for img, e in u["exteriors"].items():
                exteriors[img] = _moved(e, sc, R, t)
            for p, x in u["points"].items():
                g = sc * R @ x + t
                ground[p] = (ground[p] + g) / 2.0 if p in ground else g
            continue
        # no unit has three known points: join the one with the most control points to the
        # pending unit it shares the most tie points with (in model space), then try again
        a = max(pending, key=lambda k: (sum(p in ctrl for p in units[k]["points"]), -k))
        others = [k for k in pending if k != a]
        shared = [sum(p in units[a]["points"] for p in units[k]["points"]) for k in others]
        if not others or max(shared) < 3:
            u = units[a]
            raise TooFewPointsError(
                f"absolute orientation of {name(u)} ({', '.join(map(str, _images(u)))})",
                counts[pending.index(a)],
                3,
                "control points in the strips, or tie points shared with strips that have them",
            )
        b = others[int(np.argmax(shared))]
        _join(units[a], units[b])
        pending.remove(b)
    return BlockStart(exteriors, ground, tuple(models), tuple(fits), tuple(used))


def _strip_to_ground(src: np.ndarray, dst: np.ndarray, ids=None):
    """The similarity with a proper rotation that carries strip (model) coordinates ``src``
    (n, 3) onto ``dst`` (n, 3), ground or another model's coordinates.

    A strip is right-handed by construction (its models are intersections of rotated rays), so
    a mirror image that fits its points better means a strip bent by its chain of models, not
    a left-handed one: a start calibration without the lens distortion bent strips of 50
    images through four turns until their five nearly coplanar control points, up to 7 m off
    in height, favoured the mirror (:class:`ReflectionError` before). The best proper
    rotation is the start then; the bundle adjustment removes the bending.
    """
    from .absolute import absolute_orientation

    return absolute_orientation(src, dst, method="svd", ids=ids, reflection="rotation")


def _moved(e: ExteriorOrientation, s: float, R: np.ndarray, t: np.ndarray):
    """An exterior orientation carried by the similarity ``X = s R x + t``."""
    return ExteriorOrientation.from_matrix(
        s * R @ e.position + t, e.matrix @ R.T, on_gimbal_lock="omega-zero"
    )


def _images(u: dict) -> list:
    return list(u["exteriors"])


def _join(a: dict, b: dict) -> None:
    """Carry unit ``b`` into the model system of unit ``a`` (similarity on their common
    points, one pass removing points off by more than five times the median) and merge."""

    common = [p for p in b["points"] if p in a["points"]]
    src = np.array([b["points"][p] for p in common])
    dst = np.array([a["points"][p] for p in common])
    fit = _strip_to_ground(src, dst)
    err = np.linalg.norm(fit.residuals, axis=1)
    keep = err <= 5.0 * max(float(np.median(err)), 1e-12)
    if 3 <= keep.sum() < len(common):
        fit = _strip_to_ground(src[keep], dst[keep])
    s, R, t = fit.scale, fit.rotation, fit.translation
    for img, e in b["exteriors"].items():
        a["exteriors"].setdefault(img, _moved(e, s, R, t))
    for p, x in b["points"].items():
        g = s * R @ x + t
        a["points"][p] = (a["points"][p] + g) / 2.0 if p in a["points"] else g
    a["strips"] += b["strips"]


def points_from_exteriors(
    exteriors: Mapping[Hashable, ExteriorOrientation],
    interiors: Mapping[Hashable, InteriorOrientation],
    observations: Mapping[Hashable, Mapping[Hashable, Sequence[float]]],
    *,
    min_rays: int = 2,
    chunk: int = 2_000_000,
) -> dict:
    """Tie-point start values by intersection from known exterior orientations (GNSS/IMU).

    Parameters
    ----------
    exteriors : mapping image id -> ExteriorOrientation (e.g. from GNSS/IMU).
    interiors : mapping image id -> InteriorOrientation.
    observations : mapping image id -> {point id: (x, y)} (image system, unit of the interior
        orientation).
    min_rays : int
        Points seen in fewer images are left out.
    chunk : int
        Largest ``images x points`` block intersected at once (memory bound).

    Returns
    -------
    dict
        point id -> (3,) ground coordinates (least-squares intersection of all rays).
    """
    from .intersection import space_intersection

    imgs = [i for i in exteriors if i in observations]
    for i in imgs:
        if i not in interiors:
            raise InputError(f"image {i!r}: no interior orientation given")
    count: dict = {}
    for i in imgs:
        for p in observations[i]:
            count[p] = count.get(p, 0) + 1
    ids = [p for p, c in count.items() if c >= max(min_rays, 2)]
    cams = [(interiors[i], exteriors[i]) for i in imgs]
    step = max(1, chunk // max(len(imgs), 1))
    out: dict = {}
    for s in range(0, len(ids), step):
        part = ids[s : s + step]
        index = {p: k for k, p in enumerate(part)}
        obs = np.full((len(imgs), len(part), 2), np.nan)
        for k, i in enumerate(imgs):
            o = observations[i]
            sel = [p for p in o if p in index]
            if sel:
                obs[k, [index[p] for p in sel]] = np.array([o[p] for p in sel], dtype=float)
        used = np.any(np.isfinite(obs[:, :, 0]), axis=1)
        res = space_intersection(obs[used], [c for c, u in zip(cams, used) if u])
        out.update(zip(part, res.points))
    return out
