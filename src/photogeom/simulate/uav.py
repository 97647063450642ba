"""Simulated UAV blocks with known truth (06-bundle-adjustment.md, 05-residual-grid.md).

:func:`uav_block` flies a serpentine block of strips over a terrain, projects random tie
points, ground control and check points into every image that sees them with the true
camera (Brown distortion, optional image-variant calibration), adds the image-variant local
displacement field, measurement noise and blunders, and returns the block to adjust (initial
values from GNSS/IMU, nominal calibration, tie points triangulated from the initial cameras)
together with the truth. Everything is drawn from one ``numpy.random.Generator``: the same
seed gives the same block.

Geometry: strips run along +X (the first) and alternate in direction; the image's u axis
(width) is across the track and the top of the image looks ahead, so the along-track
footprint is ``height * GSD`` and the across-track footprint ``width * GSD``. Heights are in
metres above the datum of the terrain model; the flying height is measured above the mean
terrain height.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ..bundle.block import DEFAULT_FREE, IMAGE_VARIANT_NAMES, Block
from ..bundle.triangulate import triangulate
from ..camera.frame_kernel import project_rows
from ..camera.metashape import MetashapeCalibration
from ..errors import DegenerateGeometryError, InputError
from ..records import freeze_fields, read_only_fields, setstate_read_only
from ..rotation import opk_matrix
from .fields import LocalDistortionField, WaveTerrain, ar1_along_flight, check_field_options
from .presets import CameraPreset, preset

__all__ = ["SimulatedBlock", "uav_block"]

#: Offsets of control and check point ids from the tie point ids (all ids are integers).
CONTROL_ID0 = 1_000_000
CHECK_ID0 = 2_000_000
#: Candidate (image, point) pairs projected per chunk (bounds memory on large blocks).
_PAIR_CHUNK = 1 << 20


@dataclass(frozen=True, eq=False)
class SimulatedBlock:
    """A simulated block and its truth (returned by :func:`uav_block`).

    Attributes
    ----------
    block : Block
        The block to adjust: observed pixels (ideal + local field + noise + blunders),
        initial exterior orientation (GNSS/IMU, or perturbed truth), initial calibration,
        tie points triangulated from the initial cameras (where those cannot intersect a
        point, the mean of its initial rays' points at the mean terrain height), control and
        check points at their surveyed (noisy) coordinates. The points and observations
        depend on the true geometry only, not on the start values.
    truth : Block
        The same ids with the true exterior orientation, points, calibration (and
        image-variant offsets); its observations are the ideal pixels, so its
        reprojection residuals are zero.
    preset : CameraPreset
    camera : MetashapeCalibration
        The true camera (group calibration).
    gsd : float
        Nominal ground sample distance, metres per pixel.
    flying_height : float
        Metres above the mean terrain height.
    terrain : callable
        ``Z(X, Y)`` of the simulated ground, metres.
    field : LocalDistortionField
        The image-variant local displacement fields.
    ideal, local, noise : (n, 2)
        Per observation (block order): the true projection, the local-field displacement at
        the ideal pixel and the measurement noise, pixels.
    blunder_rows : (b,) observation rows that carry a blunder.
    blunder_offsets : (b, 2) the blunders added to those rows, px.
    control_ids, check_ids, tie_ids : ids of the points by role.
    options : mapping
        The resolved options (units as in :func:`uav_block`); read-only.
    """

    block: Block
    truth: Block
    preset: CameraPreset
    camera: MetashapeCalibration
    gsd: float
    flying_height: float
    terrain: Callable
    field: LocalDistortionField
    ideal: np.ndarray
    local: np.ndarray
    noise: np.ndarray
    blunder_rows: np.ndarray
    blunder_offsets: np.ndarray
    control_ids: np.ndarray
    check_ids: np.ndarray
    tie_ids: np.ndarray
    options: Mapping = field(default_factory=dict)

    def __post_init__(self) -> None:
        # the truth is read-only: the block's observations were made from these arrays (and
        # the options, which summary reads)
        read_only_fields(self)
        freeze_fields(self, ("options",))

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the arrays stay read-only
        freeze_fields(self, ("options",))

    @property
    def observed(self) -> np.ndarray:
        """(n, 2) observed pixels (the block's observations)."""
        return self.block.observations.uv

    @property
    def blunders(self) -> np.ndarray:
        """(n, 2) blunder displacement per observation (zero for most), pixels."""
        out = np.zeros_like(self.ideal)
        out[self.blunder_rows] = self.blunder_offsets
        return out

    def local_field(self, image_id, uv) -> np.ndarray:
        """The true local displacement that the simulator added to observations.

        ``observed = ideal + local_field(image, ideal) + noise (+ blunder)``.

        Parameters
        ----------
        image_id : hashable or sequence
            One image id, or one id per row of ``uv``.
        uv : array_like, shape (n, 2) or (2,)
            Ideal pixels (col, row).

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            ``(du, dv)``, px.

        Raises
        ------
        InputError
            For an id that is not an image of the block, or ``uv`` not of shape (n, 2) or
            (2,).
        """
        return self.field(image_id, uv)

    def rematch(self, block: Block | None = None, *, seed=None) -> Block:
        """The block's image points measured again, as a re-matching of the images would.

        Every observation becomes ``ideal + local field + fresh noise``: a new draw of the
        measurement noise with each observation's sigma (tie and control/check sigmas as
        simulated), the same points in the same images, no blunders. In the residual-grid
        study the corrected images are matched anew, so the grids, fitted to the first
        matching's residuals, meet measurements whose noise they have not seen; correcting
        the simulated observations themselves (the spec's choice for simulated blocks)
        instead lets a grid that has fitted noise look better than it is.

        Parameters
        ----------
        block : Block, optional
            A block with this simulated block's observations in the same rows, e.g. the
            adjusted ``pg.bundle_adjust(sim.block).block`` (default: ``sim.block``). Its
            orientations, calibration and points are kept; only the observed pixels change.
        seed : int or numpy.random.Generator, optional
            The noise is drawn from ``numpy.random.default_rng(seed)``.

        Returns
        -------
        Block

        Raises
        ------
        InputError
            ``block`` does not hold the simulated observations row for row (other images or
            points, observations dropped or reordered, e.g. by data snooping).
        """
        b = self.block if block is None else block
        if not isinstance(b, Block):
            raise InputError(f"rematch: block must be a Block, not {type(b).__name__}")
        ref = self.block
        if not ref.same_observation_rows(b):
            raise InputError(
                f"rematch: the block's {b.obs_image.size} observations are not the simulated "
                f"block's {ref.obs_image.size} in the same rows (same image and point per "
                "row); pass sim.block or a block adjusted from it without removing "
                "observations (snooping=False)"
            )
        sigma = ref.observations.sigma
        noise = np.random.default_rng(seed).standard_normal(self.ideal.shape) * sigma[:, None]
        return b.with_observations(uv=self.ideal + self.local + noise)

    def summary(self) -> str:
        """A few lines on the simulated block.

        Camera, GSD (cm), flying height (m), overlaps, terrain, the block's counts
        (:meth:`Block.summary`), the noise (px), the RMS of the local field (px) and the number
        of blunders.

        Returns
        -------
        str
        """
        o = self.options
        lines = [
            f"simulated {self.preset.name} block: GSD {self.gsd * 100:.2f} cm, flying height "
            f"{self.flying_height:.1f} m, overlaps {o['forward_overlap']:.0%} / "
            f"{o['side_overlap']:.0%}, terrain {o['terrain']}",
            self.block.summary(),
            f"noise {o['sigma']} px (tie), {o['gcp_sigma']} px (control/check); local field "
            f"RMS {self.field.rms} px{self._smooth_note()}; {self.blunder_rows.size} "
            "blunder(s)",
        ]
        return "\n".join(lines)

    def _smooth_note(self) -> str:
        if self.field.smooth <= 0:
            return ""
        return f" + smooth {self.field.smooth} px (total {self.field.total_rms:.3g} px)"

    def __repr__(self) -> str:
        return f"SimulatedBlock({self.preset.name}, {self.block!r})"


def _triple(v, name: str) -> np.ndarray | None:
    if v is None:
        return None
    a = np.broadcast_to(np.asarray(v, dtype=float), (3,)).copy()
    if np.any(~np.isfinite(a)) or np.any(a < 0):
        raise InputError(f"{name} must be >= 0 and finite, got {v!r}")
    return a


def _strip_counts(preset_: CameraPreset, size, strips, images_per_strip) -> list[int]:
    if size == "study":
        return list(preset_.study_strips)
    if size != "small":
        raise InputError(f"size must be 'small' or 'study', got {size!r}")
    if isinstance(images_per_strip, (int, np.integer)):
        if strips < 1 or images_per_strip < 2:
            raise InputError("a block needs strips >= 1 and images_per_strip >= 2")
        return [int(images_per_strip)] * int(strips)
    counts = [int(c) for c in images_per_strip]
    if not counts or min(counts) < 2:
        raise InputError("images_per_strip: every strip needs at least 2 images")
    return counts


def _layout(spec, extent, rng: np.random.Generator, name: str) -> np.ndarray:
    """Ground (X, Y) positions of a point layout over ``extent`` (xmin, xmax, ymin, ymax)."""
    xmin, xmax, ymin, ymax = extent
    xc, yc = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    corners = np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]])
    if spec is None:
        return np.zeros((0, 2))
    if isinstance(spec, str):
        if spec == "none":
            return np.zeros((0, 2))
        if spec == "corners":
            return corners
        if spec == "corners+centre":
            return np.vstack([corners, [[xc, yc]]])
        if spec == "edges":
            return np.array([[xc, ymin], [xmax, yc], [xc, ymax], [xmin, yc]])
        if spec == "centre":
            return np.array([[xc, yc]])
        if spec.startswith("grid"):
            try:
                k = int(spec[4:] or 3)
            except ValueError:
                k = -1
            if k < 2:
                raise InputError(f"{name}: 'gridK' needs K >= 2 (e.g. 'grid3'), got {spec!r}")
            gx, gy = np.meshgrid(np.linspace(xmin, xmax, k), np.linspace(ymin, ymax, k))
            return np.column_stack([gx.ravel(), gy.ravel()])
        raise InputError(
            f"{name}: unknown layout {spec!r}; use 'corners', 'corners+centre', 'edges', "
            "'centre', 'gridK', 'none', a count (random positions) or an (n, 2) array of X, Y"
        )
    if isinstance(spec, (int, np.integer)):
        if spec < 0:
            raise InputError(f"{name}: a count must be >= 0, got {spec}")
        return np.column_stack([rng.uniform(xmin, xmax, spec), rng.uniform(ymin, ymax, spec)])
    a = np.asarray(spec, dtype=float)
    if a.ndim != 2 or a.shape[1] != 2 or not np.all(np.isfinite(a)):
        raise InputError(f"{name}: an explicit layout is an (n, 2) array of X, Y (metres)")
    return a


