"""Finite-element residual grid of one image: bilinear elements on a regular node grid.

Geometry (pixel convention of the library: the centre of the top-left pixel is (0, 0),
``u`` the column to the right, ``v`` the row down): nodes at ``(j g, i g)`` for
``i = 0 .. ny-1``, ``j = 0 .. nx-1``, ``nx = ceil((width - 0.5) / g) + 1`` (likewise ``ny``),
so that the last node lies at or past the outer edge of the last pixel. A point at
``(u, v)`` lies in the cell with lower corner node ``(i, j) = (floor(v / g), floor(u / g))``
(clipped to the last cell) at local coordinates ``a = u / g - j``, ``b = v / g - i``, and

    r(u, v) = (1-a)(1-b) z_ij + a(1-b) z_i,j+1 + (1-a) b z_i+1,j + a b z_i+1,j+1

for each of the two components. Points in the outer half of the first pixel row or column
(``-0.5 <= u < 0``) are extrapolated from the first cell.

Fit: observations ``l_k`` (the image residuals, computed minus observed, px) with weights
``p_k = 1 / sigma_k^2`` and pseudo-observations ``0 = C z`` with weight ``1 / sigma_c^2``:
each node equals the mean of its 4 neighbours (``border="mean"``: border and corner nodes
the mean of the neighbours they have; ``border="linear"``: along each axis where the node
has both neighbours, the mean of the pair, corners free, which leaves bilinear fields
unconstrained). ``N = A' P A + C' P_c C`` is factorised once for both components.
"""

from __future__ import annotations

import math
import numbers
import threading
import weakref
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import Literal

import numpy as np
import scipy.sparse as sp

from ..adjust.selected_inverse import BlockSelectedInverse, single_threaded_blas
from ..adjust.snooping import w_critical_value
from ..adjust.sparse import HAVE_CHOLMOD, factorize
from ..adjust.variance_components import update_variance_factors
from ..errors import DegenerateGeometryError, InputError, TooFewPointsError
from ..records import freeze_fields, read_only_fields

Border = Literal["mean", "linear"]
BORDERS = ("mean", "linear")
#: Fewest residuals of an image for its grid (default of :func:`fit_grid`).
_MIN_OBSERVATIONS = 4


# --------------------------------------------------------------------------- geometry
#: Most nodes of one grid (a 3162 x 3162 node grid): beyond, the arrays of the nodes and of
#: the normal equations alone need tens of gigabytes.
MAX_NODES = 10_000_000
#: A fit of more nodes than this needs at least one observation per
#: :data:`MAX_NODES_PER_OBSERVATION` nodes (below, a fit takes at most about 1.5 s and
#: 300 MB whatever the observations).
FREE_NODES = 50_000
#: Most nodes per observation of a grid of more than :data:`FREE_NODES` nodes: a 42 Mpx image
#: at 100 px (4455 nodes) with 120 observations has 37. Beyond, the smoothness constraints
#: alone fix nearly every node, and the cost grows with the nodes (measured with 5 folds:
#: 200 901 nodes 8 s and 1.2 GB; 801 801 nodes 3 GB and minutes).
MAX_NODES_PER_OBSERVATION = 100
#: Bytes of memory per node of a fit with cross-validation (measured, 200 901 nodes).
_BYTES_PER_NODE = 6_000


