"""Bundle adjustment with self-calibration: Levenberg-Marquardt on the reduced camera system.

Unknowns: per image its projection centre and attitude (a rotation increment on the left of
``M``, reported as omega, phi, kappa) and, for image-variant calibration, its offsets of f,
cx, cy; per camera group the free Metashape calibration parameters; per tie and control
point its object coordinates. Observations: image points (pixels, computed minus
observed), control point coordinates, GNSS projection centres and IMU angles, each whitened
by its standard deviation. The engine is :mod:`photogeom.adjust.schur`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from ..adjust.levenberg import levenberg_marquardt_loop
from ..adjust.schur import Linearization, SchurSystem, folded_locals, weak_point_blocks
from ..camera.frame_kernel import (
    opk_from_increment_jacobian,
    project_rows,
    rotation_increment,
)
from ..errors import DegenerateGeometryError, InputError
from ..units import wrap_angle
from ._angles import opk_from_rotations
from .block import CALIBRATION_NAMES, IMAGE_VARIANT_NAMES, Block
from .options import BundleOptions

NCAL = len(CALIBRATION_NAMES)


def memory_limit() -> float:
    """Bytes the arrays of an adjustment that grow with the square of its camera groups may
    take: half of the machine's physical memory (``inf`` where the system does not say).

    Returns
    -------
    float
        Bytes.
    """
    from ..machine import physical_memory

    total = physical_memory()
    return math.inf if total is None else 0.5 * total


def dense_global_bytes(n_groups: int, n_images: int, b: int) -> float:
    """Bytes of the arrays of an adjustment held densely over the calibration parameters
    of its global camera groups (11 per group, held ones included): the blocks of the
    reduced camera system that couple the images with those parameters (images x b x
    parameters) and the parameters with each other (parameters x parameters), their
    covariance blocks and the inverse of the reduced system (or, when it is solved for,
    its columns of those parameters).

    A camera group observed by one image only is held in that image's unknowns
    (:func:`photogeom.adjust.schur.folded_locals`; ``b`` then counts its parameters):
    it is not a global group and does not enter ``n_groups``. The coupling of the points
    and observations with the calibration is held per point and camera group observing it
    (linear in the observations), so the points and observations do not enter.

    Parameters
    ----------
    n_groups : int
        Global camera groups (``NCAL`` calibration parameters each).
    n_images : int
        Images (local blocks of the reduced system).
    b : int
        Unknowns per image (6, 9 with image-variant ones, ``NCAL`` more with the camera
        groups of single images held in them).

    Returns
    -------
    float
        Bytes: 0.5 GB for 250 images and 250 global camera groups, 36 GB for 2000 and
        2000 (camera groups shared by pairs of images, say; a camera group per image, as
        a BAL file gives, has none).
    """
    from ..adjust.sparse import DENSE_INVERSE_MAX

    g = n_groups * NCAL
    nc = n_images * b + g
    local_global = 3.0 * n_images * b * g  # LG, its accumulation, its covariance block
    global_global = 4.5 * g * g  # GG, its accumulation and masks, its covariance block
    inverse = nc * nc if nc <= DENSE_INVERSE_MAX else 2.0 * nc * g
    return 8.0 * (local_global + global_global + inverse)


def _check_dense_global_memory(n_groups: int, n_images: int, b: int):
    """Refuse, before any work, an adjustment whose global camera groups would need more
    memory than :func:`memory_limit` (the arrays grow with the square of those groups: 0.5
    GB for 250 images with 250 such groups, 36 GB for 2000)."""
    need = dense_global_bytes(n_groups, n_images, b)
    limit = memory_limit()
    if need <= limit:
        return
    raise InputError(
        f"the block's {n_groups} camera groups observed by more than one image hold "
        f"{n_groups * NCAL} calibration parameters, which the adjustment couples with each "
        f"other and with each of its {n_images} images: about {need / 1e9:.1f} GB of "
        f"memory, more than the {limit / 1e9:.1f} GB allowed (half of this machine's "
        "memory). The memory grows with the square of these camera groups, held "
        "calibration parameters included (a camera group of a single image is held with "
        "that image and costs nothing of it): give the images taken with one camera one "
        "camera group (in a CSV block the camera column of images.csv; a Bundler file: "
        "read it with group_cameras=True, --group-cameras on the command line), or adjust "
        "the block in parts"
    )


@dataclass
class _State:
    C: np.ndarray  # (m, 3) centred projection centres
    M: np.ndarray  # (m, 3, 3)
    offset: np.ndarray  # (m, 3) image-variant f, cx, cy offsets
    cal: np.ndarray  # (groups, 11)
    X: np.ndarray  # (p_adj, 3) centred points

    def copy(self) -> _State:
        return _State(
            self.C.copy(), self.M.copy(), self.offset.copy(), self.cal.copy(), self.X.copy()
        )


class Problem:
    """The block turned into unknowns, observations and the Schur structure."""

    def __init__(self, block: Block, options: BundleOptions) -> None:
        self.block = block
        self.options = options
        role = block.role
        adj_pt = role != "check"
        self.adj_points = np.flatnonzero(adj_pt)
        self.check_points = np.flatnonzero(~adj_pt)
        pt_map = np.full(block.n_points, -1, dtype=np.int64)
        pt_map[self.adj_points] = np.arange(self.adj_points.size)
        keep = adj_pt[block.obs_point]
        self.obs_rows = np.flatnonzero(keep)  # rows of block.observations in the adjustment
        self.obs_i = block.obs_image[keep]
        self.obs_j = pt_map[block.obs_point[keep]]
        self.uv = block.observations.uv[keep]
        self.sigma = block.observations.sigma[keep]
        self.size = block.image_sizes()[self.obs_i]
        m, ng = block.n_images, len(block.calibrations)
        self.m, self.ng, self.p = m, ng, self.adj_points.size
        if self.obs_rows.size == 0:
            raise InputError("the block has no image observations of tie or control points")
        self.origin = block.exterior[:, :3].mean(axis=0)  # coordinates reduced to this
        iv_any = any(len(v) for v in block.image_variant.values())
        self.b = 9 if iv_any else 6
        lf = np.ones((m, self.b), dtype=bool)
        if options.fix_exterior:
            lf[:, :6] = False
        if iv_any:
            for gi, gid in enumerate(block.camera_ids.tolist()):
                names = self.image_variant(gid)
                rows = block.image_camera == gi
                for c, nm in enumerate(IMAGE_VARIANT_NAMES):
                    lf[rows, 6 + c] = nm in names
        gf = np.zeros(ng * NCAL, dtype=bool)
        for gi, gid in enumerate(block.camera_ids.tolist()):
            free = options.free if options.free is not None else block.free[gid]
            iv = block.image_variant[gid]
            for c, nm in enumerate(CALIBRATION_NAMES):
                gf[gi * NCAL + c] = nm in free and nm not in iv
        # a camera group without images has no observation of its calibration: held at its
        # values (named in the notes) instead of a singular reduced camera system
        used = np.bincount(block.image_camera, minlength=ng) > 0
        #: ids of the camera groups with free parameters but no images (not adjusted)
        self.unused_groups = tuple(
            gid
            for gi, gid in enumerate(block.camera_ids.tolist())
            if not used[gi] and gf[gi * NCAL : (gi + 1) * NCAL].any()
        )
        gf.reshape(ng, NCAL)[~used] = False
        self.local_free, self.global_free = lf, gf
        self.local_global = block.image_camera[:, None] * NCAL + np.arange(NCAL)[None, :]
        self.free_datum: tuple[int, int, int] | None = None
        if options.datum == "free":
            self._free_datum()
        # camera groups of single images are held in their images' unknowns
        folded = folded_locals(self.local_global, ng * NCAL)
        b_sys = self.b + NCAL if np.any(folded) else self.b
        _check_dense_global_memory(ng - int(folded.sum()), m, b_sys)
        self.sys = SchurSystem(
            m,
            self.b,
            ng * NCAL,
            self.p,
            self.obs_i,
            self.obs_j,
            self.local_global,
            self.local_free,
            self.global_free,
            backend=options.backend,
        )
        self.has_gnss = np.all(np.isfinite(block.gnss), axis=1)
        self.has_imu = np.all(np.isfinite(block.imu), axis=1)
        ctrl = role[self.adj_points] == "control"
        self.control = np.flatnonzero(ctrl)
        self.control_xyz = block.surveyed_xyz[self.adj_points[ctrl]] - self.origin
        self.control_sigma = block.point_sigma[self.adj_points[ctrl]]
        self.obs_is_control = np.isin(self.obs_j, self.control)
        #: variance factors per observation group (variance-component estimation)
        self.group_factor = {
            "image_tie": 1.0,
            "image_control": 1.0,
            "control": 1.0,
            "gnss": 1.0,
            "imu": 1.0,
        }
        self._datum_check()
        self._link_check()

    def counts(self) -> tuple[int, int]:
        """Observations (image coordinates, GNSS and IMU triples, control coordinates) and
        free unknowns of the adjustment; their difference is its redundancy."""
        n_obs = (
            2 * self.obs_i.size
            + 3 * int(self.has_gnss.sum())
            + 3 * int(self.has_imu.sum())
            + 3 * int(self.control.size)
        )
        return n_obs, int(self.local_free.sum() + self.global_free.sum() + 3 * self.p)

    def check_redundancy(self) -> None:
        """Refuse more free unknowns than observations: no geometry determines them.

        Raises
        ------
        DegenerateGeometryError
            Naming both counts and the remedy.
        """
        n_obs, n_unk = self.counts()
        if n_unk > n_obs:
            raise DegenerateGeometryError(
                f"the observations do not determine all free parameters: {n_obs} "
                f"observations for {n_unk} unknowns (redundancy {n_obs - n_unk}): fix "
                "calibration parameters the geometry cannot separate (e.g. "
                "free=('f', 'cx', 'cy', 'k1', 'k2', 'k3', 'p1', 'p2') without b1/b2/k4, or "
                "fewer), or add images, tie points or control"
            )

    # --- datum -------------------------------------------------------------------------------

    def _free_datum(self) -> None:
        """Minimal constraints of a free network: the first image's orientation and one
        coordinate of the farthest projection centre are held (the reported covariances
        are transformed to inner constraints on the centres afterwards)."""
        C = self.block.exterior[:, :3]
        if self.m < 2:
            raise DegenerateGeometryError("a free network needs at least two images")
        d = C - C[0]
        far = int(np.argmax(np.linalg.norm(d, axis=1)))
        if np.linalg.norm(d[far]) == 0:
            raise DegenerateGeometryError("a free network needs two distinct projection centres")
        axis = int(np.argmax(np.abs(d[far])))
        self.local_free[0, :6] = False
        self.local_free[far, axis] = False
        self.free_datum = (0, far, axis)

    def image_variant(self, group) -> tuple[str, ...]:
        """The parameters of camera ``group`` estimated per image: the block's image-variant
        ones, and with ``free=`` given only those it names (``free=()`` holds the whole
        calibration, the images' offsets too)."""
        names = self.block.image_variant[group]
        if self.options.free is None:
            return tuple(names)
        return tuple(n for n in names if n in self.options.free)

    def _image_components(self) -> np.ndarray:
        """(m + p,) label of the connected part of each image and adjusted point (images
        linked by common points)."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        m, n = self.m, self.m + self.p
        g = coo_matrix(
            (np.ones(self.obs_i.size), (self.obs_i, m + self.obs_j)), shape=(n, n)
        )
        return connected_components(g, directed=False)[1]

    def _datum_check(self) -> None:
        if self.options.datum == "free":
            self._free_datum_check()
            return
        if self.options.fix_exterior:
            return
        label = self._image_components()
        parts = np.unique(label[: self.m])
        ctrl_part = label[self.m + self.control]
        for part in parts:
            imgs = label[: self.m] == part
            gnss = self.has_gnss & imgs
            P = np.concatenate(
                [self.control_xyz[ctrl_part == part], self.block.gnss[gnss] - self.origin]
            )
            S = np.concatenate(
                [self.control_sigma[ctrl_part == part], self.block.gnss_sigma[gnss]]
            )
            missing = _datum_missing(P, bool(np.any(self.has_imu & imgs)), S)
            if not missing:
                continue
            what = ", ".join(missing)
            if parts.size == 1:
                raise DegenerateGeometryError(
                    f"datum defect: the control points and GNSS positions do not fix {what}. "
                    "Add control points (at least three, not on a line) or GNSS camera "
                    "positions, or pass datum='free' for a free network"
                )
            ids = self.block.image_ids[imgs]
            more = f" and {ids.size - 5} more" if ids.size > 5 else ""
            raise DegenerateGeometryError(
                f"datum defect: the block falls into {parts.size} parts that share no points, "
                f"and in the part of images {', '.join(map(str, ids[:5].tolist()))}{more} the "
                f"control points and GNSS positions do not fix {what}. Link the parts by "
                "common tie points, add control points or GNSS positions in that part, or "
                "adjust it as a block of its own"
            )

    def _held_parts(self) -> tuple[np.ndarray, np.ndarray]:
        """Parts of the block that can move against the rest: (m,) label of each image's
        part and the (k,) number of points each part shares with the others.

        Images sharing at least :data:`MIN_LINK_POINTS` points are one part; parts sharing
        at least as many points (in all, over their images) are merged, until no two parts
        do. A part that shares fewer with all others together can turn about them (two: the
        line through them; one: three rotations and the scale about it; none: the
        similarity transformation) without changing any image observation: unless its own
        control points, GNSS positions, IMU attitudes or held unknowns fix it, the normal
        equations are singular, whatever the geometry within it. The converse does not hold
        (three linking points on one ray leave a hinge too): this finds the hinges the
        tie-point graph alone proves.
        """
        from scipy.sparse.csgraph import connected_components

        m, p = self.m, self.p
        seen = sp.csr_matrix(
            (np.ones(self.obs_i.size), (self.obs_j, self.obs_i)), shape=(p, m)
        )  # (points, images): 1 where observed (pairs are unique: Block.validate)
        label = np.arange(m)
        while True:
            k = int(label.max()) + 1
            part = sp.csr_matrix((np.ones(m), (np.arange(m), label)), shape=(m, k))
            by_part = (seen @ part).tocsr()
            by_part.data[:] = 1.0  # (points, parts): whether the part sees the point
            shared = (by_part.T @ by_part).tocoo()
            link = (shared.row != shared.col) & (shared.data >= MIN_LINK_POINTS)
            if not np.any(link):
                break
            graph = sp.coo_matrix(
                (np.ones(int(link.sum())), (shared.row[link], shared.col[link])), shape=(k, k)
            )
            label = connected_components(graph, directed=False)[1][label]
        many = np.diff(by_part.indptr) > 1  # points seen by two parts or more
        linking = np.bincount(by_part[many].indices, minlength=k)
        return label, linking

    def _link_check(self) -> None:
        """Refuse a part of the block linked to the rest by fewer than
        :data:`MIN_LINK_POINTS` points and fixed by nothing of its own
        (:meth:`_held_parts`), before the iterations.

        Raises
        ------
        DegenerateGeometryError
            Naming the part's images, the linking points and what to do.
        """
        if self.options.fix_exterior or self.m < 2:
            return
        label, linking = self._held_parts()
        k = linking.size
        if k < 2:
            return
        fixed = np.zeros(k, dtype=bool)  # parts with datum observations or held unknowns
        fixed[label[self.has_gnss | self.has_imu]] = True
        fixed[label[~self.local_free[:, :6].all(axis=1)]] = True
        fixed[label[self.obs_i[self.obs_is_control]]] = True
        hinged = np.flatnonzero(~fixed & (linking < MIN_LINK_POINTS))
        if hinged.size == 0:
            return
        sizes = np.bincount(label, minlength=k)[hinged]
        worst = int(hinged[np.argsort(sizes, kind="stable")[0]])  # the smallest part
        imgs = np.flatnonzero(label == worst)
        ids = self.block.image_ids[imgs]
        more = f" and {ids.size - 5} more" if ids.size > 5 else ""
        in_part = np.zeros(self.p, dtype=bool)
        in_part[self.obs_j[label[self.obs_i] == worst]] = True
        out_part = np.zeros(self.p, dtype=bool)
        out_part[self.obs_j[label[self.obs_i] != worst]] = True
        links = self.block.point_ids[self.adj_points[np.flatnonzero(in_part & out_part)]]
        n = links.size
        free = (
            "the rotation about the line through them is"
            if n == 2
            else "its three rotations and its scale about it are"
        )
        others = (
            f" ({hinged.size - 1} more part(s) of the block are linked as weakly)"
            if hinged.size > 1
            else ""
        )
        raise DegenerateGeometryError(
            "the observations do not determine all free parameters: the part of the block "
            f"of image(s) {'; '.join(map(str, ids[:5].tolist()))}{more} is linked to the "
            f"rest by fewer than three tie points ({n}: point(s) "
            f"{', '.join(map(str, links.tolist()))}) and has no control points, GNSS "
            f"positions or IMU attitudes of its own, so {free} free (the normal "
            f"equations are singular){others}. Link the part by at least three tie points "
            "seen in both, give it control points or GNSS positions, or adjust it as a "
            "block of its own"
        )

    def _free_datum_check(self) -> None:
        """A free network holds the first image's orientation and one centre coordinate at
        their start: control points, GNSS positions or IMU attitudes would pull against
        them and distort the block (sigma0 2.7 instead of 1.0 on a simulated block)."""
        held = []
        if self.control.size:
            held.append(f"{self.control.size} control point(s)")
        if np.any(self.has_gnss):
            held.append(f"GNSS positions of {int(self.has_gnss.sum())} image(s)")
        if np.any(self.has_imu):
            held.append(f"IMU attitudes of {int(self.has_imu.sum())} image(s)")
        label = self._image_components()[: self.m]
        parts = np.unique(label).size
        if parts > 1 and not held:
            # the parts by their images, largest first (at most three parts, five ids each)
            ids, counts = np.unique(label, return_counts=True)
            listed = []
            for k in ids[np.argsort(-counts, kind="stable")][:3]:
                imgs = self.block.image_ids[label == k]
                more = f" and {imgs.size - 5} more" if imgs.size > 5 else ""
                listed.append(f"images {', '.join(map(str, imgs[:5].tolist()))}{more}")
            rest = f"; {parts - 3} more part(s)" if parts > 3 else ""
            raise DegenerateGeometryError(
                f"a free network must be connected, but the block falls into {parts} parts "
                f"that share no points ({'; '.join(listed)}{rest}): link them by common tie "
                "points or adjust each part as a block of its own"
            )
        if held:
            raise InputError(
                "datum='free' (a free network) holds the first image's orientation at its "
                "start, but the block has " + ", ".join(held) + ", which fix the datum "
                "themselves and would pull against it: use datum='weighted' (or 'auto'), or "
                "for a free network remove them first (control points as check points, "
                "GNSS and IMU set to NaN: Block.without_datum_observations())"
            )

    # --- state -------------------------------------------------------------------------------

    def initial_state(self) -> _State:
        b = self.block
        cal = np.array([[getattr(c, n) for n in CALIBRATION_NAMES] for c in b.calibrations])
        return _State(
            b.exterior[:, :3] - self.origin,
            b.rotations(),
            b.calibration_offset.copy(),
            cal,
            b.xyz[self.adj_points] - self.origin,
        )

    def update(self, s: _State, dc: np.ndarray, dp: np.ndarray) -> _State:
        m, b = self.m, self.b
        dl = dc[: m * b].reshape(m, b)
        dg = dc[m * b :].reshape(self.ng, NCAL)
        n = s.copy()
        n.C += dl[:, :3]
        n.M = rotation_increment(dl[:, 3:6]) @ s.M
        if b > 6:
            n.offset += dl[:, 6:9]
        n.cal += dg
        n.X += dp
        return n

    # --- residuals and Jacobians -----------------------------------------------------------

    def _rows(self, s: _State):
        i, j = self.obs_i, self.obs_j
        cal = s.cal[self.block.image_camera][i]
        cal[:, :3] += s.offset[i]
        return s.X[j], s.M[i], s.C[i], cal

    def jacobian_columns(self, off_points: int) -> np.ndarray:
        """(n, b + NCAL + 3) column of each observation's orientation, calibration and
        point derivatives (the blocks ``A``, ``G``, ``P`` of :meth:`linearize`) in a
        Jacobian with the unknowns ordered: orientations (``m b``), calibrations (``groups
        NCAL``), any others, then the points from column ``off_points``."""
        i = self.obs_i
        return np.concatenate(
            [
                i[:, None] * self.b + np.arange(self.b),
                self.m * self.b + self.local_global[i],
                off_points + 3 * self.obs_j[:, None] + np.arange(3),
            ],
            axis=1,
        )

    def residuals(self, s: _State) -> tuple[np.ndarray, np.ndarray]:
        """Image residuals (n, 2) px (computed - observed) and depths (positive in front)."""
        X, M, C, cal = self._rows(s)
        pr = project_rows(X, M, C, cal, self.size, jacobian=False)
        return pr.uv - self.uv, pr.depth

    def robust_weights(self, e2: np.ndarray) -> np.ndarray:
        """IRLS weights of the image observations from squared whitened norms."""
        loss, c = self.options.loss, self.options.scale
        if loss == "squared":
            return np.ones_like(e2)
        if loss == "huber":
            e = np.sqrt(e2)
            return np.where(e <= c, 1.0, c / np.maximum(e, 1e-300))
        return 1.0 / (1.0 + e2 / (c * c))

    def radial_curvature(self, e2: np.ndarray) -> np.ndarray:
        """Per image observation, the curvature of its robust cost along its residual
        relative to its IRLS weight, ``1 + 2 s rho''(s) / rho'(s)`` at ``s = |e|^2``, at
        least :data:`RADIAL_CURVATURE_FLOOR`.

        The cost ``rho(|e|^2)`` of a whitened residual ``e`` has the Hessian ``2 (w (I -
        u u') + (w + 2 rho'' s) u u')`` (``w = rho'``, ``u = e / |e|``): across the
        residual the IRLS weight, along it less. Huber's is 1 within the scale and 0
        beyond (its cost grows linearly with ``|e|`` there), Cauchy's ``(c^2 - s) / (c^2 +
        s)``, negative beyond the scale; the squared loss's 1.

        Parameters
        ----------
        e2 : numpy.ndarray (n,)
            Squared whitened norms ``s``.

        Returns
        -------
        numpy.ndarray (n,)
            In ``[RADIAL_CURVATURE_FLOOR, 1]``.
        """
        loss, c = self.options.loss, self.options.scale
        if loss == "squared":
            return np.ones_like(e2)
        if loss == "huber":
            d = np.where(e2 <= c * c, 1.0, 0.0)
        else:
            d = (c * c - e2) / (c * c + e2)
        return np.maximum(d, RADIAL_CURVATURE_FLOOR)

    def robust_rows(self, e2: np.ndarray) -> np.ndarray:
        """Robust cost of each image observation from its squared whitened norm."""
        loss, c = self.options.loss, self.options.scale
        if loss == "squared":
            return e2
        if loss == "huber":
            e = np.sqrt(e2)
            return np.where(e <= c, e2, 2 * c * e - c * c)
        return c * c * np.log1p(e2 / (c * c))

    def robust_cost(self, e2: np.ndarray) -> float:
        return float(self.robust_rows(e2).sum())

    def sigma_obs(self) -> np.ndarray:
        """Standard deviation of each image observation in use (with variance factors)."""
        gf = self.group_factor
        f = np.where(self.obs_is_control, gf["image_control"], gf["image_tie"])
        return self.sigma * np.sqrt(f)

    def prior_terms(self, s: _State):
        """Normal-equation terms of the GNSS, IMU and control-point observations and their
        whitened residuals ``{group: (k, 3)}``."""
        m, b = self.m, self.b
        gf = self.group_factor
        li = np.zeros((m, b, b))
        lg = np.zeros((m, b))
        cost = 0.0
        parts: dict[str, np.ndarray] = {}
        if np.any(self.has_gnss):
            k = self.has_gnss
            sg = self.block.gnss_sigma[k] * math.sqrt(gf["gnss"])
            r = (s.C[k] - (self.block.gnss[k] - self.origin)) / sg
            w = 1.0 / sg
            idx = np.flatnonzero(k)
            for a in range(3):
                li[idx, a, a] += w[:, a] ** 2
            lg[idx, :3] += r * w
            cost += float((r * r).sum())
            parts["gnss"] = r
        if np.any(self.has_imu):
            k = self.has_imu
            sg = self.block.imu_sigma[k] * math.sqrt(gf["imu"])
            ang = opk_from_rotations(s.M[k])
            r = wrap_angle(ang - self.block.imu[k]) / sg
            J = opk_from_increment_jacobian(ang) / sg[:, :, None]
            idx = np.flatnonzero(k)
            li[idx, 3:6, 3:6] += np.einsum("kai,kaj->kij", J, J)
            lg[idx, 3:6] += np.einsum("kai,ka->ki", J, r)
            cost += float((r * r).sum())
            parts["imu"] = r
        pi = np.zeros((self.p, 3, 3))
        pg = np.zeros((self.p, 3))
        if self.control.size:
            sg = self.control_sigma * math.sqrt(gf["control"])
            r = (s.X[self.control] - self.control_xyz) / sg
            w = 1.0 / sg
            for a in range(3):
                pi[self.control, a, a] += w[:, a] ** 2
            pg[self.control] += r * w
            cost += float((r * r).sum())
            parts["control"] = r
        return li, lg, pi, pg, cost, parts

    def _jacobian_blocks(self, pr, sw: np.ndarray):
        """Whitened derivatives of projected rows: ``A`` (n, 2, b) by the image's local
        unknowns (centre, rotation increment, image-variant f, cx, cy), ``G`` (n, 2, NCAL)
        by its group's calibration, ``P`` (n, 2, 3) by the point."""
        blocks = [pr.d_center, pr.d_rotation]
        if self.b > 6:
            blocks.append(pr.d_calibration[:, :, :3])
        w = sw[:, None, None]
        A = np.concatenate(blocks, axis=2)
        A *= w
        # the projection's own arrays are whitened in place: no copies of the size of all rows
        G = pr.d_calibration
        G *= w
        P = pr.d_point
        P *= w
        return A, G, P

    def jacobians_at(self, s: _State, rows: np.ndarray, xyz: np.ndarray):
        """:meth:`_jacobian_blocks` of observation ``rows`` of the block (e.g. of check
        points, which are not in the adjustment) with the points at ``xyz`` (k, 3, object
        coordinates, one per row) and the cameras of state ``s``; whitened with the
        observations' sigmas and :meth:`check_factor`."""
        b = self.block
        i = b.obs_image[rows]
        cal = s.cal[b.image_camera][i]
        cal[:, :3] += s.offset[i]
        size = b.image_sizes()[i]
        pr = project_rows(xyz - self.origin, s.M[i], s.C[i], cal, size, jacobian=True)
        sw = 1.0 / (b.observations.sigma[rows] * math.sqrt(self.check_factor()))
        return self._jacobian_blocks(pr, sw)

    def check_factor(self) -> float:
        """Variance factor of the image observations of check points: that of the control
        points' (``image_control``; check points are surveyed points measured in the
        images like them), or of the tie points' when no control point is observed."""
        group = "image_control" if np.any(self.obs_is_control) else "image_tie"
        return self.group_factor[group]

    def linearize(
        self, s: _State, weights: np.ndarray, radial: np.ndarray | None = None
    ) -> Linearization:
        """Whitened residuals and Jacobian blocks at ``s``, each image point weighted by
        ``weights`` (n,), the IRLS weights ``w``.

        With ``radial`` (n,), each image point's curvature along its residual relative to
        ``w`` (:meth:`radial_curvature`), the normal equations are those of Newton's method
        for the robust cost: its block ``J'(w (I - u u') + w radial u u')J`` (``u`` the
        unit residual direction), its gradient ``J' w e`` unchanged. The rows are scaled
        by ``sqrt(w) (I - (1 - sqrt(radial)) u u')`` and the residual by ``sqrt(w) /
        sqrt(radial)``, so that ``r'r`` minus the model's minimum is the decrease that
        model predicts of the robust cost.
        """
        X, M, C, cal = self._rows(s)
        pr = project_rows(X, M, C, cal, self.size, jacobian=True)
        sw = np.sqrt(weights) / self.sigma_obs()
        r = (pr.uv - self.uv) * sw[:, None]
        A, G, P = self._jacobian_blocks(pr, sw)
        if radial is not None:
            e = (pr.uv - self.uv) / self.sigma_obs()[:, None]
            norm = np.sqrt(np.einsum("nd,nd->n", e, e))
            u = e / np.where(norm > 0, norm, 1.0)[:, None]
            sr = np.sqrt(radial)
            k = (1.0 - sr)[:, None] * u  # rows J -= k (u'J), in place (no copy of J)
            for J in (A, G, P):
                uJ = np.einsum("nd,ndc->nc", u, J)
                for d in range(2):
                    J[:, d, :] -= k[:, d, None] * uJ
            r = r / sr[:, None]
        li, lg, pi, pg, pcost, _ = self.prior_terms(s)
        ng = self.ng * NCAL
        return Linearization(
            r,
            A,
            G,
            P,
            li,
            lg,
            pi,
            pg,
            sp.csr_matrix((ng, ng)),  # no prior on the calibrations
            np.zeros(ng),
            float(np.einsum("nd,nd->", r, r)) + pcost,
        )

    def cost(self, s: _State) -> tuple[float, np.ndarray, np.ndarray]:
        """Robust cost, squared whitened norms of the image residuals, depths."""
        v, depth = self.residuals(s)
        e2 = np.einsum("nd,nd->n", v, v) / self.sigma_obs() ** 2
        pcost = self.prior_terms(s)[4]
        return self.robust_cost(e2) + pcost, e2, depth

    def _point_costs(self, e2: np.ndarray, depth: np.ndarray):
        """Robust cost (p,) and whether any observation is behind its camera (p,) per
        adjusted point, from the squared whitened norms and depths of the image rows."""
        cost = np.bincount(self.obs_j, weights=self.robust_rows(e2), minlength=self.p)
        behind = np.bincount(self.obs_j, weights=~(depth > 0), minlength=self.p) > 0
        return cost, behind

    def _project_points(self, s: _State, X: np.ndarray, rows: np.ndarray, jacobian: bool):
        """Projections of image rows ``rows`` with the cameras of ``s`` and the points at
        ``X`` (one row per row of ``rows``, centred object coordinates, m)."""
        i = self.obs_i[rows]
        cal = s.cal[self.block.image_camera][i]
        cal[:, :3] += s.offset[i]
        return project_rows(X, s.M[i], s.C[i], cal, self.size[rows], jacobian=jacobian)

    def guard_point_steps(
        self,
        state: _State,
        trial: _State,
        e2: np.ndarray,
        depth: np.ndarray,
        uv: np.ndarray | None = None,
    ) -> tuple[_State, np.ndarray, np.ndarray, bool]:
        """Each tie point of ``trial`` at the better of its trial position and its position
        in ``state``, and moved from the latter by point-only Levenberg-Marquardt steps, all
        with the trial's cameras.

        The step of the reduced system moves each point by its linearisation given the
        cameras' step. A point seen in two images whose rays are nearly parallel in the
        start cameras (short base at the image edge, start 300 m off on the 250-image
        ILCE-7RM2 block with 3000 tie points per image) is so nonlinear in its depth that
        this move can raise its own cost a million times while the block's falls; left
        there, the next trials put it behind a camera, are rejected, the damping grows and
        the block crawls (not converged after 100 iterations). A point whose trial position
        is worse (or behind a camera) is held at its former position, unless the trial's
        cameras leave it undetermined there, and moved by point-only steps (a 3 x 3 system
        per point, the cameras fixed), which lower the cost of the trial, never raise it.

        Parameters
        ----------
        state, trial : _State
            The current state and the trial of one step from it.
        e2, depth : numpy.ndarray, shape (n,)
            Squared whitened norms and depths of the trial's image rows.
        uv : numpy.ndarray, shape (n, 2), optional
            The image coordinates (px) the projections are compared with, one per image
            row; default the observations. The adjustment with residual grids gives the
            observations corrected by the grids' trial values (held during these steps).

        Returns
        -------
        tuple
            ``(trial, e2, depth, changed)``, the trial's points and rows updated in place;
            ``changed`` says whether any point was.
        """
        uv = self.uv if uv is None else uv
        tie = np.ones(self.p, dtype=bool)
        tie[self.control] = False
        new_cost, new_behind = self._point_costs(e2, depth)
        X_old = state.X
        pr = self._project_points(trial, X_old[self.obs_j], np.arange(self.obs_j.size), False)
        e2_old = np.einsum("nd,nd->n", pr.uv - uv, pr.uv - uv) / self.sigma_obs() ** 2
        old_cost, old_behind = self._point_costs(e2_old, pr.depth)
        worse = new_behind | ~(new_cost <= old_cost)  # NaN (a point at a camera) is worse
        back = tie & ~old_behind & np.isfinite(old_cost) & worse
        if np.any(back):  # not where the trial's cameras leave it undetermined by its rays
            pts = np.flatnonzero(back)
            back[pts[self._weak_points(trial, pts, X_old[pts], e2_old)]] = False
        if not np.any(back):
            return trial, e2, depth, False
        trial.X[back] = X_old[back]
        guarded = back[self.obs_j]
        rows = np.flatnonzero(guarded)
        e2[rows], depth[rows] = e2_old[rows], pr.depth[rows]
        # the points stepped stay within twice the depth of the others: where rays meet
        # behind the cameras (a start far off), the cost falls towards infinity
        others = depth[~guarded]
        cap = 2.0 * float(others.max()) if others.size else np.inf
        self._point_steps(trial, np.flatnonzero(back), e2, depth, cap, uv)
        return trial, e2, depth, True

    def _weak_points(
        self, s: _State, pts: np.ndarray, X: np.ndarray, e2: np.ndarray
    ) -> np.ndarray:
        """Which of the adjusted points ``pts`` at ``X`` (k, 3, centred, m) the cameras of
        ``s`` leave undetermined (:func:`~photogeom.adjust.schur.weak_point_blocks` of
        their normal equations, with the robust weights of ``e2``, one per image row)."""
        k = pts.size
        local = np.full(self.p, -1, dtype=np.int64)
        local[pts] = np.arange(k)
        rows = np.flatnonzero(local[self.obs_j] >= 0)
        jr = local[self.obs_j[rows]]
        pr = self._project_points(s, X[jr], rows, True)
        sw = np.sqrt(self.robust_weights(e2[rows])) / self.sigma_obs()[rows]
        P = pr.d_point * sw[:, None, None]
        return weak_point_blocks(_point_normals(jr, P, k))

    def _point_steps(
        self,
        s: _State,
        pts: np.ndarray,
        e2: np.ndarray,
        depth: np.ndarray,
        cap: float,
        uv: np.ndarray | None = None,
    ) -> None:
        """Point-only Levenberg-Marquardt steps (at most :data:`POINT_STEPS`) of the adjusted
        points ``pts`` with the cameras of ``s`` held, each point damped and accepted on its
        own (lower robust cost, in front of its cameras at depths up to ``cap`` (m), and
        still determined by its rays: rays that meet behind the cameras lower a point's cost
        towards infinity); ``s.X``, ``e2`` and ``depth`` of their rows are updated in
        place. ``uv`` (n, 2) px: the coordinates the projections are compared with, one per
        image row (default the observations)."""
        k = pts.size
        local = np.full(self.p, -1, dtype=np.int64)
        local[pts] = np.arange(k)
        rows = np.flatnonzero(local[self.obs_j] >= 0)
        jr = local[self.obs_j[rows]]
        sig = self.sigma_obs()[rows]
        uv = (self.uv if uv is None else uv)[rows]
        cur = np.bincount(jr, weights=self.robust_rows(e2[rows]), minlength=k)
        mu = np.full(k, 1e-3)
        active = np.ones(k, dtype=bool)
        for _ in range(POINT_STEPS):
            w = self.robust_weights(e2[rows])
            pr = self._project_points(s, s.X[pts][jr], rows, True)
            sw = np.sqrt(w) / sig
            r = (pr.uv - uv) * sw[:, None]
            P = pr.d_point * sw[:, None, None]
            N = _point_normals(jr, P, k)
            g = _sum_by(jr, np.einsum("nai,na->ni", P, r), k)
            d = np.einsum("kii->ki", N)
            N[:, [0, 1, 2], [0, 1, 2]] += mu[:, None] * np.maximum(d, 1e-12 * d.max(initial=1))
            try:
                dx = -np.linalg.solve(N, g[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:  # pragma: no cover - damped 3 x 3 systems
                break
            Xt = s.X[pts] + dx
            pt = self._project_points(s, Xt[jr], rows, True)
            e2t = np.einsum("nd,nd->n", pt.uv - uv, pt.uv - uv) / sig**2
            ct = np.bincount(jr, weights=self.robust_rows(e2t), minlength=k)
            behind = np.bincount(jr, weights=~((pt.depth > 0) & (pt.depth <= cap)), minlength=k) > 0
            Pt = pt.d_point * sw[:, None, None]
            # not towards where the rays meet at infinity: the point stays determined
            weak = weak_point_blocks(_point_normals(jr, Pt, k))
            ok = active & ~behind & ~weak & (ct < cur)
            gain = np.where(ok, cur - ct, 0.0)
            X = s.X[pts]
            X[ok] = Xt[ok]
            s.X[pts] = X
            okr = ok[jr]
            e2[rows[okr]], depth[rows[okr]] = e2t[okr], pt.depth[okr]
            active &= ~(ok & (gain <= 1e-10 * cur))  # converged points
            cur = np.where(ok, ct, cur)
            mu = np.where(ok, mu / 10.0, mu * 10.0)
            active &= mu < 1e10
            if not np.any(active):
                break

    # --- back to a block ---------------------------------------------------------------------

    def to_block(self, s: _State, check_xyz: np.ndarray | None = None) -> Block:
        b = self.block
        ext = np.column_stack([s.C + self.origin, opk_from_rotations(s.M)])
        xyz = b.xyz.copy()
        xyz[self.adj_points] = s.X + self.origin
        if check_xyz is not None:
            xyz[self.check_points] = check_xyz
        cals = tuple(
            replace(c, **{n: float(s.cal[g, k]) for k, n in enumerate(CALIBRATION_NAMES)})
            for g, c in enumerate(b.calibrations)
        )
        # the parameters this adjustment estimated, so that adjusting the result again
        # (or its files) solves the same problem
        free, iv = b.free, b.image_variant
        if self.options.free is not None:
            free = {g: tuple(self.options.free) for g in b.camera_ids.tolist()}
            iv = {g: self.image_variant(g) for g in b.camera_ids.tolist()}
        return b.replace(
            exterior=ext,
            xyz=xyz,
            calibrations=cals,
            calibration_offset=s.offset.copy(),
            surveyed=b.survey,
            free=free,
            image_variant=iv,
            joint_adjustment=None,  # this adjustment is the first of the block's chain
        )


def _point_normals(index: np.ndarray, P: np.ndarray, k: int) -> np.ndarray:
    """(k, 3, 3) normal blocks ``sum P'P`` of points from the whitened point derivatives
    ``P`` (n, 2, 3) of image rows, by the rows' point ``index`` (n,) in ``range(k)``."""
    return _sum_by(index, np.einsum("nai,naj->nij", P, P).reshape(-1, 9), k).reshape(k, 3, 3)


def _sum_by(index: np.ndarray, values: np.ndarray, k: int) -> np.ndarray:
    """(k, c) sums of the rows of ``values`` (n, c) by ``index`` (n,) in ``range(k)``."""
    return np.stack(
        [np.bincount(index, weights=values[:, c], minlength=k) for c in range(values.shape[1])],
        axis=1,
    )


#: Least curvature of an image observation's robust cost along its residual, relative to
#: its IRLS weight, in the Newton steps of a robust adjustment
#: (:meth:`Problem.radial_curvature`): Huber's is 0 beyond the scale and Cauchy's negative,
#: which would let a step move along such residuals without bound.
RADIAL_CURVATURE_FLOOR = 3e-3

#: A robust adjustment takes IRLS steps (the Gauss-Newton steps of the weighted least
#: squares, which never over-estimate the cost's curvature) until an accepted step lowers
#: the cost by less than this fraction of it, then Newton steps with the loss's curvature
#: (:meth:`Problem.radial_curvature`).
NEWTON_SWITCH = 1e-2

#: Geodesic acceleration of a rejected step (:meth:`_BundleSteps.accelerate`): the finite
#: difference of the residuals' second derivative along the step is taken this fraction of
#: the step away.
ACCELERATION_STEP = 0.1

#: ... and the acceleration ``a`` is used when ``|a| <= ACCELERATION_RATIO |v| / 2`` (``v``
#: the step; Transtrum and Sethna's 0.75).
ACCELERATION_RATIO = 0.75

#: Point-only Levenberg-Marquardt steps at most of a tie point whose step in the reduced
#: system raised its cost (:meth:`Problem.guard_point_steps`).
POINT_STEPS = 20


#: Points a part of a block shares with the rest at least, for the tie points alone to
#: leave it no motion against the rest (:meth:`Problem._held_parts`): a part linked by two
#: can turn about the line through them, by one about it and scale.
MIN_LINK_POINTS = 3


#: Positions whose distances from their best-fitting line are, as an RMS of the distances
#: in units of their standard deviations, at most this, lie on one line as far as their
#: accuracy can tell: the rotation about that line is then fixed by their noise alone.
LINE_WITHIN_SIGMAS = 3.0


def _datum_missing(P: np.ndarray, imu: bool, sigma: np.ndarray | None = None) -> list[str]:
    """The datum elements that positions ``P`` (k, 3: control points, GNSS centres) and,
    with ``imu``, attitudes leave undetermined (empty: all seven fixed).

    Parameters
    ----------
    P : numpy.ndarray, shape (k, 3)
        Control-point and GNSS positions, object units (m).
    imu : bool
        Whether IMU attitudes are observed (they fix the three rotations).
    sigma : numpy.ndarray, shape (k, 3), optional
        Standard deviations of ``P``, object units (m). Positions on one line within
        :data:`LINE_WITHIN_SIGMAS` of them (RMS of the whitened distances from the line)
        leave the rotation about the line undetermined, as exactly collinear ones do;
        positions at one point within as much (RMS of the whitened distances from their
        centroid) the scale and, without ``imu``, the rotations, as a single one does.

    Returns
    -------
    list of str
        The undetermined elements, in words.
    """
    if P.shape[0] == 0:
        return ["3 shifts", "3 rotations", "the scale"]
    if P.shape[0] == 1:
        return ["the scale"] + ([] if imu else ["3 rotations"])
    c = P - P.mean(axis=0)
    _, s, vt = np.linalg.svd(c, full_matrices=False)
    if s[0] <= 1e-9 * max(1.0, float(np.abs(P).max())):
        return ["the scale"] + ([] if imu else ["3 rotations"])
    if sigma is not None:
        rms = float(np.sqrt(np.mean(np.sum((c / sigma) ** 2, axis=1))))
        if rms <= LINE_WITHIN_SIGMAS:  # one point within their accuracy: no scale, no roll
            dist = float(np.sqrt(np.mean(np.sum(c**2, axis=1))))
            sd = float(np.sqrt(np.mean(sigma**2)))
            return [
                "the scale"
                + ("" if imu else " and the 3 rotations")
                + f": they lie at one point within their accuracy (RMS distance from their "
                f"centroid {dist:.3g}, {rms:.2g} times their standard deviations of {sd:.3g} "
                f"RMS; at most {LINE_WITHIN_SIGMAS:g} times leaves the scale to their noise)"
            ]
    if imu:
        return []
    roll = "the rotation about the line through the control/GNSS positions"
    if s[1] <= 1e-6 * s[0]:
        return [roll]
    if sigma is not None:
        off = c - np.outer(c @ vt[0], vt[0])  # (k, 3) distances from the line, m
        rms = float(np.sqrt(np.mean(np.sum((off / sigma) ** 2, axis=1))))
        if rms <= LINE_WITHIN_SIGMAS:
            dist = float(np.sqrt(np.mean(np.sum(off**2, axis=1))))
            sd = float(np.sqrt(np.mean(sigma**2)))
            return [
                f"{roll}: they lie on one line within their accuracy (RMS distance from "
                f"the line {dist:.3g}, {rms:.2g} times their standard deviations of "
                f"{sd:.3g} RMS; at most {LINE_WITHIN_SIGMAS:g} times leaves the rotation "
                "to their noise)"
            ]
    return []


def _step_small(problem: Problem, s: _State, dc: np.ndarray, dp: np.ndarray, xtol: float) -> bool:
    m, b = problem.m, problem.b
    extent = max(float(np.ptp(s.X, axis=0).max()) if s.X.size else 1.0, 1e-9)
    dl = dc[: m * b].reshape(m, b)
    dg = dc[m * b :].reshape(problem.ng, NCAL)
    f = float(np.abs(s.cal[:, 0]).max())
    ok = np.abs(dl[:, :3]).max(initial=0) <= xtol * extent
    ok = ok and np.abs(dl[:, 3:6]).max(initial=0) <= xtol
    if b > 6:
        ok = ok and np.abs(dl[:, 6:]).max(initial=0) <= xtol * f
    scale = np.maximum(np.abs(s.cal), 1e-6)
    scale[:, :3] = f
    ok = ok and bool(np.all(np.abs(dg) <= xtol * scale))
    ok = ok and np.abs(dp).max(initial=0) <= xtol * extent
    return bool(ok)


@dataclass
class Iteration:
    """Outcome of the Levenberg-Marquardt loop."""

    state: _State
    iterations: int
    converged: bool
    message: str
    history: list
    weights: np.ndarray


class _BundleSteps:
    """The bundle problem for :func:`~photogeom.adjust.levenberg.levenberg_marquardt_loop`:
    damped Schur solves, trials, IRLS weights re-evaluated at each accepted state.

    With a robust loss the steps are first those of iteratively reweighted least squares
    (IRLS): Gauss-Newton on the cost weighted by ``rho'`` at the current residuals. They
    find the basin from a poor start (the weighted model over-estimates the curvature of
    the robust cost, so its steps are safe), but converge only linearly, and slowly where
    many residuals lie beyond the loss scale: along such a residual the cost's curvature is
    a small part of the weight (none for Huber's loss), so the steps there are a small part
    of what is needed (the 21-image ILCE-7RM2 block did not converge in 100 iterations, its
    cost still falling 1.6e-7 of itself per step). Once an accepted step lowers the cost by
    less than :data:`NEWTON_SWITCH` of it, the steps are Newton's, with the loss's
    curvature along each residual (:meth:`Problem.linearize` with ``radial``); their trials
    hold the tie points whose own move raised their cost (along a direction the robust
    cost is nearly flat in) and step them on their own
    (:meth:`Problem.guard_point_steps`), as the IRLS steps do after acceptance.
    """

    def __init__(self, problem: Problem, state: _State, e2: np.ndarray, xtol: float) -> None:
        self.problem, self.xtol = problem, xtol
        self._state = state
        self.newton = False
        self._cost = problem.robust_cost(e2) + problem.prior_terms(state)[4]
        self._guarded = False
        self.weights = problem.robust_weights(e2)
        self.lin = problem.linearize(state, self.weights)
        self._e2 = e2
        #: the damped normal equations of the last solve and their damping, with their
        #: factor: an accelerated retry of its step solves with it (no second reduction
        #: and factorisation); dropped before the next solve or linearisation
        self._normal = None
        self._damping = math.nan

    def solve(self, damping: float):
        self._normal = None  # the last trial's system: not kept beside this one
        ne = self.problem.sys.normal_equations(self.lin, damping=damping)
        dc, dp, _ = ne.solve()
        pred = ne.predicted_decrease(dc, dp, damping)
        ne.drop_reduction()  # kept: the factor and what a second right-hand side needs
        self._normal, self._damping = ne, damping
        return (dc, dp), pred

    def evaluate(self, state: _State, step):
        problem = self.problem
        trial = problem.update(state, *step)
        new_cost, self._e2, self._depth = problem.cost(trial)
        self._guarded = self.newton
        if self.newton:
            trial, e2, depth, changed = problem.guard_point_steps(
                state, trial, self._e2, self._depth
            )
            if changed:
                self._e2, self._depth = e2, depth
                new_cost = problem.robust_cost(e2) + problem.prior_terms(trial)[4]
        return trial, new_cost, bool(np.all(self._depth > 0))

    def accelerate(self, state: _State, step, damping: float):
        """The damped step ``v`` with its geodesic acceleration (Transtrum and Sethna):
        ``v + a / 2``, ``a`` the damped solve with the second directional derivative of the
        residuals along ``v`` in place of the residuals, or None when ``|a|`` exceeds
        :data:`ACCELERATION_RATIO` times ``|v| / 2`` (norms scaled by the diagonal the
        damping is scaled by) or the loss is robust. ``a`` is solved with the factor of
        the damped system ``v`` came from (the same matrix: only the right-hand side
        differs).

        The second derivative is the finite difference ``2 / h (r(x + h v) - r(x) - h J v)
        / h`` with ``h`` = :data:`ACCELERATION_STEP`; the terms of the GNSS, IMU and
        control-point observations are left out of it (their curvature is nil or small).
        The acceleration follows a curved valley of the cost that the linear model leaves
        after the first-order step: a camera per image (BAL), whose focal length trades
        with the distance to the ground and its distortion with both, takes such steps.
        """
        problem = self.problem
        if problem.options.loss != "squared" or state is not self._state:
            return None
        ne = self._normal
        if ne is None or self._damping != damping:  # not the last solve's system
            self._normal = None
            ne = self._normal = problem.sys.normal_equations(self.lin, damping=damping)
            self._damping = damping
        dc, dp = step
        lin = self.lin
        m, b = problem.m, problem.b
        i, j = problem.obs_i, problem.obs_j
        cam = problem.block.image_camera[i]
        dl = dc[: m * b].reshape(m, b)
        dg = dc[m * b :].reshape(problem.ng, NCAL)
        jv = (
            np.einsum("ndc,nc->nd", lin.A, dl[i])
            + np.einsum("ndc,nc->nd", lin.G, dg[cam])
            + np.einsum("ndc,nc->nd", lin.P, dp[j])
        )
        h = ACCELERATION_STEP
        sw = np.sqrt(self.weights) / problem.sigma_obs()
        near = problem.residuals(problem.update(state, h * dc, h * dp))[0] * sw[:, None]
        near -= lin.r
        near /= h
        near -= jv
        near *= 2.0 / h  # r_vv, whitened
        del jv
        ac, ap = ne.solve_gradient(*problem.sys.gradient(lin, near))
        del near
        # norms in the damping's metric
        diag = ne.damping_diagonal()
        v = np.concatenate([dc, dp.ravel()])
        a = np.concatenate([ac, ap.ravel()])
        if 2.0 * math.sqrt(diag @ (a * a)) > ACCELERATION_RATIO * math.sqrt(diag @ (v * v)):
            return None
        return dc + 0.5 * ac, dp + 0.5 * ap

    def refine(self, state: _State, trial: _State, cost: float):
        """The accepted ``trial`` with the tie points whose own step raised their cost
        moved by point-only steps (:meth:`Problem.guard_point_steps`), and its cost."""
        problem = self.problem
        if self._guarded:  # done in evaluate
            return trial, cost
        trial, e2, _, changed = problem.guard_point_steps(state, trial, self._e2, self._depth)
        if not changed:
            return trial, cost
        self._e2 = e2
        # summed anew: the trial's cost may exceed the refined one 1e18 times
        return trial, problem.robust_cost(e2) + problem.prior_terms(trial)[4]

    def small(self, state: _State, step) -> bool:
        return _step_small(self.problem, state, *step, self.xtol)

    def accept(self, state: _State) -> None:
        self._state = state
        problem = self.problem
        cost = problem.robust_cost(self._e2) + problem.prior_terms(state)[4]
        if problem.options.loss != "squared" and self._cost - cost <= NEWTON_SWITCH * cost:
            self.newton = True
        self._cost = cost
        self.weights = problem.robust_weights(self._e2)
        radial = problem.radial_curvature(self._e2) if self.newton else None
        self._normal = None  # the last trial's system, then the old Jacobian blocks:
        self.lin = None  # freed before the new ones are formed
        self.lin = problem.linearize(state, self.weights, radial)


def levenberg_marquardt(problem: Problem, state: _State, options: BundleOptions, progress=None):
    """Minimise the (robust) cost from ``state``; see :class:`Iteration`."""
    cost, e2, depth = problem.cost(state)
    if np.any(~(depth > 0)):
        from .result import start_route

        k = np.flatnonzero(~(depth > 0))
        o = problem.block.observations
        row = problem.obs_rows[k[0]]
        raise DegenerateGeometryError(
            f"{k.size} observation(s) have their point behind the camera at the start, e.g. "
            f"image {o.image_ids[row]} point {o.point_ids[row]}: check the initial exterior "
            "orientations (angles in radians, M = M3(kappa) M2(phi) M1(omega)) and points; "
            "a block without GNSS/IMU, or with a start degrees off, takes "
            f"{start_route(problem.block)}"
        )
    steps = _BundleSteps(problem, state, e2, options.xtol)
    run = levenberg_marquardt_loop(
        steps,
        state,
        cost,
        options,
        exact_cost=1e-26 * max(2 * problem.obs_i.size, 1),
        progress=progress,
    )
    return Iteration(
        run.state, run.iterations, run.converged, run.message, run.history, steps.weights
    )


def bundle_adjust(block: Block, options: BundleOptions | None = None, *, progress=None, **kwargs):
    """Adjust an image block: exterior orientations, points and the camera calibration.

    Parameters
    ----------
    block : Block
        The block with initial values (see :class:`photogeom.bundle.Block`).
    options : BundleOptions, optional
        Settings; default ``BundleOptions()``.
    progress : callable, optional
        Called as ``progress(iteration, cost, damping)`` after each accepted step. With
        ``verbose=True`` and no ``progress``, one line per iteration is printed.
    **kwargs
        Single fields of :class:`BundleOptions` overriding ``options`` (e.g.
        ``loss="huber"``, ``point_covariance=True``, ``free=("f", "cx", "cy", "k1", "k2")``);
        an unknown name raises :class:`InputError`.

    Returns
    -------
    BundleFit
        The adjusted block, statistics and diagnostics.

    Raises
    ------
    DegenerateGeometryError
        Datum defect, points behind cameras at the start, points without intersection,
        parameters the observations do not determine.
    InputError
        Invalid block (unknown ids, points seen once, duplicate observations, ...) or options.
    """
    opts = options or BundleOptions()
    opts = opts.updated(**kwargs) if kwargs else opts.validate()
    return adjust_block(block, opts, progress=progress)


def adjust_block(block: Block, opts: BundleOptions, *, progress=None, effective_redundancy=None):
    """:func:`bundle_adjust` with resolved options and, optionally, the redundancy its
    sigma0 is computed with (``effective_redundancy``, a mapping with ``"value"``: see
    :attr:`photogeom.bundle.BundleFit.effective_redundancy`)."""
    from .result import build_result

    t0 = time.perf_counter()
    if not isinstance(block, Block):
        raise InputError(
            f"bundle_adjust needs a photogeom.bundle.Block, got {type(block).__name__}"
        )
    block.validate()
    problem = Problem(block, opts)
    problem.check_redundancy()
    if opts.verbose and progress is None:

        def progress(it, cost, lam):
            print(f"iteration {it:3d}  cost {cost:.6e}  damping {lam:.1e}")

    run = levenberg_marquardt(problem, problem.initial_state(), opts, progress)
    vce = None
    if opts.variance_components:
        from .variance import iterate_variance_components

        run, vce = iterate_variance_components(problem, run, opts, progress)
    return build_result(
        problem, run, opts, vce, time.perf_counter() - t0, effective_redundancy
    )