def _footprint_boxes(cam, offsets, M, C, zmin: float, zmax: float) -> np.ndarray:
    """Ground bounding boxes (m, 4: xmin, xmax, ymin, ymax) of each image's view of the
    terrain between heights ``zmin`` and ``zmax``: rays through 32 points of the image border
    (undistorted with the image's calibration, 2 % margin) intersected with both planes."""
    W, H = cam.width - 1.0, cam.height - 1.0
    t = np.linspace(0.0, 1.0, 9)[:-1]
    border = np.vstack(
        [
            np.column_stack([t * W, np.zeros_like(t)]),
            np.column_stack([np.full_like(t, W), t * H]),
            np.column_stack([W - t * W, np.full_like(t, H)]),
            np.column_stack([np.zeros_like(t), H - t * H]),
        ]
    )
    m = C.shape[0]
    xy = np.empty((m, border.shape[0], 2))
    for g in np.unique(offsets, axis=0):  # distinct image calibrations, not points
        sel = np.all(offsets == g, axis=1)
        c = replace(cam, f=cam.f + g[0], cx=cam.cx + g[1], cy=cam.cy + g[2])
        res = c.unproject(border)
        xy[sel] = res.points * 1.02
    dcam = np.concatenate([xy[:, :, :1], -xy[:, :, 1:], -np.ones((m, xy.shape[1], 1))], axis=2)
    d = np.einsum("mji,mkj->mki", M, dcam)  # object-space directions (M' p)
    out = np.empty((m, 4))
    pts = []
    for z in (zmin, zmax):
        s = (z - C[:, None, 2]) / d[:, :, 2]  # > 0 for rays going down to the plane
        s = np.where(s > 0, s, np.nan)
        pts.append(C[:, None, :2] + s[:, :, None] * d[:, :, :2])
    P = np.concatenate(pts, axis=1)
    if np.any(~np.isfinite(P)):
        raise InputError(
            "an image looks above the horizon of the terrain (tilt too large for the field of "
            "view): lower attitude_jitter_deg"
        )
    out[:, 0], out[:, 1] = P[:, :, 0].min(axis=1), P[:, :, 0].max(axis=1)
    out[:, 2], out[:, 3] = P[:, :, 1].min(axis=1), P[:, :, 1].max(axis=1)
    return out