def check_spacing(value: object, name: str = "grid spacing") -> float:
    """``value`` as a positive finite length in pixels: a node spacing, or a standard
    deviation of the grids' pseudo-observations.

    Parameters
    ----------
    value : object
        The length (px): a real number (int, float, numpy number); booleans and text
        are refused (``True`` is an int, ``"100"`` converts, and both were taken as
        1 px and 100 px).
    name : str
        How the error names the value.

    Returns
    -------
    float
        The length, px.

    Raises
    ------
    InputError
        Not a real number, or not finite and positive.
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value.item()  # a 0-d array, e.g. a value read from a file
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{name} must be a number of pixels, not {value!r}")
    g = float(value)  # every numbers.Real converts
    if not math.isfinite(g) or g <= 0:
        raise InputError(f"{name} must be a positive number of pixels, not {value!r}")
    return g


@dataclass(frozen=True)
class GridLayout:
    """Node layout of a residual grid over an image.

    Parameters
    ----------
    width, height : int
        Image size in pixels (columns, rows).
    spacing : float
        Node spacing ``g`` in pixels, the same in both directions.
    """

    width: int
    height: int
    spacing: float

    def __post_init__(self) -> None:
        w, h, g = self.width, self.height, self.spacing
        for name, val in (("width", w), ("height", h)):
            if not isinstance(val, (int, np.integer)) or val < 1:
                raise InputError(
                    f"image {name} must be a positive whole number of pixels, not {val!r}"
                )
        g = check_spacing(g)
        if g > max(w, h):
            raise InputError(
                f"grid spacing {g:g} px is larger than the image ({w} x {h} px): choose a "
                f"spacing of at most {max(w, h)} px"
            )
        object.__setattr__(self, "width", int(w))
        object.__setattr__(self, "height", int(h))
        object.__setattr__(self, "spacing", g)
        nodes = self.nx * self.ny
        if nodes > MAX_NODES:  # the node arrays alone would not fit in memory
            raise InputError(
                f"grid spacing {g:g} px on a {w} x {h} px image gives {self.ny} x {self.nx} = "
                f"{nodes:,} nodes, more than {MAX_NODES:,}: choose a larger spacing (at least "
                f"{math.sqrt(w * h / MAX_NODES):.3g} px)"
            )

    @property
    def nx(self) -> int:
        """Number of node columns."""
        return math.ceil((self.width - 0.5) / self.spacing) + 1

    @property
    def ny(self) -> int:
        """Number of node rows."""
        return math.ceil((self.height - 0.5) / self.spacing) + 1

    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``."""
        return self.ny, self.nx

    @property
    def n_nodes(self) -> int:
        return self.nx * self.ny

    def node_coordinates(self) -> tuple[np.ndarray, np.ndarray]:
        """Node positions ``(u, v)`` in pixels.

        Returns
        -------
        u, v : numpy.ndarray, shape (ny, nx)
            px.
        """
        g = self.spacing
        return np.meshgrid(np.arange(self.nx) * g, np.arange(self.ny) * g)

    def check_inside(self, uv: np.ndarray, what: str = "uv") -> None:
        """Refuse points outside the image area ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``.

        Parameters
        ----------
        uv : numpy.ndarray, shape (n, 2)
            Pixels (col, row), centre convention.
        what : str, default "uv"
            Name of the points in the message.

        Raises
        ------
        InputError
            Counting the points outside and naming the first.
        """
        out = (
            (uv[:, 0] < -0.5)
            | (uv[:, 0] > self.width - 0.5)
            | (uv[:, 1] < -0.5)
            | (uv[:, 1] > self.height - 0.5)
        )
        if np.any(out):
            k = int(np.flatnonzero(out)[0])
            raise InputError(
                f"{what}: {int(out.sum())} point(s) outside the {self.width} x {self.height} px "
                f"image (first: row {k}, ({uv[k, 0]:g}, {uv[k, 1]:g}))"
            )

    def locate(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element nodes and bilinear weights of points.

        Parameters
        ----------
        uv : numpy.ndarray, shape (n, 2)
            Pixels (col, row) inside the image.

        Returns
        -------
        nodes : numpy.ndarray of int, shape (n, 4)
        weights : numpy.ndarray, shape (n, 4)
        """
        g, nx = self.spacing, self.nx
        x = uv[:, 0] / g
        y = uv[:, 1] / g
        j = np.clip(np.floor(x).astype(np.int64), 0, nx - 2)
        i = np.clip(np.floor(y).astype(np.int64), 0, self.ny - 2)
        a = x - j
        b = y - i
        k = i * nx + j
        nodes = np.stack([k, k + 1, k + nx, k + nx + 1], axis=1)
        weights = np.stack([(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b], axis=1)
        return nodes, weights

    def cell_index(self, uv: np.ndarray) -> np.ndarray:
        """Index ``i * (nx - 1) + j`` of the cell holding each point.

        Parameters
        ----------
        uv : numpy.ndarray, shape (n, 2)
            Pixels (col, row) inside the image.

        Returns
        -------
        numpy.ndarray of int, shape (n,)
        """
        g = self.spacing
        j = np.clip(np.floor(uv[:, 0] / g).astype(np.int64), 0, self.nx - 2)
        i = np.clip(np.floor(uv[:, 1] / g).astype(np.int64), 0, self.ny - 2)
        return i * (self.nx - 1) + j

    def design_matrix(self, uv: np.ndarray) -> sp.csr_matrix:
        """Sparse ``A`` of the bilinear interpolation at ``uv``.

        Parameters
        ----------
        uv : numpy.ndarray, shape (n, 2)
            Pixels (col, row) inside the image.

        Returns
        -------
        scipy.sparse.csr_matrix, shape (n, n_nodes)
            Four weights per row, summing to 1.
        """
        nodes, w = self.locate(uv)
        n = uv.shape[0]
        indptr = np.arange(0, 4 * n + 1, 4)
        return sp.csr_matrix((w.ravel(), nodes.ravel(), indptr), shape=(n, self.n_nodes))

    def constraint_matrix(self, border: Border = "mean") -> sp.csr_matrix:
        """Sparse ``C``: rows ``z_ij - mean(neighbours)`` (see the module).

        Parameters
        ----------
        border : {"mean", "linear"}, default "mean"
            Smoothness condition at the border nodes (see the module).

        Returns
        -------
        scipy.sparse.csr_matrix, shape (m, n_nodes)
            ``m = n_nodes`` for ``"mean"``, ``n_nodes - 4`` for ``"linear"``.

        Raises
        ------
        InputError
            For another ``border``.
        """
        if border not in BORDERS:
            raise InputError(f"border must be one of {', '.join(BORDERS)}, not {border!r}")
        ny, nx = self.shape
        I, J = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        I, J = I.ravel(), J.ravel()
        k = I * nx + J
        left, right, up, down = J > 0, J < nx - 1, I > 0, I < ny - 1
        if border == "mean":
            use = {"l": left, "r": right, "u": up, "d": down}
        else:
            hx, hy = left & right, up & down
            use = {"l": hx, "r": hx, "u": hy, "d": hy}
        deg = sum(m.astype(float) for m in use.values())
        rows_mask = deg > 0
        row_of = np.cumsum(rows_mask) - 1
        offs = {"l": -1, "r": 1, "u": -nx, "d": nx}
        R = [row_of[rows_mask]]
        Cc = [k[rows_mask]]
        V = [np.ones(int(rows_mask.sum()))]
        for key, m in use.items():
            R.append(row_of[m])
            Cc.append(k[m] + offs[key])
            V.append(-1.0 / deg[m])
        m_rows = int(rows_mask.sum())
        return sp.csr_matrix(
            (np.concatenate(V), (np.concatenate(R), np.concatenate(Cc))),
            shape=(m_rows, self.n_nodes),
        )

    def constraint_rank(self, border: Border = "mean") -> int:
        """Independent smoothness pseudo-observations per component: the rank of ``C``.

        With ``border="mean"`` every node has a row, but the rows are dependent: summed with
        the nodes' neighbour counts as weights they vanish for every field
        (``sum_k deg_k (z_k - mean of its neighbours) = 0``), so only ``n_nodes - 1`` are
        independent (the constant field is the one null vector). With ``"linear"`` the
        ``n_nodes - 4`` rows are independent (the bilinear fields are the null space).
        The redundancy and the variance components count these, not the rows.

        Parameters
        ----------
        border : {"mean", "linear"}, default "mean"
            Smoothness condition at the border nodes (see the module).

        Returns
        -------
        int

        Raises
        ------
        InputError
            For another ``border``.
        """
        if border not in BORDERS:
            raise InputError(f"border must be one of {', '.join(BORDERS)}, not {border!r}")
        return self.n_nodes - (1 if border == "mean" else 4)

    def to_dict(self) -> dict:
        """``{"width", "height"}`` of the image (px) and the node ``"spacing"`` (px).

        Returns
        -------
        dict
        """
        return {"width": self.width, "height": self.height, "spacing": self.spacing}


# --------------------------------------------------------------------------- system
#: Factorisation of the grid's normal matrix: sparse at every size. The matrix is banded
#: (13 non-zeros per row); the library's "auto" choice, a dense Cholesky up to 2500
#: unknowns, took 263 ms per image for the 2035 nodes of a 7952 x 5304 px image at 150 px
#: against 56 ms for the 4455 nodes at 100 px (sparse; 16 ms sparse at 150 px), so the
#: computing time of the grid-size sweep, its cost axis, fell from 150 px to 100 px.
GRID_BACKEND = "cholmod" if HAVE_CHOLMOD else "superlu"


class FiniteElementSystem:
    """The normal equations of one image's grid for given weights.

    ``N = A' P A + C' P_c C``, factorised once (``photogeom.adjust.sparse``); ``solve``
    returns the node values for observations ``l`` (n, 2) and, optionally, non-zero
    pseudo-observations ``lc`` (m, 2) of the constraints (zero in the grid fit).

    Parameters
    ----------
    layout : GridLayout
    uv : numpy.ndarray, shape (n, 2)
        Observation positions (px).
    weights : numpy.ndarray, shape (n,)
        ``p_k = 1 / sigma_k^2`` (1/px^2).
    constraint_weight : float
        ``1 / sigma_c^2`` (1/px^2).
    border : {"mean", "linear"}
    A, C : scipy.sparse matrix, optional
        The design and constraint matrices when already built.
    factor : bool
        Factorise ``N`` (needed by ``solve``; not by ``selected_inverse``).
    """

    def __init__(
        self,
        layout: GridLayout,
        uv,
        weights,
        constraint_weight: float,
        border: Border = "mean",
        *,
        A=None,
        C=None,
        factor: bool = True,
    ):
        self.layout = layout
        self.uv = uv
        self.weights = np.asarray(weights, dtype=float)
        self.constraint_weight = float(constraint_weight)
        self.border = border
        self.A = layout.design_matrix(uv) if A is None else A
        self.C = layout.constraint_matrix(border) if C is None else C
        AtP = self.A.T.multiply(self.weights[None, :]).tocsr()
        self._AtP = AtP
        self.N = (AtP @ self.A + self.constraint_weight * (self.C.T @ self.C)).tocsc()
        self.factor = None
        if not factor:  # only the selected inverse is wanted
            return
        try:
            self.factor = factorize(
                self.N, backend=GRID_BACKEND, what="normal matrix of the residual grid"
            )
        except DegenerateGeometryError as exc:
            raise DegenerateGeometryError(
                f"{exc}: the observations do not determine the grid (with border='linear' "
                "at least 4 points not on one line are needed; try border='mean')"
            ) from None

    def solve(self, l: np.ndarray, lc: np.ndarray | None = None) -> np.ndarray:
        """Node values for observations ``l`` (and pseudo-observations).

        Parameters
        ----------
        l : numpy.ndarray, shape (n, 2)
            Observed residuals (x, y), px.
        lc : numpy.ndarray, shape (m, 2), optional
            Values of the smoothness pseudo-observations, px; default zero.

        Returns
        -------
        numpy.ndarray, shape (n_nodes, 2)
            px.
        """
        rhs = self._AtP @ l
        if lc is not None:
            rhs = rhs + self.constraint_weight * (self.C.T @ lc)
        return self.factor.solve(np.asarray(rhs))

    @cached_property
    def selected_inverse(self) -> BlockSelectedInverse:
        """Entries of ``N^-1`` on the pattern of ``N`` (two node rows or columns per block)."""
        ny, nx = self.layout.shape
        if nx <= ny:  # blocks of two node rows
            perm, s = np.arange(nx * ny), 2 * nx
        else:  # blocks of two node columns
            perm, s = np.arange(nx * ny).reshape(ny, nx).T.ravel(), 2 * ny
        return BlockSelectedInverse(self.N, s, perm, what="normal matrix of the residual grid")

    def observation_cofactors(self) -> np.ndarray:
        """``a_k' N^-1 a_k`` for every observation: cofactor of the modelled residual.

        Returns
        -------
        numpy.ndarray, shape (n,)
            px^2 per unit weight.
        """
        nodes, w = self.layout.locate(self.uv)
        Z = self.selected_inverse.entries(nodes[:, :, None], nodes[:, None, :])
        return np.einsum("ki,kij,kj->k", w, Z, w)


# --------------------------------------------------------------------------- result
@dataclass(frozen=True, eq=False)
class ResidualGrid:
    """The fitted residual field of one image.

    Attributes
    ----------
    layout : GridLayout
    nodes : numpy.ndarray, shape (ny, nx, 2)
        Node values (px): the modelled residual, computed minus observed, (x, y).
    sigma0 : float
        A-posteriori standard deviation of unit weight of the fit (observations and
        pseudo-observations); NaN when the redundancy is 0.
    redundancy : int
        ``2 (n_used + m - n_nodes)`` (both components), ``m`` the independent
        constraints (:meth:`GridLayout.constraint_rank`): ``2 (n_used - 1)`` with
        ``border="mean"``, ``2 (n_used - 4)`` with ``"linear"``.
    sigma_obs : numpy.ndarray, shape (n,)
        Standard deviations of the observations used (px), after variance components.
    sigma_constraint : float
        Standard deviation of the pseudo-observations (px), after variance components.
    support : numpy.ndarray of bool, shape (ny, nx)
        Nodes whose adjacent cells hold at least ``min_support`` used observations.
    counts : numpy.ndarray of int, shape (ny, nx)
        Observations in the cells adjacent to each node.
    rms_before, rms_after : float
        RMS length of the image's residuals before and after subtracting the field
        (used points, px).
    rms_cv_before, rms_cv_after : float
        The same on points left out of the fit (k-fold cross-validation); NaN without it,
        or when leaving a fold out leaves the grid undetermined (``border="linear"`` with
        very few points).
    outliers : numpy.ndarray of bool, shape (n_input,)
        Input points rejected by data snooping.
    vce_iterations : int
        Variance-component iterations (0: weights given).
    border : str
    uv : numpy.ndarray, shape (n_input, 2), optional
        Pixel positions of the input points (px), kept to compute :attr:`node_std` on first
        use (and stored by :func:`~photogeom.calibration.save_grids`); None for a grid
        read from a file written without them, and for the grids of
        :func:`~photogeom.calibration.adjust_with_grids`.
    snooping : mapping, optional
        Read-only (its arrays too). With ``snooping=True``: ``"test"`` (``"w"``),
        ``"alpha"``, ``"critical_value"`` and ``"w"`` (n_input,), the larger ``|w|`` of
        the two components of every rejected point in the round that rejected it (NaN for
        the points kept); ``"rounds"``, the rounds that removed points, and
        ``"still_flagged"`` (n_input,), the points still failing the test when
        ``max_snooping_rounds`` ended the removal (kept in the fit);
        None otherwise (and for grids read from a file).

    Notes
    -----
    The arrays are read-only views (the node cofactors are computed once from ``uv``,
    ``sigma_obs`` and ``outliers`` and kept): change a grid with
    :func:`dataclasses.replace`, which gives a grid whose kept cofactors are those of its own
    observations, weights and layout (kept when these are unchanged, computed again
    otherwise).
    """

    layout: GridLayout
    nodes: np.ndarray
    sigma0: float
    redundancy: int
    sigma_obs: np.ndarray
    sigma_constraint: float
    support: np.ndarray
    counts: np.ndarray
    rms_before: float
    rms_after: float
    rms_cv_before: float = float("nan")
    rms_cv_after: float = float("nan")
    outliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    vce_iterations: int = 0
    border: str = "mean"
    uv: np.ndarray | None = field(default=None, repr=False)
    snooping: Mapping | None = field(default=None, repr=False)
    _std: list = field(default_factory=list, repr=False)

    def __post_init__(self) -> None:
        read_only_fields(self)
        freeze_fields(self, ("snooping",))  # its "w" and "still_flagged" read-only too
        # The cache holds (inputs, cofactor) pairs; dataclasses.replace hands the original's
        # list over: keep only what was computed for this grid's inputs, in a list of its own
        # (a bare array is a cofactor given for this grid: read from a file, or computed by
        # the adjustment with grids).
        key = self._cofactor_key()
        kept = [
            (key, _read_only_view(entry))
            if isinstance(entry, np.ndarray)
            else (key, entry[1])
            for entry in self._std
            if isinstance(entry, np.ndarray) or _same_inputs(entry[0], key)
        ]
        object.__setattr__(self, "_std", kept[:1])

    def __setstate__(self, state: dict) -> None:
        # pickle / deepcopy rebuild arrays writable: read-only again (the cache included)
        self.__dict__.update(state)
        for name in _GRID_ARRAYS:
            value = self.__dict__.get(name)
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
        for _, cof in self.__dict__.get("_std", ()):
            cof.flags.writeable = False
        freeze_fields(self, ("snooping",))

    def _cofactor_key(self) -> tuple:
        """What the node cofactors derive from (arrays compared by identity: read-only)."""
        return (
            self.layout,
            self.border,
            self.sigma_constraint,
            self.uv,
            self.sigma_obs,
            self.outliers,
        )

    # -------------------------------------------------------------- evaluation
    @property
    def spacing(self) -> float:
        return self.layout.spacing

    @property
    def image_size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self.layout.width, self.layout.height

    def evaluate(self, uv) -> np.ndarray:
        """The modelled residual (computed minus observed, px) at image points.

        Parameters
        ----------
        uv : array_like, shape (n, 2) or (2,)
            Pixel coordinates (column, row) inside the image.

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            px.
        """
        single = np.ndim(uv) == 1
        uv = _as_uv(uv, "uv", "evaluating the grid")
        self.layout.check_inside(uv)
        out = evaluate_nodes(self.layout, self.nodes, uv)
        return out[0] if single else out

    def correct(self, uv) -> np.ndarray:
        """Corrected image coordinates ``uv + r(uv)``.

        The observation moved by the modelled residual, i.e. the local displacement field
        ``-r`` subtracted.

        Parameters
        ----------
        uv : array_like, shape (n, 2) or (2,)
            Observed pixels (col, row).

        Returns
        -------
        numpy.ndarray, shape (n, 2) (or (2,) for a single point (2,))
            px.
        """
        single = np.ndim(uv) == 1
        uv = _as_uv(uv, "uv", "correcting them")
        out = uv + self.evaluate(uv)
        return out[0] if single else out

    @property
    def reduction(self) -> float:
        """``1 - rms_after / rms_before`` on the points of the fit."""
        return 1.0 - self.rms_after / self.rms_before if self.rms_before > 0 else float("nan")

    @property
    def reduction_cv(self) -> float:
        """``1 - rms_cv_after / rms_cv_before`` on points left out (cross-validation)."""
        if not self.rms_cv_before > 0:
            return float("nan")
        return 1.0 - self.rms_cv_after / self.rms_cv_before

    @property
    def node_std(self) -> np.ndarray:
        """A-posteriori standard deviations of the node values (ny, nx), px, the same for
        x and y: ``sigma0 sqrt(diag(N^-1))``. Computed on first use (selected inversion,
        no dense inverse)."""
        return self.sigma0 * np.sqrt(self.node_cofactor)

    @property
    def node_cofactor(self) -> np.ndarray:
        """``diag(N^-1)`` reshaped (ny, nx), px^2 per unit weight; computed on first use
        and kept (read-only)."""
        if not self._std:
            if self.uv is None:
                raise InputError(
                    "node standard deviations were not stored with this grid (saved with "
                    "std=False / --no-std, or its weights or layout replaced after reading): "
                    "fit the grid again to compute them"
                )
            used = ~self.outliers if self.outliers.size else np.ones(len(self.uv), bool)
            with single_threaded_blas():
                sysm = FiniteElementSystem(
                    self.layout,
                    self.uv[used],
                    1.0 / self.sigma_obs**2,
                    1.0 / self.sigma_constraint**2,
                    self.border,  # type: ignore[arg-type]
                    factor=False,
                )
                diag = sysm.selected_inverse.diagonal()
            cof = diag.reshape(self.layout.shape)
            cof.flags.writeable = False  # the cache itself is returned: never written into
            self._std.append((self._cofactor_key(), cof))
        return self._std[0][1]

    def to_dict(self) -> dict:
        """JSON-ready summary (without the node arrays).

        Returns
        -------
        dict
            Layout, sigma0, redundancy, RMS values (px), counts; ``sigma_obs_rms`` is the RMS of
            the observations' standard deviations (px), estimated with ``sigma_constraint="vce"``.
        """
        return {
            **self.layout.to_dict(),
            "shape": list(self.layout.shape),
            "border": self.border,
            "sigma0": _num(self.sigma0),
            "redundancy": int(self.redundancy),
            "sigma_constraint": _num(self.sigma_constraint),
            "sigma_obs_rms": (
                _num(float(np.sqrt(np.mean(np.square(self.sigma_obs)))))
                if self.sigma_obs.size
                else None
            ),
            "n_observations": int(self.sigma_obs.size),
            "n_outliers": int(self.outliers.sum()),
            "supported_nodes": int(self.support.sum()),
            "rms_before": _num(self.rms_before),
            "rms_after": _num(self.rms_after),
            "reduction": _num(self.reduction),
            "rms_cv_before": _num(self.rms_cv_before),
            "rms_cv_after": _num(self.rms_cv_after),
            "reduction_cv": _num(self.reduction_cv),
            "vce_iterations": int(self.vce_iterations),
        }


def _num(x) -> float | None:
    return float(x) if np.isfinite(x) else None


#: The array fields of :class:`ResidualGrid` (read-only).
_GRID_ARRAYS = ("nodes", "sigma_obs", "support", "counts", "outliers", "uv")


def _read_only_view(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a`` (``a`` itself when it is read-only already)."""
    if not a.flags.writeable:
        return a
    v = a.view()
    v.flags.writeable = False
    return v


def _same_inputs(a: tuple, b: tuple) -> bool:
    """Two :meth:`ResidualGrid._cofactor_key` tuples name the same inputs."""
    (la, ba, sa, *arrays_a), (lb, bb, sb, *arrays_b) = a, b
    same_scalar = sa == sb or (sa != sa and sb != sb)  # NaN equals NaN here
    return la == lb and ba == bb and same_scalar and all(
        x is y for x, y in zip(arrays_a, arrays_b)
    )


def evaluate_nodes(layout: GridLayout, nodes: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of node values (ny, nx, 2) at points (n, 2); no checks."""
    idx, w = layout.locate(uv)
    flat = nodes.reshape(-1, 2)
    return np.einsum("nk,nkc->nc", w, flat[idx])


def _as_uv(values, name: str, action: str = "fitting") -> np.ndarray:
    """``values`` as an (n, 2) float array; errors name ``name`` and say to remove bad rows
    before ``action`` (the operation the caller asked for: fitting, evaluating, ...)."""
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{name}: cannot be read as numbers ({exc})") from exc
    if arr.ndim == 1 and arr.shape[0] == 2:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise InputError(f"{name}: expected shape (n, 2) or (2,), got {arr.shape}")
    bad = ~np.isfinite(arr).all(axis=1)
    if np.any(bad):
        raise InputError(
            f"{name}: {int(bad.sum())} row(s) hold NaN or infinite values (first: row "
            f"{int(np.flatnonzero(bad)[0])}); remove them before {action}"
        )
    return arr


# --------------------------------------------------------------------------- fitting
def fit_grid(
    uv,
    residuals,
    image_size: tuple[int, int],
    spacing: float,
    *,
    sigma_obs=1.0,
    sigma_constraint: float | Literal["vce"] = 1.0,
    border: Border = "mean",
    min_observations: int = _MIN_OBSERVATIONS,
    min_support: int = 3,
    folds: int = 5,
    snooping: bool = False,
    alpha: float = 0.001,
    max_snooping_rounds: int = 10,
    max_vce_iterations: int = 30,
    vce_tol: float = 1e-3,
    seed: int = 0,
    image_id: object = None,
) -> ResidualGrid:
    """Fit the finite-element residual field of one image.

    Parameters
    ----------
    uv : array_like, shape (n, 2)
        Observed image coordinates (column, row) in pixels.
    residuals : array_like, shape (n, 2)
        Image residuals at ``uv`` (computed minus observed, px).
    image_size : (int, int)
        ``(width, height)`` of the image in pixels.
    spacing : float
        Node spacing in pixels.
    sigma_obs : float or array_like (n,)
        Standard deviation of the residuals (px); weights ``1 / sigma_obs^2``.
    sigma_constraint : float or "vce"
        Standard deviation of the pseudo-observations ``0 = z - mean(neighbours)`` (px), or
        ``"vce"`` to estimate both variances (Förstner's iteration; ``sigma_obs`` is then
        the start and only its relative values matter).
    max_vce_iterations, vce_tol : int, float
        With ``"vce"``: at most ``max_vce_iterations`` solves of the grid
        (:class:`ConvergenceError` beyond); converged when the ratio of the two estimated
        variance factors is within ``(1 + vce_tol)^2`` of 1 (unitless).
    border : {"mean", "linear"}
        Constraint of border and corner nodes (see the module).
    min_observations : int
        Fewer used observations than this is refused.
    min_support : int
        A node is supported when its adjacent cells hold at least this many observations.
    folds : int
        k of the k-fold cross-validation (0 or 1: none).
    snooping, alpha, max_snooping_rounds : bool, float, int
        Data snooping (Baarda's w-test with the a-priori sigmas, level ``alpha``, two-sided:
        0.001 gives the critical value 3.29); per round every flagged point whose ``|w|`` is
        the largest of the flagged points in its cell and the 8 cells around it is removed,
        up to ``max_snooping_rounds`` rounds; points still flagged then are marked in
        ``snooping["still_flagged"]`` of the result.
    seed : int
        Seed of the pseudo-random split into folds (a hash of each observation's values
        salted by the seed: the split does not depend on the order of the observations).
    image_id : object
        Named in error messages.

    Returns
    -------
    ResidualGrid
        Node values (px), sigma0, redundancy, the observations' and pseudo-observations'
        standard deviations, support, outliers and the RMS before/after (also
        cross-validated).

    Raises
    ------
    InputError
        NaN/infinite values, points outside the image, bad spacing (0, negative, larger
        than the image), mismatched shapes.
    TooFewPointsError
        Fewer than ``min_observations`` residuals.
    """
    # small dense blocks and supernodes: BLAS threads cost more than they give
    with single_threaded_blas():
        return _fit_grid(
            uv,
            residuals,
            image_size,
            spacing,
            sigma_obs=sigma_obs,
            sigma_constraint=sigma_constraint,
            border=border,
            min_observations=min_observations,
            min_support=min_support,
            folds=folds,
            snooping=snooping,
            alpha=alpha,
            max_snooping_rounds=max_snooping_rounds,
            max_vce_iterations=max_vce_iterations,
            vce_tol=vce_tol,
            seed=seed,
            image_id=image_id,
        )


def _image_inputs(uv, residuals, image_size, spacing, min_observations: int, where: str):
    """The checks of one image's input that need no fitting (shapes, finite values, the
    points inside the image, the spacing, enough points): ``(uv, residuals, layout)``."""
    uv = _as_uv(uv, f"{where}uv")
    res = _as_uv(residuals, f"{where}residuals")
    if res.shape != uv.shape:
        raise InputError(f"{where}uv {uv.shape} and residuals {res.shape} differ in shape")
    try:
        width, height = (int(x) for x in image_size)
    except (TypeError, ValueError):
        raise InputError(f"{where}image_size must be (width, height), not {image_size!r}") from None
    layout = GridLayout(width, height, spacing)
    layout.check_inside(uv, f"{where}uv")
    n = uv.shape[0]
    if n < max(1, min_observations):
        raise TooFewPointsError(
            f"{where}residual grid of {layout.ny} x {layout.nx} nodes",
            n,
            max(1, min_observations),
            "a grid of any spacing needs them: leave the image out",
        )
    _refuse_sparse_data(layout, n, where)
    return uv, res, layout


def supported_spacing(width: int, height: int, n_observations: int) -> float:
    """The smallest spacing (px, 3 significant digits) whose grid the observations support.

    Parameters
    ----------
    width, height : int
        Image size (px).
    n_observations : int
        Residuals of the image.

    Returns
    -------
    float
        px: the grid has at most ``max(FREE_NODES, MAX_NODES_PER_OBSERVATION *
        n_observations)`` nodes.
    """
    most = max(FREE_NODES, MAX_NODES_PER_OBSERVATION * int(n_observations))
    g = float(f"{math.sqrt(width * height / most):.3g}")
    step = 10.0 ** (math.floor(math.log10(g)) - 2)
    while (math.ceil((width - 0.5) / g) + 1) * (math.ceil((height - 0.5) / g) + 1) > most:
        g = round(g + step, 12)  # a few steps at most: the estimate is within a node row
    return g


def _refuse_sparse_data(layout: GridLayout, n: int, where: str) -> None:
    """Refuse a grid of more than ``FREE_NODES`` nodes with more than
    ``MAX_NODES_PER_OBSERVATION`` nodes per observation (``n`` observations)."""
    nodes = layout.n_nodes
    if nodes <= max(FREE_NODES, MAX_NODES_PER_OBSERVATION * n):
        return
    g = supported_spacing(layout.width, layout.height, n)
    raise InputError(
        f"{where}grid spacing {layout.spacing:g} px on a {layout.width} x {layout.height} px "
        f"image gives {layout.ny} x {layout.nx} = {nodes:,} nodes for {n} observations "
        f"({nodes / n:,.0f} nodes per observation; at most {MAX_NODES_PER_OBSERVATION} on "
        f"grids of more than {FREE_NODES:,} nodes): the fit would need about "
        f"{nodes * _BYTES_PER_NODE / 1e9:.1f} GB of memory and the constraints alone would "
        f"fix the nodes; choose a spacing of at least {g:g} px for {n} observations"
    )


def _fit_grid(
    uv,
    residuals,
    image_size,
    spacing,
    *,
    sigma_obs,
    sigma_constraint,
    border,
    min_observations,
    min_support,
    folds,
    snooping,
    alpha,
    max_snooping_rounds,
    max_vce_iterations,
    vce_tol,
    seed,
    image_id,
) -> ResidualGrid:
    where = f"image {image_id}: " if image_id is not None else ""
    uv, res, layout = _image_inputs(uv, residuals, image_size, spacing, min_observations, where)
    n = uv.shape[0]
    s_obs = np.broadcast_to(np.asarray(sigma_obs, dtype=float), (n,)).copy()
    if not np.all(np.isfinite(s_obs) & (s_obs > 0)):
        raise InputError(f"{where}sigma_obs must be positive and finite")
    vce = isinstance(sigma_constraint, str)
    if vce and sigma_constraint != "vce":
        raise InputError(
            f"sigma_constraint must be a number (px) or 'vce', not {sigma_constraint!r}"
        )
    s_c = 1.0 if vce else float(sigma_constraint)
    if not (math.isfinite(s_c) and s_c > 0):
        raise InputError(f"{where}sigma_constraint must be positive and finite")
    if border not in BORDERS:
        raise InputError(f"border must be one of {', '.join(BORDERS)}, not {border!r}")
    check_min_support(min_support)

    C = layout.constraint_matrix(border)
    used = np.ones(n, bool)
    crit = w_critical_value(alpha) if snooping else math.inf
    cells = layout.cell_index(uv)
    vce_its = 0
    w_rejected = np.full(n, np.nan)
    still = np.zeros(n, dtype=bool)
    rounds = 0
    for _round in range(max_snooping_rounds + 1 if snooping else 1):
        k_used = int(used.sum())
        if k_used < max(1, min_observations):
            raise TooFewPointsError(
                f"{where}residual grid after data snooping",
                k_used,
                max(1, min_observations),
                "use a larger spacing, a larger alpha, or leave the image out",
            )
        u_uv, u_l = uv[used], res[used]
        A = layout.design_matrix(u_uv)
        if vce:
            s_obs_u, s_c, vce_its, system, z = _vce(
                layout,
                u_uv,
                u_l,
                s_obs[used],
                s_c,
                border,
                A,
                C,
                max_vce_iterations,
                vce_tol,
                where,
            )
            s_obs[used] = s_obs_u
        else:
            system = FiniteElementSystem(
                layout, u_uv, 1.0 / s_obs[used] ** 2, 1.0 / s_c**2, border, A=A, C=C
            )
            z = system.solve(u_l)
        if not snooping:
            break
        v = np.asarray(A @ z) - u_l
        qvv = s_obs[used] ** 2 - system.observation_cofactors()
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.abs(v) / np.sqrt(np.where(qvv > 1e-12 * s_obs[used] ** 2, qvv, np.nan))[:, None]
        wmax = np.nanmax(np.where(np.isfinite(w), w, -1.0), axis=1)
        flagged = wmax > crit
        if not np.any(flagged) or _round == max_snooping_rounds:  # the last fit stands
            still[np.flatnonzero(used)[flagged]] = True
            break
        rounds += 1
        idx_used = np.flatnonzero(used)
        fi = idx_used[flagged]
        fw = wmax[flagged]
        drop = _local_maxima(layout, cells[fi], fw)
        used[fi[drop]] = False
        w_rejected[fi[drop]] = fw[drop]

    u_uv, u_l = uv[used], res[used]
    A = system.A
    model = np.asarray(A @ z)
    v = model - u_l
    p = 1.0 / s_obs[used] ** 2
    wc = np.asarray(C @ z)
    vtpv = float(np.sum(p[:, None] * v * v) + np.sum(wc * wc) / s_c**2)
    redundancy = 2 * (u_uv.shape[0] + layout.constraint_rank(border) - layout.n_nodes)
    sigma0 = math.sqrt(vtpv / redundancy) if redundancy > 0 else float("nan")

    counts = _node_counts(layout, u_uv)
    rms_before = _rms_len(u_l)
    rms_after = _rms_len(u_l - model)
    cv_before = cv_after = float("nan")
    if folds and folds > 1 and u_uv.shape[0] >= folds:
        cv_before, cv_after = _cross_validate(system, u_uv, u_l, p, A, folds, seed)
    grid = ResidualGrid(
        layout=layout,
        nodes=z.reshape(layout.ny, layout.nx, 2),
        sigma0=sigma0,
        redundancy=int(redundancy),
        sigma_obs=s_obs[used],
        sigma_constraint=s_c,
        support=counts >= min_support,
        counts=counts,
        rms_before=rms_before,
        rms_after=rms_after,
        rms_cv_before=cv_before,
        rms_cv_after=cv_after,
        outliers=~used,
        vce_iterations=vce_its,
        border=border,
        uv=np.array(uv),  # its own copy (may be the caller's array): the cofactors derive from it
        snooping=(
            {
                "test": "w",
                "alpha": float(alpha),
                "critical_value": crit,
                "w": w_rejected,
                "rounds": rounds,
                "still_flagged": still,
            }
            if snooping
            else None
        ),
    )
    _keep_factor(grid, system)
    return grid


#: The factorised normal equations of each grid fitted in this process, held as long as
#: the grid (the grid's object is the key) and within :func:`kept_factor_limit`:
#: :func:`~photogeom.calibration.chain.chain_redundancy` solves with them instead of
#: factorising every grid again (:func:`fitted_solver`).
_FACTORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Estimated bytes of the factors kept now (``_FACTORS``), under ``_KEPT_LOCK``.
_KEPT = {"bytes": 0.0}
_KEPT_LOCK = threading.Lock()
#: Bytes per unknown of a sparse (CHOLMOD or SuperLU) grid factor with its scaled matrix,
#: as measured on 100 px grids of a 7952 x 5304 px image (3.8 MB for 4455 nodes).
KEPT_BYTES_PER_UNKNOWN = 900.0


def kept_factor_limit() -> float:
    """Bytes the factors kept with fitted grids may take together: an eighth of the
    machine's physical memory (a quarter of
    :func:`photogeom.bundle.adjustment.memory_limit`; ``inf`` where the system does not
    say). Grids fitted beyond it keep none;
    the chain of :func:`~photogeom.calibration.readjust` factorises those again (the same
    numbers, more time). Without the limit, 250 grids at 100 px held 0.9 GB, and the fit of
    a 2000-image block would hold 7.6 GB, as long as the grids live."""
    from ..machine import physical_memory

    total = physical_memory()
    return math.inf if total is None else 0.125 * total


def _factor_bytes(system: FiniteElementSystem) -> float:
    """Estimated bytes of what :func:`_keep_factor` keeps of ``system``."""
    f = system.factor
    core = 8.0 * f.n * f.n if f.backend == "dense" else KEPT_BYTES_PER_UNKNOWN * f.n
    AtP = system._AtP
    return core + 12.0 * float(getattr(AtP, "nnz", np.size(AtP))) + system.weights.nbytes


def _release(size: float) -> None:
    with _KEPT_LOCK:
        _KEPT["bytes"] -= size


def _keep_factor(grid: ResidualGrid, system: FiniteElementSystem) -> None:
    """Keep ``system``'s factor with ``grid`` when it is the grid's own (its final
    weights) and the factors kept stay within :func:`kept_factor_limit`."""
    if system.factor is None:
        return
    size = _factor_bytes(system)
    with _KEPT_LOCK:
        if _KEPT["bytes"] + size > kept_factor_limit():
            return
        _KEPT["bytes"] += size
    _FACTORS[grid] = (
        system.weights.copy(),
        system.constraint_weight,
        system._AtP,
        system.factor,
    )
    weakref.finalize(grid, _release, size)


def fitted_solver(grid: ResidualGrid) -> Callable[[np.ndarray], np.ndarray] | None:
    """``l -> node values`` of ``grid``'s fit, ``N^-1 A' P l`` for the residuals ``l``
    (k, c) px at the positions the grid kept, from the factor of its fit (None when the
    grid was not fitted in this process, or its weights were replaced since)."""
    kept = _FACTORS.get(grid)
    if kept is None:
        return None
    w, wc, AtP, factor = kept
    same = (
        w.shape == np.shape(grid.sigma_obs)
        and np.array_equal(w, 1.0 / np.asarray(grid.sigma_obs, dtype=float) ** 2)
        and wc == 1.0 / float(grid.sigma_constraint) ** 2
    )
    if not same:
        return None
    return lambda l: factor.solve(np.asarray(AtP @ l))


def check_min_support(min_support) -> int:
    """``min_support`` as a count of observations (a whole number, 0 or more)."""
    if isinstance(min_support, (bool, np.bool_)) or not isinstance(
        min_support, (int, np.integer)
    ):
        raise InputError(
            f"min_support must be a whole number of observations, not {min_support!r}"
        )
    if min_support < 0:
        raise InputError(
            f"min_support must be 0 or more (observations in a node's cells), not {min_support}"
        )
    return int(min_support)


def _rms_len(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(v * v, axis=1)))) if v.size else float("nan")


def _node_counts(layout: GridLayout, uv: np.ndarray) -> np.ndarray:
    """Observations in the cells adjacent to each node, (ny, nx)."""
    ny, nx = layout.shape
    cells = np.bincount(layout.cell_index(uv), minlength=(ny - 1) * (nx - 1)).reshape(
        ny - 1, nx - 1
    )
    out = np.zeros((ny, nx), dtype=np.int64)
    out[:-1, :-1] += cells
    out[:-1, 1:] += cells
    out[1:, :-1] += cells
    out[1:, 1:] += cells
    return out


def _fold_of(uv: np.ndarray, l: np.ndarray, folds: int, seed) -> np.ndarray:
    """Fold (0 .. folds - 1) of each observation: the observations ranked by a seeded hash of
    their own values (u, v in px, the two residuals in px), every k-th to one fold.

    A random permutation of the row numbers put an observation's fold, and so
    ``rms_cv_after``, at the mercy of the order of the rows (0.1396 px or 0.1408 px for the
    same 400 residuals shuffled); the hash depends on the values alone. Equal observations
    share a hash and are interchangeable, so their order does not matter either.

    Parameters
    ----------
    uv, l : numpy.ndarray, shape (n, 2)
        Image coordinates and residuals (px).
    folds : int
        k >= 2.
    seed : int or None
        Salt of the hash (as ``numpy.random.default_rng(seed)``).

    Returns
    -------
    numpy.ndarray of int, shape (n,)
    """
    n = uv.shape[0]
    bits = np.ascontiguousarray(np.column_stack([uv, l]), dtype=np.float64).view(np.uint64)
    salt = np.random.default_rng(seed).integers(0, 2**63, size=bits.shape[1], dtype=np.uint64)
    h = np.zeros(n, dtype=np.uint64)
    for j in range(bits.shape[1]):  # splitmix64's finaliser of each value, chained
        z = h ^ bits[:, j] ^ salt[j]
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        h = z ^ (z >> np.uint64(31))
    fold_of = np.empty(n, dtype=np.int64)
    fold_of[np.argsort(h, kind="stable")] = np.arange(n) % folds
    return fold_of


def _cross_validate(system, uv, l, p, A, folds, seed):
    """k-fold: refit without each fold by downdating N and the right-hand side."""
    fold_of = _fold_of(uv, l, folds, seed)
    pred = np.empty_like(l)
    AtPl = system._AtP @ l
    for f in range(folds):
        m = fold_of == f
        Af = A[m]
        Nf = system.N - (Af.T.multiply(p[m][None, :]) @ Af)
        bf = AtPl - Af.T @ (p[m][:, None] * l[m])
        try:
            fac = factorize(
                Nf,
                backend=GRID_BACKEND,
                what="normal matrix of the residual grid (cross-validation)",
            )
        except DegenerateGeometryError:  # a fold left the grid undetermined: no estimate
            nan = float("nan")
            return nan, nan
        zf = fac.solve(np.asarray(bf))
        pred[m] = np.asarray(Af @ zf)
    return _rms_len(l), _rms_len(l - pred)


def _local_maxima(layout: GridLayout, cells: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Mask of the flagged points to reject in one snooping round: those whose ``|w|`` is
    the largest of all flagged points in their cell and the 8 cells around it.

    Points of neighbouring cells share nodes, so a blunder inflates their ``|w|`` too; one
    rejection per 3 x 3 cells leaves them to the next round, refitted without the blunder.

    Parameters
    ----------
    layout : GridLayout
    cells : numpy.ndarray of int, shape (k,)
        Cell index (:meth:`GridLayout.cell_index`) of every flagged point.
    w : numpy.ndarray, shape (k,)
        Their ``|w|`` (dimensionless).

    Returns
    -------
    numpy.ndarray of bool, shape (k,)
    """
    ny, nx = layout.ny - 1, layout.nx - 1
    best = np.full(ny * nx, -np.inf)
    np.maximum.at(best, cells, w)
    padded = np.full((ny + 2, nx + 2), -np.inf)
    padded[1:-1, 1:-1] = best.reshape(ny, nx)
    around = np.max(
        [padded[a : a + ny, b : b + nx] for a in range(3) for b in range(3)], axis=0
    ).reshape(-1)
    keep_first = w >= around[cells]
    # one point per cell even when two share the largest |w|
    order = np.flatnonzero(keep_first)
    _, first = np.unique(cells[order], return_index=True)
    out = np.zeros(w.size, dtype=bool)
    out[order[first]] = True
    return out


