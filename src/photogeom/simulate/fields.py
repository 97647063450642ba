"""Smooth random surfaces of the simulator: terrain heights and image-variant local fields.

Both are sums of random plane waves (a truncated random Fourier series), so they are smooth,
cheap to evaluate at any point, vectorised, and fully determined by their coefficients.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from ..errors import InputError
from ..records import ReadOnlyRecord, read_only_fields, setstate_read_only
from ..validation import as_points_single, one_or_many

__all__ = ["LocalDistortionField", "WaveTerrain", "ar1_along_flight", "check_field_options"]

#: Rows per chunk when evaluating many modes at many points (bounds the temporaries).
_CHUNK = 1 << 15


@dataclass(frozen=True, eq=False)
class WaveTerrain(ReadOnlyRecord):
    """Hilly terrain ``Z(X, Y) = base + sum_k a_k cos(2 pi (kx_k X + ky_k Y) + phase_k)``.

    Attributes
    ----------
    base : float
        Mean height, metres.
    freq : (K, 2) spatial frequencies, cycles per metre.
    amplitude, phase : (K,) metres and radians.
    """

    base: float
    freq: np.ndarray
    amplitude: np.ndarray
    phase: np.ndarray

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        extent: tuple[float, float, float, float],
        relief: float,
        base: float = 0.0,
        waves: int = 6,
    ) -> WaveTerrain:
        """Random hills over an extent.

        Wavelengths 0.4 to 1.5 times the extent's diagonal.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the random waves.
        extent : (xmin, xmax, ymin, ymax)
            Ground extent, m.
        relief : float
            Peak-to-peak height on the extent, m.
        base : float, default 0.0
            Height halfway between the lowest and the highest point on the extent, m.
        waves : int, default 6
            Number of cosine waves summed.

        Returns
        -------
        WaveTerrain
        """
        xmin, xmax, ymin, ymax = extent
        diag = float(np.hypot(xmax - xmin, ymax - ymin)) or 1.0
        lam = rng.uniform(0.4, 1.5, waves) * diag
        ang = rng.uniform(0.0, np.pi, waves)
        freq = np.column_stack([np.cos(ang), np.sin(ang)]) / lam[:, None]
        amp = rng.uniform(0.5, 1.0, waves)
        phase = rng.uniform(0.0, 2 * np.pi, waves)
        t = cls(0.0, freq, amp, phase)
        gx, gy = np.meshgrid(np.linspace(xmin, xmax, 101), np.linspace(ymin, ymax, 101))
        z = t(gx.ravel(), gy.ravel())
        span = float(z.max() - z.min())
        scale = relief / span if span > 0 else 0.0
        mid = 0.5 * float(z.max() + z.min()) * scale
        return cls(float(base) - mid, freq, amp * scale, phase)

    def __call__(self, X, Y) -> np.ndarray:
        """Heights (m) at ground positions ``X, Y`` (arrays of one shape)."""
        X = np.asarray(X, dtype=float)
        Y = np.asarray(Y, dtype=float)
        ph = 2 * np.pi * (X[..., None] * self.freq[:, 0] + Y[..., None] * self.freq[:, 1])
        return self.base + np.cos(ph + self.phase) @ self.amplitude


def ar1_along_flight(
    rng: np.random.Generator,
    n: int,
    shape: tuple[int, ...],
    correlation: float,
    *,
    name: str = "correlation",
) -> np.ndarray:
    """Stationary unit-variance AR(1) sequences along the first axis.

    ``x_0 ~ N(0, 1)``, ``x_i = rho x_{i-1} + sqrt(1 - rho^2) e_i``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the draws.
    n : int
        Length of the sequences (images along the flight).
    shape : tuple of int
        Shape of one element of the sequences.
    correlation : float
        ``rho``, the correlation between consecutive elements, in [0, 1).
    name : str, default "correlation"
        The caller's name of ``correlation``, used in the error for a value out of range.

    Returns
    -------
    numpy.ndarray, shape (n, *shape)
        Unitless.

    Raises
    ------
    InputError
        For ``correlation`` outside [0, 1) (the message names ``name``).
    """
    if not 0.0 <= correlation < 1.0:
        raise InputError(
            f"{name} must be in [0, 1) (the correlation between consecutive images), "
            f"got {correlation}"
        )
    e = rng.standard_normal((n, *shape))
    if n == 0 or correlation == 0.0:
        return e
    s = np.sqrt(1.0 - correlation**2)
    e[0] /= s
    return lfilter([s], [1.0, -correlation], e, axis=0)


#: The parameters of :meth:`LocalDistortionField.random` checked by
#: :func:`check_field_options`, by their names there.
_FIELD_NAMES = {n: n for n in ("rms", "modes", "correlation", "static", "slope", "smooth")}

#: Highest wave number of the smooth component (:meth:`LocalDistortionField.random`,
#: ``smooth``): the four waves one cycle long across the image.
SMOOTH_MODES = 1


def check_field_options(
    rms: float,
    modes: int,
    correlation: float,
    static: float,
    slope: float,
    names: dict[str, str] | None = None,
    *,
    smooth: float = 0.0,
) -> None:
    """Refuse field settings :meth:`LocalDistortionField.random` cannot draw from.

    Parameters
    ----------
    rms : float
        RMS of the displacement, px (>= 0).
    modes : int
        Highest wave number (a whole number >= 1).
    correlation : float
        Correlation between consecutive images, in [0, 1).
    static : float
        Share of the variance common to all images, in [0, 1].
    slope : float
        Exponent of the coefficients' fall with the wave number (>= 0).
    names : dict, optional
        The caller's names of these parameters (keys ``rms``, ``modes``, ``correlation``,
        ``static``, ``slope``, ``smooth``), used in the messages; default: the names above.
    smooth : float, default 0.0
        RMS of the smooth component, px (>= 0).

    Raises
    ------
    InputError
        For the first value out of range, named with ``names``.
    """
    nm = {**_FIELD_NAMES, **(names or {})}
    if isinstance(modes, bool) or not float(modes).is_integer() or modes < 1:
        raise InputError(f"{nm['modes']} must be a whole number >= 1, got {modes}")
    if not (np.isfinite(rms) and rms >= 0):
        raise InputError(f"{nm['rms']} must be >= 0 (RMS, pixels), got {rms}")
    if not 0.0 <= correlation < 1.0:
        raise InputError(
            f"{nm['correlation']} must be in [0, 1) (the correlation between consecutive "
            f"images), got {correlation}"
        )
    if not 0.0 <= static <= 1.0:
        raise InputError(f"{nm['static']} must be in [0, 1], got {static}")
    if not (np.isfinite(slope) and slope >= 0):
        raise InputError(f"{nm['slope']} must be >= 0, got {slope}")
    if not (np.isfinite(smooth) and smooth >= 0):
        raise InputError(f"{nm['smooth']} must be >= 0 (RMS, pixels), got {smooth}")


@dataclass(frozen=True, eq=False)
class LocalDistortionField:
    """Image-variant local displacement fields (pixels), one smooth random field per image.

    In image ``i`` the displacement of pixel ``(u, v)`` is

        d(u, v) = sum_k  c[i, k, 0] cos(t_k) + c[i, k, 1] sin(t_k),
        t_k = 2 pi (kx_k u / width + ky_k v / height)

    with ``c[i, k, j]`` a 2-vector (du, dv). Wave numbers are whole numbers
    ``0 <= kx <= modes``, ``-modes <= ky <= modes`` (one half-plane, no constant term), so the
    shortest wavelength is ``width / modes`` along u. The coefficients' standard deviation
    falls as ``1 / |k|**slope`` (wave-number magnitude; ``slope`` 1 by default: about equal
    variance per octave of wavelength; larger slopes put the variance into the longest
    waves) and is scaled so that the expected RMS length of the displacement over an image
    is ``rms``. Along the flight the coefficients follow a
    stationary AR(1) process with the given correlation between consecutive images, plus an
    optional static part shared by all images.

    An optional smooth component of RMS ``smooth`` adds to the four longest waves
    (``max(|kx|, |ky|) <= 1``, one cycle across the image) coefficients drawn the same way
    (standard deviation ``1 / |k|``, the same correlation and static share) and independent
    of the first: a smooth image-variant deformation beside a finer field. The two add up to
    one field of the same form whose coefficients have the variances of both
    (:meth:`coefficient_std`), and an expected mean square length of ``rms**2 + smooth**2``.

    Attributes
    ----------
    image_ids : (m,) ids of the images, in flight order.
    width, height : float
        Image size, pixels.
    waves : (K, 2) integer wave numbers (kx, ky).
    coef : (m, K, 2, 2) coefficients: image, mode, (cos, sin), (du, dv), pixels.
    rms : float
        The nominal RMS length of the first component (spectrum ``1 / |k|**slope`` up to
        ``modes``), pixels.
    correlation, static : float
        The distribution the coefficients were drawn from along the flight: AR(1)
        correlation between consecutive images and the share of the variance common to all
        images (:meth:`image_covariance`).
    slope : float
        Exponent of the coefficients' fall with the wave number (:meth:`coefficient_std`).
    smooth : float
        The nominal RMS length of the smooth component, pixels (0: none).
    """

    image_ids: np.ndarray
    width: float
    height: float
    waves: np.ndarray
    coef: np.ndarray
    rms: float
    correlation: float = 0.0
    static: float = 0.0
    slope: float = 1.0
    smooth: float = 0.0

    def __post_init__(self) -> None:
        # read-only views: the simulated observations were made from these coefficients
        read_only_fields(self)

    def __setstate__(self, state: dict) -> None:
        setstate_read_only(self, state)  # pickle / deepcopy: the arrays stay read-only

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        image_ids,
        width: float,
        height: float,
        *,
        rms: float,
        modes: int = 6,
        correlation: float = 0.9,
        static: float = 0.0,
        slope: float = 1.0,
        smooth: float = 0.0,
    ) -> LocalDistortionField:
        """Random fields for images in flight order (see the class docstring).

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the random coefficients.
        image_ids : sequence
            Image ids, in flight order.
        width, height : float
            Image size, px.
        rms : float
            RMS of the displacement, px (>= 0).
        modes : int, default 6
            Highest wave number (>= 1).
        correlation : float, default 0.9
            Correlation of a coefficient between consecutive images.
        static : float, default 0.0
            Share of the variance common to all images, in [0, 1].
        slope : float, default 1.0
            Exponent (>= 0) of the coefficients' fall with the wave number.
        smooth : float, default 0.0
            RMS of the smooth component, px (>= 0): independent coefficients of the four
            longest waves, drawn after the first component's (0 draws nothing, so the
            first component and everything drawn later from ``rng`` are as without it).
            With ``rms`` 0 the field has only these four waves.

        Returns
        -------
        LocalDistortionField

        Raises
        ------
        InputError
            For a value out of range; the message names the parameter of this method
            (:func:`check_field_options` with the names of the caller's options).
        """
        check_field_options(rms, modes, correlation, static, slope, smooth=smooth)
        if not all(np.isfinite(v) and v > 0 for v in (width, height)):
            raise InputError(
                f"width and height must be > 0 (image size, pixels), got {width}, {height}"
            )
        ids = np.asarray(image_ids)
        modes = int(modes) if rms > 0 or smooth == 0 else SMOOTH_MODES
        kx, ky = np.meshgrid(np.arange(0, modes + 1), np.arange(-modes, modes + 1), indexing="ij")
        kx, ky = kx.ravel(), ky.ravel()
        half = (kx > 0) | ((kx == 0) & (ky > 0))
        waves = np.column_stack([kx[half], ky[half]])
        K = waves.shape[0]
        varying = ar1_along_flight(rng, ids.size, (K, 2, 2), correlation)
        common = rng.standard_normal((1, K, 2, 2))
        c = np.sqrt(1.0 - static) * varying + np.sqrt(static) * common
        coef = c * _wave_std(waves, rms, slope)[None, :, None, None]
        if smooth > 0:
            sel = _smooth_waves(waves)
            ks = int(np.sum(sel))
            varying = ar1_along_flight(rng, ids.size, (ks, 2, 2), correlation)
            common = rng.standard_normal((1, ks, 2, 2))
            c = np.sqrt(1.0 - static) * varying + np.sqrt(static) * common
            coef[:, sel] += c * _wave_std(waves[sel], smooth)[None, :, None, None]
        return cls(
            ids,
            float(width),
            float(height),
            waves,
            coef,
            float(rms),
            correlation,
            static,
            float(slope),
            float(smooth),
        )

    @classmethod
    def zero(cls, image_ids, width: float, height: float) -> LocalDistortionField:
        """No local displacement in any image.

        Parameters
        ----------
        image_ids : sequence
            Image ids.
        width, height : float
            Image size, px.

        Returns
        -------
        LocalDistortionField
        """
        ids = np.asarray(image_ids)
        return cls(
            ids, float(width), float(height), np.zeros((0, 2)), np.zeros((ids.size, 0, 2, 2)), 0.0
        )

    def coefficient_std(self) -> np.ndarray:
        """Standard deviation of the cos, then the sin coefficients of each wave, as drawn.

        The same for du and dv; with a smooth component, the root sum of squares of both
        components' (they are independent).

        Returns
        -------
        numpy.ndarray, shape (2K,)
            px.
        """
        std = _wave_std(self.waves, self.rms, self.slope)
        if self.smooth > 0:
            sel = _smooth_waves(self.waves)
            add = np.zeros_like(std)
            add[sel] = _wave_std(self.waves[sel], self.smooth)
            std = np.sqrt(std**2 + add**2)
        return np.tile(std, 2)

    @property
    def total_rms(self) -> float:
        """The expected RMS length of the whole field, ``sqrt(rms**2 + smooth**2)``, px."""
        return float(np.hypot(self.rms, self.smooth))

    def image_covariance(self, image_rows: np.ndarray) -> np.ndarray:
        """Correlation of one coefficient between images.

        ``(1 - static) correlation^|i - j| + static`` for the images at flight positions ``i``,
        ``j``.

        Parameters
        ----------
        image_rows : numpy.ndarray of int, shape (n,)
            Flight positions of the images (see :meth:`image_rows`).

        Returns
        -------
        numpy.ndarray, shape (n, n)
            Unitless.
        """
        r = np.asarray(image_rows)
        lag = np.abs(r[:, None] - r[None, :])
        return (1.0 - self.static) * self.correlation**lag + self.static

    def basis(self, uv) -> np.ndarray:
        """The functions the coefficients multiply.

        ``d = basis @ [c[:, 0, j]; c[:, 1, j]]`` for coordinate j.

        Parameters
        ----------
        uv : array_like, shape (n, 2)
            Pixels (col, row).

        Returns
        -------
        numpy.ndarray, shape (n, 2K)
            ``cos(t_k)`` then ``sin(t_k)`` of the K waves, unitless.
        """
        a = np.asarray(uv, dtype=float).reshape(-1, 2)
        t = 2.0 * np.pi * (
            np.outer(a[:, 0], self.waves[:, 0]) / self.width
            + np.outer(a[:, 1], self.waves[:, 1]) / self.height
        )
        return np.concatenate([np.cos(t), np.sin(t)], axis=1)

    def image_rows(self, image_ids) -> np.ndarray:
        """Flight positions (rows of :attr:`coef`) of ``image_ids``.

        Parameters
        ----------
        image_ids : sequence or numpy.ndarray
            Image ids of the field.

        Returns
        -------
        numpy.ndarray of int, shape (n,)

        Raises
        ------
        InputError
            Naming the first id that is not an image of the field.
        """
        flat = np.asarray(image_ids).reshape(-1)
        order = np.argsort(self.image_ids, kind="stable")
        keys = self.image_ids[order]
        pos = np.clip(np.searchsorted(keys, flat), 0, max(keys.size - 1, 0))
        if keys.size == 0 or not np.all(keys[pos] == flat):
            bad = flat[~(keys[pos] == flat)] if keys.size else flat
            raise InputError(
                f"local_field: unknown image id {str(bad[0])!r} (not an image of the "
                "simulated block)"
            )
        return order[pos]

    def rows(self, image_rows: np.ndarray, uv) -> np.ndarray:
        """Displacements at pixels of given image rows, vectorised over observations.

        Parameters
        ----------
        image_rows : numpy.ndarray of int, shape (n,)
            Positions in :attr:`image_ids` of each observation's image.
        uv : array_like, shape (n, 2)
            Pixels (col, row).

        Returns
        -------
        numpy.ndarray, shape (n, 2)
            ``(du, dv)``, px.
        """
        uv_all = np.asarray(uv, dtype=float).reshape(-1, 2)
        r = np.asarray(image_rows, dtype=np.int64).reshape(-1)
        out = np.zeros((uv_all.shape[0], 2))
        if self.waves.shape[0] == 0 or uv_all.shape[0] == 0:
            return out
        kmax = int(np.max(np.abs(self.waves)))
        kx = self.waves[:, 0].astype(np.int64)
        ky = self.waves[:, 1].astype(np.int64) + kmax
        hu = 2 * np.pi * np.arange(kmax + 1) / self.width
        hv = 2 * np.pi * np.arange(-kmax, kmax + 1) / self.height
        order = np.argsort(r, kind="stable")
        rs = r[order]
        cuts = np.flatnonzero(np.diff(rs)) + 1
        starts = np.concatenate([[0], cuts])
        stops = np.concatenate([cuts, [rs.size]])
        for s0, s1 in zip(starts, stops):  # one matrix product per image, not per row
            c = self.coef[rs[s0]]  # (K, 2, 2)
            c2 = np.ascontiguousarray(np.concatenate([c[:, 0], c[:, 1]]))  # (2K, 2)
            for b0 in range(s0, s1, _CHUNK):
                b1 = min(b0 + _CHUNK, s1)
                idx = order[b0:b1]
                # cos/sin of t = a + b from the harmonics of u and v separately
                a = np.multiply.outer(uv_all[idx, 0], hu)
                b = np.multiply.outer(uv_all[idx, 1], hv)
                ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
                ca, sa, cb, sb = ca[:, kx], sa[:, kx], cb[:, ky], sb[:, ky]
                cs = np.concatenate([ca * cb - sa * sb, sa * cb + ca * sb], axis=1)
                out[idx] = cs @ c2
        return out

    def __call__(self, image_id, uv) -> np.ndarray:
        """Displacement (n, 2) px at pixels ``uv`` (n, 2) of image ``image_id`` (one id, or
        one per row of ``uv``); (2,) for a single point ``uv`` (2,)."""
        a, single = as_points_single(uv, 2, "uv", finite=False)
        ids = np.asarray(image_id)
        flat = np.broadcast_to(ids.reshape(-1) if ids.ndim else ids, (a.shape[0],))
        return one_or_many(self.rows(self.image_rows(flat), a), single)


def _smooth_waves(waves: np.ndarray) -> np.ndarray:
    """(K,) bool: the waves of the smooth component, ``max(|kx|, |ky|) <= SMOOTH_MODES``."""
    return np.max(np.abs(waves), axis=1) <= SMOOTH_MODES


def _wave_std(waves: np.ndarray, rms: float, slope: float = 1.0) -> np.ndarray:
    """(K,) standard deviation (px) of each wave's coefficients: proportional to
    ``1 / |k|**slope``, scaled so that the expected RMS length of the displacement is
    ``rms``."""
    w = np.hypot(waves[:, 0], waves[:, 1]) ** -float(slope)
    return (rms / np.sqrt(2.0 * np.sum(w**2))) * w