def _candidate_pairs(boxes: np.ndarray, XY: np.ndarray):
    """(image row, point row) pairs with the point inside the image's ground box: points
    sorted into a grid of cells, each box covering contiguous runs of cells per cell row
    (vectorised over images and points)."""
    cell = 0.25 * float(np.min(np.minimum(boxes[:, 1] - boxes[:, 0], boxes[:, 3] - boxes[:, 2])))
    cell = max(cell, 1e-9)
    lo = XY.min(axis=0)
    ij = np.floor((XY - lo) / cell).astype(np.int64)
    ncx = int(ij[:, 0].max()) + 1
    ncy = int(ij[:, 1].max()) + 1
    key = ij[:, 1] * ncx + ij[:, 0]
    order = np.argsort(key, kind="stable")
    skey = key[order]
    ix0 = np.clip(np.floor((boxes[:, 0] - lo[0]) / cell), 0, ncx - 1).astype(np.int64)
    ix1 = np.clip(np.floor((boxes[:, 1] - lo[0]) / cell), 0, ncx - 1).astype(np.int64)
    iy0 = np.clip(np.floor((boxes[:, 2] - lo[1]) / cell), 0, ncy - 1).astype(np.int64)
    iy1 = np.clip(np.floor((boxes[:, 3] - lo[1]) / cell), 0, ncy - 1).astype(np.int64)
    rows = int(np.max(iy1 - iy0)) + 1
    iy = iy0[:, None] + np.arange(rows)[None, :]
    valid = iy <= iy1[:, None]
    start = np.searchsorted(skey, iy * ncx + ix0[:, None], side="left")
    stop = np.searchsorted(skey, iy * ncx + ix1[:, None], side="right")
    count = np.where(valid, stop - start, 0).ravel()
    start = start.ravel()
    img = np.repeat(np.repeat(np.arange(boxes.shape[0]), rows), count)
    first = np.repeat(np.cumsum(count) - count, count)
    pos = np.arange(int(count.sum())) - first + np.repeat(start, count)
    pts = order[pos]
    inside = (
        (XY[pts, 0] >= boxes[img, 0])
        & (XY[pts, 0] <= boxes[img, 1])
        & (XY[pts, 1] >= boxes[img, 2])
        & (XY[pts, 1] <= boxes[img, 3])
    )
    return img[inside], pts[inside]


def _project_pairs(img, pts, X, M, C, calv, size):
    """Pixels, depth and ideal normalised radius of (image, point) pairs, in chunks."""
    uv = np.empty((img.size, 2))
    depth = np.empty(img.size)
    radius = np.empty(img.size)
    for s in range(0, img.size, _PAIR_CHUNK):  # chunks of pairs, not single pairs
        e = min(s + _PAIR_CHUNK, img.size)
        i, j = img[s:e], pts[s:e]
        pr = project_rows(X[j], M[i], C[i], calv[i], size[i], jacobian=False)
        uv[s:e] = pr.uv
        depth[s:e] = pr.depth
        p = np.einsum("nij,nj->ni", M[i], X[j] - C[i])
        with np.errstate(divide="ignore", invalid="ignore"):
            radius[s:e] = np.hypot(p[:, 0], p[:, 1]) / np.abs(p[:, 2])
    return uv, depth, radius