def _vce(layout, uv, l, s_obs, s_c, border, A, C, max_it, tol, where):
    """Förstner's variance components of two groups: observations and pseudo-observations.

    Only the ratio of the two variances changes the solution, so the estimate is the root
    of ``h(x) = log(ratio_c / ratio_o)`` in ``x = log(sigma_constraint)`` (the observation
    sigmas held), ``ratio_k = v_k' P_k v_k / r_k`` with the redundancy contributions ``r_k``;
    at the root both groups' factors equal, and both sigmas are scaled by that factor. The
    plain Förstner iteration takes the step ``x + h/2`` and converges linearly, slowly when
    one group's redundancy is small, and drifts without end when ``h`` has no root (a grid
    far finer than its observations support). Here ``h`` is evaluated in decades of
    ``sigma_constraint`` from the start until it changes sign, and Brent's method finds the
    root in that decade; without a sign change the error says how close the best ratio came.
    One factorisation per evaluation of ``h``.
    """
    from scipy.optimize import brentq

    from ..errors import ConvergenceError

    # m: the independent constraints; with border="mean" one combination of the rows is
    # zero for every field, so its residual is always zero and it has no redundancy
    n, m, u = uv.shape[0], layout.constraint_rank(border), layout.n_nodes
    p = 1.0 / s_obs**2
    state = {"its": 0}

    def h(x: float) -> float:
        state["its"] += 1
        if state["its"] > max_it:
            raise ConvergenceError(
                f"{where}variance components did not converge in {max_it} evaluations "
                "(give sigma_constraint instead)",
                iterations=max_it,
            )
        sc = math.exp(x)
        system = FiniteElementSystem(layout, uv, p, 1.0 / sc**2, border, A=A, C=C)
        z = system.solve(l)
        v = np.asarray(A @ z) - l
        wc = np.asarray(C @ z)
        t = float(np.sum(p * system.observation_cofactors()))  # tr(N^-1 A'PA)
        r = [2.0 * (n - t), 2.0 * (m - (u - t))]
        q = [float(np.sum(p[:, None] * v * v)), float(np.sum(wc * wc)) / sc**2]
        try:
            _, ratio = update_variance_factors([1.0, 1.0], q, r)
        except InputError as exc:
            raise DegenerateGeometryError(
                f"{where}variance components of the residual grid with sigma_constraint "
                f"{sc:.3g} px: {exc}"
            ) from None
        if ratio[1] <= 0:
            raise DegenerateGeometryError(
                f"{where}variance components: the residuals are reproduced exactly, so the "
                "constraint variance is zero; give sigma_constraint instead of 'vce'"
            )
        state["last"] = (float(ratio[0]), x)
        return math.log(ratio[1] / ratio[0])

    eps = 2.0 * math.log1p(tol)
    x0 = math.log(s_c)
    values = {0: h(x0)}
    root = x0 if abs(values[0]) <= eps else None
    step = math.log(10.0)
    bracket = None
    # search outward in decades, first where Förstner's step points (h > 0: weaker
    # constraints), then the other way, until h changes sign
    first = 1 if values[0] > 0 else -1
    for direction in (first, -first) if root is None else ():
        for k in range(1, 7):
            key = direction * k
            try:
                values[key] = h(x0 + key * step)
            except DegenerateGeometryError:
                break  # beyond what the data determine: no root further out
            prev = values[direction * (k - 1)]
            if abs(values[key]) <= eps:
                root = x0 + key * step
                break
            if prev * values[key] < 0:
                bracket = sorted((x0 + key * step, x0 + (key - direction) * step))
                break
        if root is not None or bracket is not None:
            break
    if root is None and bracket is None:
        best = min(values, key=lambda k: abs(values[k]))
        raise ConvergenceError(
            f"{where}variance components: no ratio of the variances fits these residuals "
            f"(the closest, at sigma_constraint {math.exp(x0 + best * step):.3g} "
            f"px, leaves the factors {math.exp(values[best]):.3g} apart; {n} observations "
            f"for {u} nodes: a grid finer than its data, or a field below the noise): give "
            "sigma_constraint, or a larger spacing",
            iterations=state["its"],
        )
    if root is None:
        root = brentq(h, bracket[0], bracket[1], xtol=1e-3 * tol, rtol=1e-12, maxiter=max_it)
    h(root)  # the factor at the root
    f = state["last"][0]
    s_c_new = math.exp(root) * math.sqrt(f)
    s_obs_new = s_obs * math.sqrt(f)
    system = FiniteElementSystem(layout, uv, 1.0 / s_obs_new**2, 1.0 / s_c_new**2, border, A=A, C=C)
    return s_obs_new, s_c_new, state["its"], system, system.solve(l)


