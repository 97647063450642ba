"""3D affine (12-parameter) transformation ``X = A x + t`` and its decomposition."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..records import ReadOnlyRecord
from ..rotation import DEFAULT_CONVENTION, Convention, angles_from_rotation, rotation_from_angles
from ._common import MatrixShift3D, fmt_params, frozen, invertible, matrix_and_shift, vector
from .base import Transform
from .similarity3d import Similarity3D

_PARAM_NAMES = (
    "a11", "a12", "a13", "a21", "a22", "a23", "a31", "a32", "a33", "tx", "ty", "tz",
)
_TEXTBOOK_NAMES = (
    "sx", "sy", "sz", "shear_xy", "shear_xz", "shear_yz", "omega", "phi", "kappa", "tx", "ty", "tz",
)


@dataclass(frozen=True, eq=False)
class AffineDecomposition(ReadOnlyRecord):
    """``A = shear @ diag(scales) @ rotation`` (see :meth:`Affine3D.decompose`).

    Attributes
    ----------
    rotation : numpy.ndarray, shape (3, 3)
        Proper rotation (det +1).
    scales : numpy.ndarray, shape (3,)
        ``sx, sy, sz`` (``sz < 0`` for a reflection, ``det(A) < 0``).
    shears : numpy.ndarray, shape (3,)
        ``shear_xy, shear_xz, shear_yz``: the off-diagonal elements of the unit upper
        triangular ``shear = [[1, xy, xz], [0, 1, yz], [0, 0, 1]]``.
    det : float
        ``det(A) = sx sy sz``: the volume scale.
    """

    rotation: np.ndarray
    scales: np.ndarray
    shears: np.ndarray
    det: float

    @property
    def shear_matrix(self) -> np.ndarray:
        """The unit upper triangular shear matrix."""
        xy, xz, yz = self.shears
        return np.array([[1.0, xy, xz], [0.0, 1.0, yz], [0.0, 0.0, 1.0]])

    def compose(self) -> np.ndarray:
        """``shear @ diag(scales) @ rotation`` (= the original ``A``).

        Returns
        -------
        numpy.ndarray, shape (3, 3)
        """
        return self.shear_matrix @ np.diag(self.scales) @ self.rotation


@dataclass(frozen=True, eq=False, repr=False)
class Affine3D(MatrixShift3D, Transform):
    """3D affine transformation ``X = A @ x + t``.

    Parametric form: the nine elements ``a11 .. a33`` of ``A`` and ``tx, ty, tz``.
    Textbook form (:meth:`decompose`)::

        A = [[1, shear_xy, shear_xz], [0, 1, shear_yz], [0, 0, 1]] @ diag(sx, sy, sz) @ R

    with ``R`` a proper rotation whose angles ``omega, phi, kappa`` follow the ``"transposed"``
    convention (``R = M(omega, phi, kappa).T``), as :class:`Similarity3D`. With ``A.T A = a I``
    the transformation is a similarity, with ``A.T A = I`` rigid; :meth:`similarity_deviation`
    says how far it is from a similarity.

    Parameters
    ----------
    linear : array_like, shape (3, 3)
        ``A`` (unitless).
    translation : array_like, shape (3,)
        ``t`` in target units.
    """

    name = "affine3d"
    dim = 3
    _linear_indices = tuple(range(9))

    linear: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        A, t = matrix_and_shift(self.linear, self.translation, "Affine3D", "linear part")
        object.__setattr__(self, "linear", frozen(A))
        object.__setattr__(self, "translation", frozen(t))

    @classmethod
    def from_matrix(cls, M) -> Affine3D:
        """From a 3x4 ``[A | t]`` or a homogeneous 4x4 matrix (last row ``0 0 0 1``).

        Parameters
        ----------
        M : array_like, shape (3, 4) or (4, 4)
            The matrix; translation in target units.

        Returns
        -------
        Affine3D

        Raises
        ------
        InputError
            For another shape, or a 4x4 matrix whose last row is not ``0 0 0 1``.
        """
        M = np.asarray(M, dtype=float)
        if M.shape == (4, 4):
            if not np.allclose(M[3], [0, 0, 0, 1]):
                raise InputError("Affine3D: the last row of a 4x4 affine matrix must be 0 0 0 1")
            M = M[:3]
        if M.shape != (3, 4):
            raise InputError(f"Affine3D: expected a 3x4 or 4x4 matrix, got shape {M.shape}")
        return cls(M[:, :3], M[:, 3])

    @classmethod
    def from_textbook(
        cls,
        scales,
        shears,
        omega: float,
        phi: float,
        kappa: float,
        translation,
        *,
        convention: Convention = DEFAULT_CONVENTION,
        unit: str = "rad",
    ) -> Affine3D:
        """From scales, shears, angles (``unit``, ``convention``) and translation.

        ``A = shear @ diag(scales) @ R(omega, phi, kappa)``.

        Parameters
        ----------
        scales : array_like, shape (3,)
            ``(sx, sy, sz)``, unitless.
        shears : array_like, shape (3,)
            ``(xy, xz, yz)``: the upper entries of the unit upper-triangular shear matrix.
        omega, phi, kappa : float
            Rotation angles in ``unit``.
        translation : array_like, shape (3,)
            ``t``, target units.
        convention : {"transposed", "direct"}, default "transposed"
            As in :func:`photogeom.rotation_from_angles`.
        unit : str, default "rad"
            Angle unit.

        Returns
        -------
        Affine3D
        """
        s = vector(scales, 3, "Affine3D scales")
        xy, xz, yz = vector(shears, 3, "Affine3D shears")
        S = np.array([[1.0, xy, xz], [0.0, 1.0, yz], [0.0, 0.0, 1.0]])
        R = rotation_from_angles(omega, phi, kappa, convention=convention, unit=unit)
        return cls(S @ np.diag(s) @ R, translation)

    @property
    def det(self) -> float:
        """``det(A)``: the volume scale (negative for a reflection)."""
        return float(np.linalg.det(self.linear))

    @property
    def singular(self) -> bool:
        """``True`` when the linear part is singular to rounding (``|det(A)| <= 1e-14
        max|A|^3``): the transformation maps space onto a plane or a line (e.g. fitted to
        coplanar target points), it has no inverse and no textbook decomposition."""
        A = self.linear
        return bool(abs(self.det) <= 1e-14 * max(np.max(np.abs(A)) ** 3, 1e-300))

    def decompose(self) -> AffineDecomposition:
        """``A = shear @ diag(scales) @ rotation`` by an RQ decomposition.

        Unique with ``sx, sy > 0``, a proper rotation, and ``sz`` carrying the sign of
        ``det(A)``.

        Returns
        -------
        AffineDecomposition
            ``scales``, ``shears``, ``rotation`` (and ``shear_matrix``).

        Raises
        ------
        InputError
            For a singular ``A`` (see :attr:`singular`).
        """
        A = self.linear
        if self.singular:
            raise InputError(
                "Affine3D: the linear part is singular (it maps space onto a plane or a line, "
                "e.g. fitted to coplanar target points); scales, shears and angles are "
                "undefined, it has no decomposition"
            )
        import scipy.linalg  # imported here: applying a transformation needs no scipy

        K, Q = scipy.linalg.rq(A)
        D = np.sign(np.diag(K))  # make the triangular diagonal positive: A = (K D) (D Q)
        K, Q = K * D, D[:, None] * Q
        if np.linalg.det(Q) < 0:  # proper rotation; the reflection goes into sz
            Q[2] = -Q[2]
            K[:, 2] = -K[:, 2]
        scales = np.diag(K).copy()
        shear = K / scales
        return AffineDecomposition(
            rotation=Q,
            scales=scales,
            shears=np.array([shear[0, 1], shear[0, 2], shear[1, 2]]),
            det=self.det,
        )

    def similarity_deviation(self) -> dict:
        """How far ``A`` is from a similarity ``s R``.

        Returns
        -------
        dict
            ``singular_values`` of ``A``; ``anisotropy`` = largest / smallest singular value
            minus 1 (0 for a similarity); ``nearest_similarity``: the :class:`Similarity3D`
            ``s R`` closest to ``A`` in the Frobenius norm (``R`` from the polar decomposition,
            ``s = trace(R.T A) / 3``, same translation); ``relative_deviation`` =
            ``|A - s R|_F / |A|_F``; ``max_scale_ratio`` = max/min of the decomposition scales;
            ``max_shear`` = largest absolute shear.
        """
        A = self.linear
        U, sv, Vt = np.linalg.svd(A)
        if np.linalg.det(U @ Vt) < 0:
            raise InputError("Affine3D: det(A) < 0 (a reflection); no similarity is near it")
        R = U @ Vt
        s = float(np.trace(R.T @ A) / 3.0)
        dec = self.decompose()
        sc = np.abs(dec.scales)
        return {
            "singular_values": sv,
            "anisotropy": float(sv[0] / sv[-1] - 1.0),
            "nearest_similarity": Similarity3D(s, R, self.translation),
            "relative_deviation": float(np.linalg.norm(A - s * R) / np.linalg.norm(A)),
            "max_scale_ratio": float(sc.max() / sc.min()),
            "max_shear": float(np.max(np.abs(dec.shears))),
        }

    def textbook(self, convention: Convention = DEFAULT_CONVENTION) -> dict[str, float]:
        """Scales, shears, rotation angles (rad, ``convention``) and shifts.

        Parameters
        ----------
        convention : {"transposed", "direct"}, default "transposed"
            Convention of the angles (see :func:`photogeom.rotation_from_angles`); at gimbal
            lock omega is set to zero.

        Returns
        -------
        dict of str to float
            ``sx, sy, sz, shear_xy, shear_xz, shear_yz`` (unitless), ``omega, phi, kappa``
            (rad), ``tx, ty, tz`` (target units).

        Raises
        ------
        InputError
            For a singular linear part (see :meth:`decompose`).
        """
        dec = self.decompose()
        w, p, k = angles_from_rotation(dec.rotation, convention=convention,
                                       on_gimbal_lock="omega-zero")
        vals = [*dec.scales, *dec.shears, w, p, k, *self.translation]
        return {n: float(v) for n, v in zip(_TEXTBOOK_NAMES, vals)}

    @property
    def textbook_units(self) -> dict[str, str]:
        units = dict.fromkeys(_TEXTBOOK_NAMES[:6], "1")
        units.update(dict.fromkeys(("omega", "phi", "kappa"), "rad"))
        units.update(dict.fromkeys(("tx", "ty", "tz"), ""))
        return units

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return _PARAM_NAMES

    @property
    def _matrix3(self) -> np.ndarray:
        return self.linear

    def inverse(self) -> Affine3D:
        """Closed form ``x = A^-1 (X - t)``.

        Returns
        -------
        Affine3D

        Raises
        ------
        DegenerateGeometryError
            When the linear part is singular.
        """
        Ai = invertible(self.linear, "Affine3D")
        return Affine3D(Ai, -Ai @ self.translation)

    def to_dict(self) -> dict:
        """JSON-ready parameters.

        Returns
        -------
        dict
            ``model, linear (3x3 list), translation, det``.
        """
        return {
            "model": self.name,
            "linear": self.linear.tolist(),
            "translation": self.translation.tolist(),
            "det": self.det,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Affine3D:
        """From :meth:`to_dict` output or a ``matrix`` (3x4 or 4x4).

        Parameters
        ----------
        data : dict
            ``matrix``, else ``linear`` and ``translation``.

        Returns
        -------
        Affine3D

        Raises
        ------
        InputError
            For a ``matrix`` of the wrong shape (see :meth:`from_matrix`).
        KeyError
            When ``linear`` or ``translation`` is missing.
        """
        if "matrix" in data:
            return cls.from_matrix(data["matrix"])
        return cls(data["linear"], data["translation"])

    def __repr__(self) -> str:
        return f"Affine3D({fmt_params(_PARAM_NAMES, self.parameters)}; det={self.det:.9g})"