def _max_radius(cam: MetashapeCalibration) -> float:
    """Ideal normalised radius of the farthest image corner (slightly enlarged), checked to
    lie where the radial distortion is still one-to-one: rays beyond it cannot reach the
    frame, although the polynomial may fold them back into it."""
    W, H = cam.width, cam.height
    corners = np.array([[0.0, 0.0], [W - 1.0, H - 1.0], [0.0, H - 1.0], [W - 1.0, 0.0]])
    res = cam.unproject(corners)
    if not res.all_converged:
        raise InputError(
            "the true camera's distortion cannot be inverted at the image corners "
            f"({res.describe_failures()}): choose smaller distortion coefficients"
        )
    rmax = float(np.max(np.hypot(res.points[:, 0], res.points[:, 1]))) * 1.02
    r2 = np.linspace(0.0, rmax, 200) ** 2
    d = 1 + r2 * (3 * cam.k1 + r2 * (5 * cam.k2 + r2 * (7 * cam.k3 + r2 * 9 * cam.k4)))
    if np.any(d <= 0):
        raise InputError(
            "the true camera's radial distortion folds over inside the image "
            "(d r_distorted / d r <= 0): choose smaller distortion coefficients"
        )
    return rmax


def _terrain_height_starts(
    block: Block, points: np.ndarray, height: float
) -> tuple[np.ndarray, np.ndarray]:
    """Start coordinates of points from their rays in the block's cameras and a height.

    Parameters
    ----------
    block : Block
        Cameras (calibration, exterior orientation) and observations.
    points : (k,) int
        Rows of the points in ``block``.
    height : float
        Ground height Z the rays are cut with, in the block's length unit (metres).

    Returns
    -------
    xyz : (k, 3) float
        Mean of the points where each of a point's rays cuts ``Z = height`` in front of its
        camera (``Z = height``; NaN where no ray does).
    hit : (k,) bool
        Points with at least one such ray.
    """
    from ..bundle.triangulate import normalized_rays

    local = np.full(block.n_points, -1, dtype=np.int64)
    local[points] = np.arange(points.size)
    rows = np.flatnonzero(local[block.obs_point] >= 0)
    xy, ok = normalized_rays(block, rows)
    img = block.obs_image[rows]
    dcam = np.column_stack([xy[:, 0], -xy[:, 1], -np.ones(rows.size)])
    d = np.einsum("nji,nj->ni", block.rotations()[img], dcam)
    C = block.exterior[img, :3]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (height - C[:, 2]) / d[:, 2]
    good = ok & np.isfinite(lam) & (lam > 0)
    lp = local[block.obs_point[rows]][good]
    X = C[good] + lam[good, None] * d[good]
    n = np.bincount(lp, minlength=points.size)
    xyz = np.column_stack(
        [np.bincount(lp, weights=X[:, a], minlength=points.size) for a in range(2)]
        + [np.full(points.size, height)]
    )
    hit = n > 0
    xyz[hit, :2] /= n[hit, None]
    xyz[~hit] = np.nan
    return xyz, hit