def _reporting(items: list, report: Callable[[int, int], None]):
    """``items`` one by one, calling ``report(done, total)`` before the first and after each
    (when the next is asked for: after the caller's work on it)."""
    report(0, len(items))
    for done, item in enumerate(items, 1):
        yield item
        report(done, len(items))


def progress_over(items: list, progress: bool | Callable[[int, int], None]) -> Iterable:
    """``items`` one by one with the progress of :func:`fit_grids`: ``True`` a progress bar
    (rich) on the terminal, a callable called as ``progress(done, total)`` before the first
    item and after each, ``False`` none."""
    if callable(progress):
        return _reporting(items, progress)
    if progress:
        from rich.progress import track

        return track(items, description="fitting residual grids", transient=True)
    return items


def fit_grids(
    per_image: dict,
    image_size,
    spacing: float,
    *,
    sigma_obs=1.0,
    progress: bool | Callable[[int, int], None] = False,
    **options,
) -> dict:
    """Fit the residual grids of many images, one sparse factorisation each.

    Parameters
    ----------
    per_image : dict
        ``image id -> (uv (n, 2), residuals (n, 2))``, pixels, computed minus observed.
    image_size : (int, int) or dict
        ``(width, height)`` for all images, or ``image id -> (width, height)``.
    spacing : float
        Node spacing (px).
    sigma_obs : float, array or dict
        As :func:`fit_grid` (default 1 px) for all images, or ``image id -> sigma_obs`` of
        that image (its residuals' standard deviations, px: a number or one per residual).
    progress : bool or callable
        ``True``: a progress bar (rich) on the terminal; a callable: called as
        ``progress(done, total)`` (images) before the first and after every image.
    **options
        Passed to :func:`fit_grid` (weights, border, folds, snooping, ...).

    Returns
    -------
    dict
        ``image id -> ResidualGrid``, in the order of ``per_image``.
    """
    # the input of every image is checked before any is fitted: an error in the last of
    # 250 images came after the others were fitted (minutes), now at once
    min_obs = options.get("min_observations", _MIN_OBSERVATIONS)
    by_image = sigma_obs if isinstance(sigma_obs, Mapping) else None
    items = []  # (image id, uv, residuals, size)
    for key, val in per_image.items():
        try:
            uv, res = val
        except (TypeError, ValueError):
            raise InputError(f"image {key}: expected a pair (uv, residuals)") from None
        size = image_size[key] if isinstance(image_size, dict) else image_size
        _image_inputs(uv, res, size, spacing, min_obs, f"image {key}: ")
        if by_image is not None and key not in by_image:
            raise InputError(f"image {key}: sigma_obs gives no standard deviations for it")
        items.append((key, uv, res, size))
    return {
        key: fit_grid(
            uv,
            res,
            size,
            spacing,
            image_id=key,
            sigma_obs=sigma_obs if by_image is None else by_image[key],
            **options,
        )
        for key, uv, res, size in progress_over(items, progress)
    }


def scaled_constraint_sigma(sigma_constraint, spacing) -> float | str:
    """``sigma_constraint`` with ``"scaled"`` resolved to ``0.1 px * (spacing / 100 px)^2``
    (numbers and ``"vce"`` pass through)."""
    if isinstance(sigma_constraint, str) and sigma_constraint == "scaled":
        try:
            g = float(spacing)
        except (TypeError, ValueError):
            return 0.1  # the layout names the bad spacing
        return 0.1 * (g / 100.0) ** 2 if math.isfinite(g) and g > 0 else 0.1
    return sigma_constraint