def uav_block(
    camera: str | CameraPreset = "FC300S",
    *,
    seed: int | np.random.Generator | None = None,
    gsd: float | None = None,
    flying_height: float | None = None,
    size: str = "small",
    strips: int = 3,
    images_per_strip: int | Sequence[int] = 7,
    forward_overlap: float | None = None,
    side_overlap: float | None = None,
    terrain: str | Callable = "hilly",
    relief: float | None = None,
    terrain_height: float = 0.0,
    origin: Sequence[float] = (0.0, 0.0),
    tie_points_per_image: float = 120.0,
    observation_probability: float = 1.0,
    min_rays: int = 2,
    border: float = 2.0,
    gcps="corners+centre",
    checks=4,
    survey_sigma=(0.01, 0.01, 0.02),
    sigma: float = 0.3,
    gcp_sigma: float = 0.5,
    gnss_sigma=(0.03, 0.03, 0.05),
    imu_sigma_deg: float | None = 1.0,
    position_jitter=(1.0, 1.0, 0.5),
    attitude_jitter_deg: float = 1.5,
    initial_position_error: float = 5.0,
    initial_attitude_error_deg: float = 2.0,
    blunders: int = 0,
    blunder_size: float = 50.0,
    brown: bool | Mapping[str, float] = True,
    true_camera: MetashapeCalibration | None = None,
    initial_camera: str | MetashapeCalibration = "nominal",
    local_field: float | None = None,
    local_field_modes: int = 6,
    local_field_correlation: float = 0.9,
    local_field_static: float = 0.0,
    local_field_slope: float = 1.0,
    local_field_smooth: float = 0.0,
    calibration_variation=None,
    calibration_correlation: float = 0.9,
    free: Sequence[str] | None = None,
) -> SimulatedBlock:
    """Simulate a UAV block with known truth.

    Parameters
    ----------
    camera : str or CameraPreset
        ``"ILCE-7RM2"``, ``"FC6310"`` or ``"FC300S"`` (see :mod:`photogeom.simulate.presets`).
    seed : int or numpy.random.Generator, optional
        Everything random is drawn from ``numpy.random.default_rng(seed)``.
    gsd : float, optional
        Ground sample distance, metres per pixel (default: the study's for the camera);
        the flying height is ``H = gsd * f`` with the nominal focal length in pixels.
    flying_height : float, optional
        Metres above the mean terrain height; overrides ``gsd``.
    size : {"small", "study"}
        ``"small"``: ``strips`` x ``images_per_strip``; ``"study"``: the study's block
        (250 / 195 / 82 images for ILCE-7RM2 / FC6310 / FC300S).
    strips : int
        Number of strips (>= 1) with ``size="small"``.
    images_per_strip : int or sequence of int
        Images per strip (>= 2), or one count per strip (then ``strips`` is not used).
    forward_overlap, side_overlap : float, optional
        Fractions (default: the preset's, 0.7 / 0.4 for ILCE-7RM2, 0.8 / 0.7 otherwise).
    terrain : {"hilly", "flat"} or callable
        ``"hilly"``: random smooth hills of peak-to-peak height ``relief``; ``"flat"``:
        ``Z = terrain_height``; a callable ``Z(X, Y)`` (vectorised, metres).
    relief : float, optional
        Peak-to-peak height of the hills, metres (default 0.1 H).
    terrain_height : float
        Mean ground height, metres.
    origin : (float, float)
        Ground X, Y of the block's first image (metres; e.g. UTM-sized values to test
        conditioning).
    tie_points_per_image : float
        Mean number of tie points in one image's ground footprint.
    observation_probability : float
        Probability that a point inside an image is measured there (matching success).
    min_rays : int
        Tie points seen by fewer images are dropped (>= 2).
    border : float
        Observations closer than this to the image edge are not made, pixels.
    gcps, checks : layout
        ``"corners"``, ``"corners+centre"``, ``"edges"``, ``"centre"``, ``"gridK"``,
        ``"none"``, a count (random positions) or an (n, 2) array of ground X, Y (metres).
        Named layouts are laid over the rectangle of the projection centres.
    survey_sigma : float or (3,)
        Standard deviations of the surveyed control/check coordinates, metres (the block's
        coordinates carry this noise; the truth's are exact).
    sigma : float
        Standard deviation of tie-point image measurements, pixels (noise drawn and stated).
    gcp_sigma : float
        Standard deviation of control/check image measurements, pixels.
    gnss_sigma : float or (3,) or None
        Standard deviations of the GNSS projection centres, metres; None: no GNSS (initial
        positions are the truth perturbed by ``initial_position_error``).
    imu_sigma_deg : float or None
        Standard deviation of the IMU attitude, degrees; None: no IMU (initial angles are the
        truth perturbed by ``initial_attitude_error_deg``).
    position_jitter : float or (3,)
        Standard deviations of the true projection centres about the flight plan, metres.
    attitude_jitter_deg : float
        Standard deviation of the true omega, phi, kappa about the nadir heading, degrees.
    initial_position_error : float
        Without GNSS: standard deviation of the initial projection centres, metres.
    initial_attitude_error_deg : float
        Without IMU: standard deviation of the initial angles, degrees.
    blunders, blunder_size : int, float
        Number of tie observations given a blunder of ``blunder_size`` pixels (random
        direction); their rows are :attr:`SimulatedBlock.blunder_rows`.
    brown : bool or mapping
        True: the preset's true Brown distortion; False: none (principal point offsets
        kept); a mapping overrides single coefficients (``k1 .. k4``, ``p1``, ``p2``, ``b1``,
        ``b2``, ``cx``, ``cy``, ``f``).
    true_camera : MetashapeCalibration, optional
        The true camera, replacing the preset's (and ``brown``).
    initial_camera : "nominal" or "truth" or MetashapeCalibration
        The block's starting calibration: the preset's nominal camera (nominal f, centred
        principal point, no distortion), the true camera, or a given one.
    local_field : float, optional
        RMS length of the image-variant local displacement fields, pixels (default: the
        preset's: 1.0 px for ILCE-7RM2, 0.15 px otherwise; 0: none).
    local_field_modes : int
        Highest wave number of the fields (shortest wavelength ``width / modes``).
    local_field_correlation : float
        Correlation of the field coefficients between consecutive images, in [0, 1).
    local_field_static : float
        Share of the field's variance common to all images, in [0, 1].
    local_field_slope : float
        The fields' coefficients fall as ``1 / |k|**slope`` with the wave number (>= 0;
        default 1: about equal variance per octave; 3: nearly all in the longest waves).
    local_field_smooth : float
        RMS of a second, smooth component of the local fields, pixels (default 0: none): the
        four waves one cycle long across the image (coefficients falling as ``1 / |k|``),
        drawn independently of the first component with the same
        ``local_field_correlation`` and ``local_field_static``; the fields' expected RMS is
        then ``sqrt(local_field**2 + local_field_smooth**2)``. A smooth deformation that
        changes from image to image beside a finer one (a stand-in for, e.g., a sensor that
        moves slightly between images; its form is the field's longest waves, not a tilt's
        projective one); it is part of :attr:`SimulatedBlock.field`, ``local`` and the
        observations.
    calibration_variation, calibration_correlation : float or (3,) or None, float
        Standard deviations of image-variant offsets of f, cx, cy, pixels (AR(1) along the
        flight with correlation ``calibration_correlation`` between consecutive images);
        the blocks then estimate those names per image (``image_variant``).
    free : sequence of str, optional
        Calibration parameters the block marks free (default: Metashape's f, cx, cy, k1-k3,
        p1, p2).

    Returns
    -------
    SimulatedBlock

    Raises
    ------
    InputError
        Invalid options (named).
    DegenerateGeometryError
        A control or check point seen by fewer than two images.
    """
    P = preset(camera)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    fo = P.forward_overlap if forward_overlap is None else float(forward_overlap)
    so = P.side_overlap if side_overlap is None else float(side_overlap)
    for nm, v in (("forward_overlap", fo), ("side_overlap", so)):
        if not 0.0 <= v < 1.0:
            raise InputError(f"{nm} must be in [0, 1), got {v}")
    if not 0.0 < observation_probability <= 1.0:
        raise InputError("observation_probability must be in (0, 1]")
    if min_rays < 2:
        raise InputError("min_rays must be >= 2 (a tie point needs two rays)")
    for nm, v in (("sigma", sigma), ("gcp_sigma", gcp_sigma)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{nm} must be > 0 (pixels), got {v}")
    if blunders < 0:
        raise InputError(f"blunders must be >= 0 (a number of observations), got {blunders}")
    if not (np.isfinite(blunder_size) and blunder_size >= 0):
        raise InputError(f"blunder_size must be >= 0 (pixels), got {blunder_size}")
    if not (np.isfinite(tie_points_per_image) and tie_points_per_image > 0):
        # checked here: numpy's Poisson draw would fail on it with its own words
        raise InputError(
            f"tie_points_per_image must be > 0 (a mean number of points), got "
            f"{tie_points_per_image}"
        )
    check_field_options(
        0.0 if local_field is None else local_field,
        local_field_modes,
        local_field_correlation,
        local_field_static,
        local_field_slope,
        smooth=local_field_smooth,
        names={
            "rms": "local_field",
            "modes": "local_field_modes",
            "correlation": "local_field_correlation",
            "static": "local_field_static",
            "slope": "local_field_slope",
            "smooth": "local_field_smooth",
        },
    )
    # --- cameras ---------------------------------------------------------------------------
    if true_camera is not None:
        cam = true_camera
    else:
        cam = P.true_camera(brown=bool(brown))
        if isinstance(brown, Mapping):
            try:
                cam = MetashapeCalibration(**{**cam.__dict__, **dict(brown)})
            except TypeError as exc:
                raise InputError(f"brown: unknown calibration parameter ({exc})") from None
    nominal = P.nominal_camera()
    if isinstance(initial_camera, MetashapeCalibration):
        cam0 = initial_camera
    elif initial_camera == "nominal":
        cam0 = nominal
    elif initial_camera == "truth":
        cam0 = cam
    else:
        raise InputError(
            f"initial_camera must be 'nominal', 'truth' or a MetashapeCalibration, got "
            f"{initial_camera!r}"
        )
    W, Hpx = cam.width, cam.height
    if flying_height is not None:
        H = float(flying_height)
        g = H / P.focal_px
    else:
        g = P.gsd if gsd is None else float(gsd)
        H = g * P.focal_px
    if not (np.isfinite(H) and H > 0):
        raise InputError(f"gsd / flying_height must be > 0, got {g!r} / {H!r}")
    # --- flight plan (serpentine strips along X) -------------------------------------------
    counts = _strip_counts(P, size, strips, images_per_strip)
    along, across = Hpx * g, W * g
    base, spacing = (1.0 - fo) * along, (1.0 - so) * across
    X0s, Y0s, kap = [], [], []
    for s, c in enumerate(counts):  # strips, not points
        xs = np.arange(c) * base
        fwd = s % 2 == 0
        X0s.append(xs if fwd else xs[::-1])
        Y0s.append(np.full(c, -s * spacing))
        kap.append(np.full(c, -np.pi / 2 if fwd else np.pi / 2))
    X0 = np.concatenate(X0s) + origin[0]
    Y0 = np.concatenate(Y0s) + origin[1]
    kappa0 = np.concatenate(kap)
    m = X0.size
    image_ids = np.arange(m)
    pj = _triple(position_jitter, "position_jitter")
    C_true = np.column_stack([X0, Y0, np.full(m, terrain_height + H)])
    C_true = C_true + rng.standard_normal((m, 3)) * pj
    att = np.radians(attitude_jitter_deg) * rng.standard_normal((m, 3))
    ang_true = np.column_stack([att[:, 0], att[:, 1], kappa0 + att[:, 2]])
    ext_true = np.column_stack([C_true, ang_true])
    # --- terrain -----------------------------------------------------------------------------
    extent = (
        X0.min() - 0.5 * along,
        X0.max() + 0.5 * along,
        Y0.min() - 0.5 * across,
        Y0.max() + 0.5 * across,
    )
    rel = 0.1 * H if relief is None else float(relief)
    if callable(terrain):
        surf = terrain
        terrain_name = getattr(terrain, "__name__", "callable")
    elif terrain == "flat":
        surf = _Flat(float(terrain_height))
        terrain_name = "flat"
    elif terrain == "hilly":
        surf = WaveTerrain.random(rng, extent, rel, base=terrain_height)
        terrain_name = f"hilly ({rel:.1f} m relief)"
    else:
        raise InputError(f"terrain must be 'flat', 'hilly' or a callable Z(X, Y), got {terrain!r}")
    # --- points ------------------------------------------------------------------------------
    area = (extent[1] - extent[0]) * (extent[3] - extent[2])
    n_tie = int(rng.poisson(tie_points_per_image * area / (along * across)))
    XYt = np.column_stack(
        [rng.uniform(extent[0], extent[1], n_tie), rng.uniform(extent[2], extent[3], n_tie)]
    )
    cext = (X0.min(), X0.max(), Y0.min(), Y0.max())
    XYc = _layout(gcps, cext, rng, "gcps")
    XYk = _layout(checks, cext, rng, "checks")
    XY = np.vstack([XYt, XYc, XYk])
    Z = np.asarray(surf(XY[:, 0], XY[:, 1]), dtype=float).reshape(-1)
    if Z.shape != (XY.shape[0],) or not np.all(np.isfinite(Z)):
        raise InputError("terrain: Z(X, Y) must return finite heights, one per point")
    xyz_true = np.column_stack([XY, Z])
    role = np.array(
        ["tie"] * n_tie + ["control"] * XYc.shape[0] + ["check"] * XYk.shape[0], dtype="<U7"
    )
    pid = np.concatenate(
        [
            np.arange(n_tie),
            CONTROL_ID0 + np.arange(XYc.shape[0]),
            CHECK_ID0 + np.arange(XYk.shape[0]),
        ]
    )
    # --- image-variant calibration ------------------------------------------------------------
    calv = np.array([getattr(cam, n) for n in _CAL_NAMES], dtype=float)
    cv = _triple(calibration_variation, "calibration_variation")
    offsets = np.zeros((m, 3))
    variant: tuple[str, ...] = ()
    if cv is not None and np.any(cv > 0):
        name = "calibration_correlation"
        ar1 = ar1_along_flight(rng, m, (3,), calibration_correlation, name=name)
        offsets = ar1 * cv
        variant = tuple(n for n, s in zip(IMAGE_VARIANT_NAMES, cv) if s > 0)
        offsets[:, cv == 0] = 0.0
    cal_rows = np.tile(calv, (m, 1))
    cal_rows[:, :3] += offsets
    sizes = np.tile([float(W), float(Hpx)], (m, 1))
    # --- visibility ----------------------------------------------------------------------------
    M_true = np.asarray(opk_matrix(ang_true[:, 0], ang_true[:, 1], ang_true[:, 2])).reshape(
        -1, 3, 3
    )
    rmax = _max_radius(cam)
    boxes = _footprint_boxes(cam, offsets, M_true, C_true, float(Z.min()), float(Z.max()))
    ci, cj = _candidate_pairs(boxes, xyz_true[:, :2])
    uv_c, depth_c, rad_c = _project_pairs(ci, cj, xyz_true, M_true, C_true, cal_rows, sizes)
    inside = (
        (depth_c > 0)
        & (rad_c <= rmax)
        & (uv_c[:, 0] >= border)
        & (uv_c[:, 0] <= W - 1 - border)
        & (uv_c[:, 1] >= border)
        & (uv_c[:, 1] <= Hpx - 1 - border)
    )
    if observation_probability < 1.0:
        inside &= rng.random(inside.size) < observation_probability
    ci, cj, uv_ideal = ci[inside], cj[inside], uv_c[inside]
    rays = np.bincount(cj, minlength=pid.size)
    surveyed = role != "tie"
    weak = surveyed & (rays < 2)
    if np.any(weak):
        raise DegenerateGeometryError(
            f"{int(weak.sum())} control/check point(s) are seen by fewer than two images "
            f"(e.g. id {pid[weak][0]}): choose a layout inside the block (gcps=, checks=) or "
            "larger overlaps"
        )
    keep_pt = (rays >= min_rays) | surveyed
    if not np.any(keep_pt & ~surveyed):
        raise InputError(
            "no tie point is seen by min_rays images: raise tie_points_per_image or the overlaps"
        )
    keep_obs = keep_pt[cj]
    ci, cj, uv_ideal = ci[keep_obs], cj[keep_obs], uv_ideal[keep_obs]
    newp = np.cumsum(keep_pt) - 1
    pid, role, xyz_true = pid[keep_pt], role[keep_pt], xyz_true[keep_pt]
    cj = newp[cj]
    order = np.lexsort((pid[cj], ci))
    ci, cj, uv_ideal = ci[order], cj[order], uv_ideal[order]
    n = ci.size
    # --- observation errors --------------------------------------------------------------------
    rms_field = P.local_field_rms if local_field is None else float(local_field)
    if rms_field > 0 or local_field_smooth > 0:
        fld = LocalDistortionField.random(
            rng,
            image_ids,
            W,
            Hpx,
            rms=rms_field,
            modes=local_field_modes,
            correlation=local_field_correlation,
            static=local_field_static,
            slope=local_field_slope,
            smooth=float(local_field_smooth),
        )
    else:
        if rms_field < 0:
            raise InputError(f"local_field must be >= 0 (RMS, pixels), got {rms_field}")
        fld = LocalDistortionField.zero(image_ids, W, Hpx)
    local = fld.rows(ci, uv_ideal)
    obs_sigma = np.where(role[cj] == "tie", float(sigma), float(gcp_sigma))
    noise = rng.standard_normal((n, 2)) * obs_sigma[:, None]
    tie_rows = np.flatnonzero(role[cj] == "tie")
    nb = int(blunders)
    if nb > tie_rows.size:
        raise InputError(
            f"blunders: {nb} asked for, but the block has {tie_rows.size} tie observations"
        )
    brows = np.sort(rng.choice(tie_rows, nb, replace=False)) if nb else np.zeros(0, np.int64)
    bdir = rng.uniform(0.0, 2 * np.pi, nb)
    boff = float(blunder_size) * np.column_stack([np.cos(bdir), np.sin(bdir)])
    observed = uv_ideal + local + noise
    observed[brows] += boff
    # --- surveyed coordinates, GNSS / IMU, initial values ----------------------------------------
    ss = _triple(survey_sigma, "survey_sigma")
    if np.any(ss <= 0):
        raise InputError("survey_sigma must be > 0 (metres)")
    surveyed = role != "tie"
    xyz_obs = xyz_true.copy()
    xyz_obs[surveyed] += rng.standard_normal((int(surveyed.sum()), 3)) * ss
    point_sigma = np.where(surveyed[:, None], ss, np.nan)
    gs = _triple(gnss_sigma, "gnss_sigma")
    if gs is not None and np.any(gs <= 0):
        raise InputError("gnss_sigma must be > 0 (metres), or None for no GNSS")
    gnss = gnss_sig = imu = imu_sig = None
    if gs is not None:
        gnss = C_true + rng.standard_normal((m, 3)) * gs
        gnss_sig = np.tile(gs, (m, 1))
        C0 = gnss.copy()
    else:
        C0 = C_true + rng.standard_normal((m, 3)) * float(initial_position_error)
    if imu_sigma_deg is not None:
        if not imu_sigma_deg > 0:
            raise InputError("imu_sigma_deg must be > 0 (degrees), or None for no IMU")
        isg = np.radians(float(imu_sigma_deg))
        imu = ang_true + rng.standard_normal((m, 3)) * isg
        imu_sig = np.full((m, 3), isg)
        A0 = imu.copy()
    else:
        A0 = ang_true + rng.standard_normal((m, 3)) * np.radians(initial_attitude_error_deg)
    ext0 = np.column_stack([C0, A0])
    group = P.name
    free_names = DEFAULT_FREE if free is None else tuple(free)

    def build(ci, cj, pid, role, xyz_true, xyz_obs, point_sigma, uv_ideal, observed, obs_sigma):
        common = dict(
            image_ids=image_ids,
            image_camera=[group] * m,
            point_ids=pid,
            obs_image_ids=image_ids[ci],
            obs_point_ids=pid[cj],
            sigma=obs_sigma,
            role=role,
            point_sigma=point_sigma,
            gnss_sigma=gnss_sig,
            imu_sigma=imu_sig,
            free=free_names,
            image_variant=variant,
        )
        truth = Block.from_arrays(
            cameras={group: cam},
            exterior=ext_true,
            xyz=xyz_true,
            uv=uv_ideal,
            gnss=None if gnss is None else C_true,
            imu=None if imu is None else ang_true,
            calibration_offset=offsets,
            **common,
        )
        start = Block.from_arrays(
            cameras={group: cam0},
            exterior=ext0,
            xyz=xyz_obs,
            uv=observed,
            gnss=gnss,
            imu=imu,
            **common,
        )
        return truth, start

    arrays = [ci, cj, pid, role, xyz_true, xyz_obs, point_sigma, uv_ideal, observed, obs_sigma]
    truth, start = build(*arrays)
    tie_idx = np.flatnonzero(role == "tie")
    tri = triangulate(start, pid[tie_idx], iterations=50)
    tri_xyz = np.array(tri.xyz)
    fail = ~tri.ok
    drop = np.zeros(tie_idx.size, dtype=bool)
    n_plane = 0
    if np.any(fail):
        # Which tie points exist is a matter of the true geometry (a matcher's output lacks
        # those whose rays are nearly parallel), not of the start values: a point the true
        # cameras cannot intersect is dropped; one only the initial cameras cannot intersect
        # (rays crossing behind them when the start is degrees off) keeps its observations and
        # starts where its initial rays meet the mean terrain height.
        drop[fail] = ~triangulate(truth, pid[tie_idx[fail]], iterations=50).ok
        redo = fail & ~drop
        plane, hit = _terrain_height_starts(start, tie_idx[redo], float(terrain_height))
        tri_xyz[np.flatnonzero(redo)] = plane
        n_plane = int(np.sum(hit))
        drop[np.flatnonzero(redo)[~hit]] = True  # no initial ray reaches the ground
    n_dropped = int(np.sum(drop))
    if n_dropped:
        # dropped from both blocks; their number is ``options["dropped_tie_points"]``
        keep_pt = np.ones(pid.size, dtype=bool)
        keep_pt[tie_idx[drop]] = False
        keep_o = keep_pt[cj]
        newrow = np.cumsum(keep_o) - 1
        kb = keep_o[brows]
        brows, boff = newrow[brows[kb]], boff[kb]
        newp = np.cumsum(keep_pt) - 1
        ci, cj = ci[keep_o], newp[cj[keep_o]]
        uv_ideal, observed, obs_sigma = uv_ideal[keep_o], observed[keep_o], obs_sigma[keep_o]
        local, noise = local[keep_o], noise[keep_o]
        pid, role = pid[keep_pt], role[keep_pt]
        xyz_true, xyz_obs, point_sigma = xyz_true[keep_pt], xyz_obs[keep_pt], point_sigma[keep_pt]
        arrays = [ci, cj, pid, role, xyz_true, xyz_obs, point_sigma, uv_ideal, observed, obs_sigma]
        truth, start = build(*arrays)
        tri_xyz = tri_xyz[~drop]
    xyz0 = xyz_obs.copy()
    xyz0[role == "tie"] = tri_xyz
    start = start.replace(xyz=xyz0)
    options = dict(
        camera=P.name,
        gsd=g,
        flying_height=H,
        strips=len(counts),
        images_per_strip=counts,
        forward_overlap=fo,
        side_overlap=so,
        terrain=terrain_name,
        relief=rel if terrain == "hilly" else None,
        tie_points_per_image=tie_points_per_image,
        dropped_tie_points=n_dropped,
        terrain_height_starts=n_plane,
        sigma=float(sigma),
        gcp_sigma=float(gcp_sigma),
        gnss_sigma=None if gs is None else gs.tolist(),
        imu_sigma_deg=imu_sigma_deg,
        blunders=nb,
        blunder_size=float(blunder_size),
        local_field=rms_field,
        local_field_modes=local_field_modes,
        local_field_correlation=local_field_correlation,
        local_field_static=float(local_field_static),
        local_field_slope=float(local_field_slope),
        local_field_smooth=float(local_field_smooth),
        calibration_variation=None if cv is None else cv.tolist(),
        initial_camera=initial_camera if isinstance(initial_camera, str) else "given",
    )
    return SimulatedBlock(
        block=start,
        truth=truth,
        preset=P,
        camera=cam,
        gsd=g,
        flying_height=H,
        terrain=surf,
        field=fld,
        ideal=uv_ideal,
        local=local,
        noise=noise,
        blunder_rows=brows,
        blunder_offsets=boff,
        control_ids=pid[role == "control"],
        check_ids=pid[role == "check"],
        tie_ids=pid[role == "tie"],
        options=options,
    )


_CAL_NAMES = ("f", "cx", "cy", "k1", "k2", "k3", "k4", "p1", "p2", "b1", "b2")


@dataclass(frozen=True)
class _Flat:
    height: float

    def __call__(self, X, Y) -> np.ndarray:
        return np.full(np.broadcast(np.asarray(X), np.asarray(Y)).shape, self.height)
