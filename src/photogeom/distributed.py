"""Out of core and distributed: Dask arrays and per-item jobs on ``dask.distributed``.

* :func:`map_items` - run a function over many items (files, images) as Dask tasks on a
  local cluster or a scheduler, with progress and per-item failures collected instead of
  stopping the whole job;
* :func:`transform_array` - apply a transformation to a ``dask.array`` of points (n, 3);
* :func:`absolute_orientation` - the absolute orientation of two ``dask.array`` point sets
  in one pass over the data (moments per block, merged exactly);
* :func:`register_clouds` - absolute orientation of one LAS/LAZ cloud to another from
  corresponding points, with check-pair statistics;
* :func:`localize_files`, :func:`resect_images` - per-image jobs of a block (RPC
  localisation in many files, space resection of many images) on :func:`map_items`;
* :func:`scheduler_client` - the Dask client for a ``scheduler=`` value.

``scheduler`` values (also ``--scheduler`` on the command line):

=====================  ======================================================================
``None``/``"local"``   a ``distributed.LocalCluster`` of processes on this machine (one
                       single-threaded worker per core), started and closed by the call
``"local:N"``          the same with N workers
``"tcp://host:8786"``  an existing ``dask.distributed`` scheduler (a real cluster)
``"threads"``          Dask's threaded scheduler in this process (no ``distributed``)
``"sync"``             everything in this process, one item after another (debugging)
=====================  ======================================================================

Dask is an optional extra: ``pip install "photogeom[dask]"``.
"""

from __future__ import annotations

import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import FileFormatError, InputError, PhotogeomError
from .records import ReadOnlyRecord

__all__ = [
    "CloudRegistration",
    "ItemFailure",
    "MapResult",
    "absolute_orientation",
    "localize_files",
    "map_items",
    "register_clouds",
    "resect_images",
    "scheduler_client",
    "transform_array",
]


def _dask():
    """``(dask.array, dask.delayed)``, or an error naming the extra to install."""
    try:
        import dask.array as da
        from dask import delayed
    except ImportError:  # pragma: no cover - depends on the installation
        raise PhotogeomError(
            "out-of-core and distributed processing need Dask: pip install 'photogeom[dask]'"
        ) from None
    return da, delayed


def _distributed():
    try:
        import distributed
    except ImportError:  # pragma: no cover - depends on the installation
        raise PhotogeomError(
            "a Dask cluster needs dask.distributed: pip install 'photogeom[dask]'"
        ) from None
    return distributed


def _parse_scheduler(scheduler: str | None) -> tuple[str, Any]:
    if scheduler is None or scheduler == "local":
        return "local", None
    if not isinstance(scheduler, str):
        return "client", scheduler  # a distributed.Client given directly
    s = scheduler.strip()
    if s.startswith("local:"):
        try:
            n = int(s.split(":", 1)[1])
        except ValueError:
            n = 0
        if n < 1:
            raise InputError(f"scheduler {scheduler!r}: 'local:N' needs a worker count N >= 1")
        return "local", n
    if s in ("threads", "sync", "synchronous"):
        return "threads" if s == "threads" else "sync", None
    if "://" in s or ":" in s:
        return "address", _check_address(scheduler, s)
    raise InputError(
        f"scheduler {scheduler!r}: give 'local', 'local:N', 'threads', 'sync' or a scheduler "
        "address such as tcp://host:8786"
    )


#: Schemes of ``dask.distributed`` scheduler addresses accepted as ``scheduler=``.
_ADDRESS_SCHEMES = ("tcp", "tls", "ucx", "ws", "wss", "inproc")

#: Wall-clock limit (s) on connecting to a scheduler address: the TCP connection, the
#: handshake and the first reply together.
CONNECT_TIMEOUT = 10.0


def _check_address(given: str, s: str) -> str:
    """``s`` (``scheme://host:port`` or ``host:port``) checked for its form; the address with
    its scheme (``tcp://`` when none is given), or an :class:`InputError` naming the problem.
    """
    form = (
        "give the scheduler address as tcp://host:port (also tls://host:port, or host:port), "
        "e.g. tcp://127.0.0.1:8786"
    )
    scheme, sep, rest = s.partition("://")
    if not sep:
        scheme, rest = "tcp", s
    scheme = scheme.lower()
    if scheme in ("http", "https"):
        raise InputError(
            f"scheduler {given!r} is a web address (the Dask dashboard, usually port 8787), "
            f"not a scheduler: {form}; the scheduler's address is printed when it starts "
            "(usually port 8786)"
        )
    if scheme not in _ADDRESS_SCHEMES:
        raise InputError(f"scheduler {given!r}: unknown address scheme {scheme + '://'!r}; {form}")
    if scheme == "inproc":  # a scheduler in this process (LocalCluster(processes=False))
        return f"{scheme}://{rest}"
    host, colon, port = rest.rpartition(":")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]  # IPv6 literal
    if "/" in rest or any(c.isspace() for c in rest):
        problem = "a path or blank after the scheme"
    elif not colon:
        problem = "no port"
    elif not host:
        problem = "no host"
    elif not (port.isdigit() and 0 < int(port) < 65536):
        problem = f"port {port!r} is not a number from 1 to 65535"
    else:
        return f"{scheme}://{rest}"
    raise InputError(f"scheduler {given!r} is not a scheduler address ({problem}); {form}")


def _connect(distributed, address: str, timeout: float):
    """A ``distributed.Client`` connected to ``address`` within ``timeout`` seconds of wall
    time, or a :class:`PhotogeomError` naming the address and what to check.

    ``Client(address, timeout=...)`` bounds only the TCP connection: a server that accepts
    it but never answers the handshake (a plain listener, the dashboard's HTTP port, another
    service) keeps the client waiting for ever, and one that sends something else can fail
    with any exception (``MemoryError`` for a banner read as a message length). Here the whole
    start (connection, handshake, first reply) runs under one deadline; a client that did
    not start is closed before the error is raised.
    """

    class _DeadlineClient(distributed.Client):
        def start(self, **kwargs):
            # Client.start passes callback_timeout to distributed.utils.sync, which cancels
            # the start coroutine and raises TimeoutError when it runs out
            kwargs.setdefault("callback_timeout", timeout)
            try:
                super().start(**kwargs)
            except BaseException:
                try:
                    self.close(timeout=min(timeout, 5.0))
                except Exception:  # pragma: no cover - best effort on a failed start
                    pass
                raise

    _DeadlineClient.__name__ = _DeadlineClient.__qualname__ = "Client"
    check = (
        "is a Dask scheduler running there (dask scheduler, or distributed.LocalCluster) "
        "and is this its scheduler port (usually 8786, not the dashboard's 8787)? "
        "(--scheduler local runs a cluster on this machine)"
    )
    try:
        return _DeadlineClient(address, timeout=timeout)
    except (TimeoutError, OSError) as exc:
        timed_out = isinstance(exc, TimeoutError) or "Timed out" in str(exc)
        what = (
            f"no answer from a Dask scheduler within {timeout:g} s"
            if timed_out
            else f"cannot connect ({exc})"
        )
        raise PhotogeomError(f"Dask scheduler at {address}: {what}; {check}") from None
    except Exception as exc:
        detail = (
            "it sent data that is not a Dask message"  # a banner read as a message length
            if isinstance(exc, MemoryError)
            else f"{type(exc).__name__}: {exc}"
        )
        raise PhotogeomError(
            f"Dask scheduler at {address}: the server there did not answer as a Dask "
            f"scheduler ({detail}); {check}"
        ) from None


def connect_to_scheduler(address: str):
    """A ``distributed.Client`` connected to the scheduler at ``address``: the address form
    checked first (:class:`InputError`), then the whole start under one deadline of
    :data:`CONNECT_TIMEOUT` seconds (:class:`PhotogeomError` naming the address). The
    caller closes it."""
    return _connect(_distributed(), _check_address(address, address.strip()), CONNECT_TIMEOUT)


def _local_cluster_message(n: int, exc: BaseException) -> str:
    """Why a local cluster of ``n`` worker processes did not start, and what to do."""
    return (
        f"a local Dask cluster of {n} worker process(es) (scheduler 'local', --scheduler "
        f"local) did not start ({type(exc).__name__}: {exc}). Its workers are new Python "
        "processes that import the program's main module again: in a script, put the code "
        "that calls photogeom under 'if __name__ == \"__main__\":'; or run in this process "
        "with scheduler='threads' (--scheduler threads)"
    )


@contextmanager
def scheduler_client(scheduler: str | None = None) -> Iterator[Any]:
    """A ``distributed.Client`` for ``scheduler`` (None for ``"threads"``/``"sync"``).

    A local cluster is started for the duration of the ``with`` block and closed after it;
    an address connects to a running scheduler (left running).

    Parameters
    ----------
    scheduler : str or distributed.Client, optional
        See the module docstring. An address is ``tcp://host:port``, ``tls://host:port``
        or ``host:port`` (``tcp://`` then).

    Yields
    ------
    distributed.Client or None
        The client (closed with its local cluster, if one was started, when the block
        ends); None for ``"threads"`` and ``"sync"``.

    Raises
    ------
    InputError
        ``scheduler`` is not one of the accepted forms (e.g. ``http://...``, the dashboard,
        or ``host:notaport``).
    PhotogeomError
        The client did not connect to the address within :data:`CONNECT_TIMEOUT` seconds of
        wall time (nothing listening, a server that does not answer or is not a Dask
        scheduler); the message names the address and what to check. Or a local cluster did
        not start its worker processes (most often a script without an
        ``if __name__ == "__main__":`` guard: the workers import the main module again and
        would start a cluster of their own); the message names the guard and
        ``scheduler="threads"``.
    """
    kind, arg = _parse_scheduler(scheduler)
    if kind in ("threads", "sync"):
        yield None
        return
    if kind == "client":
        yield arg
        return
    distributed = _distributed()
    if kind == "address":
        client = _connect(distributed, arg, CONNECT_TIMEOUT)
        try:
            yield client
        finally:
            client.close()
        return
    n = arg or max(1, os.cpu_count() or 1)
    try:
        cluster = distributed.LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=None,
            silence_logs=40,
        )
    except Exception as exc:
        raise PhotogeomError(_local_cluster_message(n, exc)) from exc
    client = distributed.Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def _compute(*collections, scheduler: str | None):
    """``dask.compute`` on the scheduler named."""
    import dask

    kind, _ = _parse_scheduler(scheduler)
    if kind in ("threads", "sync"):
        return dask.compute(*collections, scheduler="threads" if kind == "threads" else "sync")
    with scheduler_client(scheduler) as client:
        return client.compute(list(collections), sync=True)


# --- per-item jobs ------------------------------------------------------------------------------


@dataclass(frozen=True)
class ItemFailure:
    """One item whose function raised.

    Attributes
    ----------
    index : int
        Position in the input.
    item : object
        The item.
    error : str
        ``"ExceptionType: message"``.
    traceback : str
        The formatted traceback (from the worker).
    """

    index: int
    item: Any
    error: str
    traceback: str


@dataclass(frozen=True)
class MapResult:
    """Results of :func:`map_items`, in input order.

    Attributes
    ----------
    results : list
        ``func(item)`` per item; ``None`` where it failed.
    failures : list of ItemFailure
        The items that raised (sorted by index); empty when all succeeded.
    elapsed : float
        Wall time (s).
    """

    results: list
    failures: list[ItemFailure]
    elapsed: float

    @property
    def ok(self) -> bool:
        """True when every item succeeded."""
        return not self.failures

    def raise_failures(self) -> None:
        """Raise a :class:`PhotogeomError` listing the failures (the first five in full)."""
        if self.failures:
            lines = [f"  item {f.index} ({f.item!r}): {f.error}" for f in self.failures[:5]]
            more = len(self.failures) - 5
            raise PhotogeomError(
                f"{len(self.failures)} of {len(self.results)} item(s) failed:\n"
                + "\n".join(lines)
                + (f"\n  ... and {more} more" if more > 0 else "")
            )


def _guarded(func: Callable, item: Any) -> tuple[bool, Any]:
    """Run ``func(item)`` on a worker; an exception becomes data (so one bad file does not
    stop the job)."""
    try:
        return True, func(item)
    except Exception as exc:
        return False, (f"{type(exc).__name__}: {exc}", traceback.format_exc())


def map_items(
    func: Callable[[Any], Any],
    items: Sequence,
    *,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    raise_on_failure: bool = False,
) -> MapResult:
    """Run ``func(item)`` for each item as a Dask task; collect results and failures.

    Parameters
    ----------
    func : callable
        A picklable function of one item (module-level function or ``functools.partial``);
        it runs on the workers.
    items : sequence
        The work items (file names, image records, ...).
    scheduler : str, optional
        Where to run (see the module docstring): a local cluster by default, a scheduler
        address for a real cluster, ``"threads"`` or ``"sync"`` in this process.
    progress : callable(done, total), optional
        Called as items finish (in completion order).
    raise_on_failure : bool
        Raise after all items ran if any failed (the message lists them); by default the
        failures are returned in :attr:`MapResult.failures`.

    Returns
    -------
    MapResult
        Results in input order (``None`` for failed items) and the failures.
    """
    t0 = time.perf_counter()
    items = list(items)
    total = len(items)
    outcomes: list = [None] * total
    kind, _ = _parse_scheduler(scheduler)
    if kind in ("threads", "sync"):
        if kind == "sync":
            for i, item in enumerate(items):
                outcomes[i] = _guarded(func, item)
                if progress is not None:
                    progress(i + 1, total)
        else:
            from concurrent.futures import ThreadPoolExecutor, as_completed

            ex = ThreadPoolExecutor(max_workers=os.cpu_count() or 1)
            try:
                futs = {ex.submit(_guarded, func, it): i for i, it in enumerate(items)}
                for done, fut in enumerate(as_completed(futs), 1):
                    outcomes[futs[fut]] = fut.result()
                    if progress is not None:
                        progress(done, total)
            except BaseException:  # Ctrl-C, a failing progress: the items not started are
                ex.shutdown(wait=True, cancel_futures=True)  # dropped, not run to the end
                raise
            ex.shutdown(wait=True)
    elif total:
        distributed = _distributed()
        with scheduler_client(scheduler) as client:
            futs = client.map(_guarded, [func] * total, items, pure=False)
            index = {f.key: i for i, f in enumerate(futs)}
            for done, fut in enumerate(distributed.as_completed(futs), 1):
                outcomes[index[fut.key]] = fut.result()
                if progress is not None:
                    progress(done, total)
    results: list = []
    failures: list[ItemFailure] = []
    for i, (ok, value) in enumerate(outcomes):
        if ok:
            results.append(value)
        else:
            results.append(None)
            failures.append(ItemFailure(i, items[i], value[0], value[1]))
    out = MapResult(results, failures, time.perf_counter() - t0)
    if raise_on_failure:
        out.raise_failures()
    return out


# --- dask arrays of points -------------------------------------------------------------------


def _as_dask_points(arr, name: str):
    da, _ = _dask()
    if not isinstance(arr, da.Array):
        # name=False: no hash of the whole array (seconds for 1e7 points)
        arr = da.from_array(np.asarray(arr, dtype=float), chunks=(1_000_000, 3), name=False)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"{name} must have shape (n, 3), got {arr.shape}")
    if len(arr.chunks[1]) != 1:
        arr = arr.rechunk({1: 3})
    return arr


def transform_array(transform, points):
    """``transform.apply`` over a ``dask.array`` of points, block by block.

    Lazy: nothing is computed until the result is.

    Parameters
    ----------
    transform : transformation
        Anything with ``apply((n, 3)) -> (n, 3)``, a ``Fit`` (its ``transform``) or a
        function.
    points : dask.array.Array or array_like, shape (n, 3)
        Points in the source system; an in-memory array is wrapped in blocks of 1 000 000
        points.

    Returns
    -------
    dask.array.Array, shape (n, 3)
        Of the same chunks, in the target system.

    Raises
    ------
    InputError
        For ``points`` not of shape (n, 3), or a ``transform`` that is neither a
        transformation nor a function.
    """
    from .io.cloud import _as_apply

    fn = _as_apply(transform)
    pts = _as_dask_points(points, "points")
    return pts.map_blocks(fn, dtype=float)


def absolute_orientation(
    source,
    target,
    *,
    method: str = "svd",
    with_scale: bool = True,
    weights=None,
    scale_method: str = "least-squares",
    scheduler: str | None = "threads",
    unit: str = "m",
):
    """Absolute orientation ``target ~ s R source + t`` of two ``dask.array`` point sets.

    One pass over the data: each block pair gives its centred moments
    (:func:`photogeom.orientation.absolute_chunked.chunk_moments`), merged exactly on the
    client. Equal to ``photogeom.absolute_orientation(source, target, method=method,
    statistics=False)`` on the same points to rounding (tests: 1e-12 relative), and so are
    its sigma0 and parameter covariance (to the digits the moments keep).

    Parameters
    ----------
    source, target : dask.array or numpy.ndarray, shape (n, 3)
        Corresponding points (target is rechunked to the source's row blocks if needed).
    method : {"svd", "quaternion", "dual-quaternion", "gauss-helmert"}
    with_scale : bool
        False estimates the rigid (6-parameter) transformation, ``s = 1``.
    weights : dask.array or numpy.ndarray, shape (n,), optional
        Point weights (unitless), as in :func:`photogeom.absolute_orientation`.
    scale_method : {"least-squares", "symmetric"}
        Scale of the SVD / quaternion / dual-quaternion methods: the least-squares scale
        (Umeyama) or Horn's ``sqrt(sum |X'|^2 / sum |x'|^2)``.
    scheduler : str
        See the module docstring; ``"threads"`` (this process) by default, ``"local"`` for a
        local cluster of processes, or a scheduler address.
    unit : str
        Length unit of the target coordinates (labels of the shift and the residual sum).

    Returns
    -------
    AbsoluteOrientationFit
        Parameters, sigma0 and the covariance of the parameters (from the moments, as
        :func:`photogeom.orientation.absolute_chunked.fit_from_moments`); no per-point
        residuals or tests; ``extras["sum_squared_residuals"]`` from the moments.
    """
    from .orientation.absolute_chunked import (
        MOMENT_METHODS,
        chunk_moments,
        fit_from_moments,
        merge_moments,
    )

    t0 = time.perf_counter()
    if method not in MOMENT_METHODS:
        raise InputError(
            f"method {method!r} needs all points at once; over dask arrays: "
            f"{', '.join(MOMENT_METHODS)}"
        )
    _, delayed = _dask()
    x = _as_dask_points(source, "source")
    X = _as_dask_points(target, "target")
    if x.shape[0] != X.shape[0]:
        raise InputError(f"source has {x.shape[0]} points, target {X.shape[0]}: need pairs")
    X = X.rechunk((x.chunks[0], 3))
    xb = x.to_delayed().ravel()
    Xb = X.to_delayed().ravel()
    if weights is None:
        parts = [delayed(chunk_moments)(a, b) for a, b in zip(xb, Xb)]
    else:
        da, _ = _dask()
        w = (
            weights
            if isinstance(weights, da.Array)
            else da.from_array(np.asarray(weights, dtype=float), name=False)
        )
        if w.shape != (x.shape[0],):
            raise InputError(f"weights must have shape ({x.shape[0]},), got {w.shape}")
        wb = w.rechunk((x.chunks[0],)).to_delayed().ravel()
        parts = [delayed(chunk_moments)(a, b, c) for a, b, c in zip(xb, Xb, wb)]
    # merge in a tree on the workers: only small tuples travel
    while len(parts) > 1:
        parts = [delayed(merge_moments)(parts[i : i + 16]) for i in range(0, len(parts), 16)]
    (moments,) = _compute(parts[0], scheduler=scheduler)
    return fit_from_moments(
        moments,
        int(x.shape[0]),
        method=method,
        with_scale=with_scale,
        scale_method=scale_method,
        unit=unit,
        t0=t0,
    )


# --- registration of one cloud to another ------------------------------------------------------


def _pair_block(src: str, dst: str, start: int, stop: int, check_every: int, want: str):
    """Moments of the control pairs (``want="moments"``) or residual sums of the check pairs
    (``want="checks"``, a tuple ``(count, sum v, sum v^2, max |v|)``) of points start:stop."""
    from .io.cloud import read_cloud_xyz

    try:
        x = read_cloud_xyz(src, start, stop)
        X = read_cloud_xyz(dst, start, stop)
        if x.shape != (stop - start, 3) or X.shape != (stop - start, 3):
            raise FileFormatError(
                f"{len(x)} and {len(X)} points read where {stop - start} were asked for"
            )
    except Exception as exc:
        # on a worker the traceback is far away: the message names both files and the block
        cls = FileFormatError if isinstance(exc, (FileFormatError, ValueError)) else PhotogeomError
        raise cls(
            f"registering {src} to {dst}, pairs {start}:{stop}: {exc}"
            if isinstance(exc, PhotogeomError)
            else f"registering {src} to {dst}, pairs {start}:{stop}: {type(exc).__name__}: {exc}"
        ) from None
    if check_every:
        is_check = (np.arange(start, stop) % check_every) == 0
    else:
        is_check = np.zeros(stop - start, dtype=bool)
    if want == "moments":
        from .orientation.absolute_chunked import chunk_moments

        return chunk_moments(x[~is_check], X[~is_check])
    return x[is_check], X[is_check]


def _check_sums(block, transform) -> tuple:
    x, X = block
    if x.shape[0] == 0:
        return 0, np.zeros(3), np.zeros(3), 0.0
    v = transform.apply(x) - X
    return (
        x.shape[0],
        v.sum(axis=0),
        (v * v).sum(axis=0),
        float(np.sqrt((v * v).sum(axis=1)).max()),
    )


@dataclass(frozen=True, eq=False)
class CloudRegistration(ReadOnlyRecord):
    """Result of :func:`register_clouds`.

    Attributes
    ----------
    fit : AbsoluteOrientationFit
        From the control pairs: parameters, sigma0 and their covariance (from the moments;
        unit weights, so sigma0 is the standard deviation of one target coordinate in target
        units when the source is exact); no per-point residuals or tests.
    n_control, n_check : int
    check_rms : numpy.ndarray, shape (3,)
        Per-axis RMS of the check-pair residuals (computed minus observed, target units).
    check_rmse : float
        Per-point RMSE ``sqrt(sum |v|^2 / n_check)``.
    check_mean : numpy.ndarray, shape (3,)
        Mean residual per axis (a systematic shift shows here).
    check_max : float
        Largest residual length.
    control_rmse : float
        ``sqrt(sum_squared_residuals / n_control)`` of the control pairs (from the moments).
    crs_name : str or None
        The CRS recorded in the target (reference) cloud: the system of the parameters'
        output and of the residuals (``fit.crs`` holds it as an EPSG code or WKT, and
        ``fit.source_crs`` the source cloud's record).
    """

    fit: Any
    n_control: int
    n_check: int
    check_rms: np.ndarray
    check_rmse: float
    check_mean: np.ndarray
    check_max: float
    control_rmse: float
    crs_name: str | None = None

    def to_dict(self) -> dict:
        """JSON-ready (NaN where there are no check pairs).

        Returns
        -------
        dict
            The fitted similarity (scale, rotation, translation, angles in rad, parameters with
            standard deviations and covariance, sigma0, redundancy), control and check pair
            counts and RMSEs (target units), the CRSs and the transformation's ``to_dict``.
        """
        f = self.fit
        return {
            "method": f.method,
            "scale": f.scale,
            "rotation": np.asarray(f.rotation).tolist(),
            "translation": np.asarray(f.translation).tolist(),
            "angles_transposed_rad": [f.params[k] for k in ("omega", "phi", "kappa")],
            "parameter_names": list(f.parameter_names),
            "parameters": np.asarray(f.parameters).tolist(),
            "std": np.sqrt(np.diag(f.covariance)).tolist(),
            "covariance": np.asarray(f.covariance).tolist(),
            "sigma0": f.sigma0,
            "redundancy": f.redundancy,
            "n_control": self.n_control,
            "n_check": self.n_check,
            "control_rmse": self.control_rmse,
            "check_rmse": self.check_rmse,
            "check_rms": self.check_rms.tolist(),
            "check_mean": self.check_mean.tolist(),
            "check_max": self.check_max,
            "target_crs": self.crs_name,
            "crs": f.crs,
            "source_crs": f.source_crs,
            "transform": f.transform.to_dict(),
        }


def register_clouds(
    source,
    target,
    *,
    method: str = "svd",
    with_scale: bool = True,
    check_every: int = 0,
    chunk_size: int = 1_000_000,
    scheduler: str | None = "threads",
) -> CloudRegistration:
    """Absolute orientation of the cloud ``source`` to ``target`` (LAS/LAZ files whose points
    correspond one to one, in file order), out of core, with check-pair statistics.

    Every ``check_every``-th pair (indices 0, k, 2k, ...) is kept out of the estimate and its
    residuals are reported (``0``: no check pairs). Two passes over the files: the moments of
    the control pairs, then the residuals of the check pairs (skipped without check pairs).
    Blocks of ``chunk_size`` pairs are Dask tasks on ``scheduler``. The CRS records of the
    files go into ``fit.crs`` (target) and ``fit.source_crs``; a geographic one (degrees)
    is refused: the orientation is computed in Cartesian coordinates.

    Parameters
    ----------
    source, target : str or path
        LAS/LAZ files with the same number of points, corresponding in file order
        (coordinates in their CRS's unit, usually m).
    method : {"svd", "quaternion", "dual-quaternion", "gauss-helmert"}
        Estimator working from the moments.
    with_scale : bool
        False fixes the scale to 1 (rigid transformation).
    check_every : int
        Every k-th pair is a check pair (k >= 2), or 0 for none.
    chunk_size : int
        Pairs per Dask task (memory is proportional to it).
    scheduler : str, optional
        As in :func:`map_items`; ``"threads"`` (this process) by default.

    Returns
    -------
    CloudRegistration
        The fit (parameters, sigma0 and their covariance from the moments) and the
        check-pair statistics (target units).
    """
    from .io.cloud import _check_chunk, cloud_info
    from .orientation.absolute_chunked import fit_from_moments, merge_moments

    t0 = time.perf_counter()
    _, delayed = _dask()
    chunk_size = _check_chunk(chunk_size)
    check_every = int(check_every)
    if check_every < 0 or check_every == 1:
        raise InputError(
            f"check_every={check_every}: give 0 (no check pairs) or k >= 2 (every k-th pair)"
        )
    n = cloud_info(source).point_count
    target_info = cloud_info(target)
    m = target_info.point_count
    if n != m:
        raise InputError(
            f"{source} has {n} points and {target} {m}: registration needs corresponding "
            "points, the same count in the same order"
        )
    crs_records = {
        key: _cloud_crs(info, path)
        for key, info, path in (
            ("crs", target_info, target),
            ("source_crs", cloud_info(source), source),
        )
    }
    src, dst = str(source), str(target)
    ranges = [(i, min(i + chunk_size, n)) for i in range(0, n, chunk_size)]
    parts = [delayed(_pair_block)(src, dst, a, b, check_every, "moments") for a, b in ranges]
    while len(parts) > 1:
        parts = [delayed(merge_moments)(parts[i : i + 16]) for i in range(0, len(parts), 16)]
    n_check = 0 if not check_every else len(range(0, n, check_every))
    (moments,) = _compute(parts[0], scheduler=scheduler)
    fit = fit_from_moments(moments, n - n_check, method=method, with_scale=with_scale, t0=t0)
    if any(crs_records.values()):
        from dataclasses import replace

        fit = replace(fit, **crs_records)
    if n_check:
        T = fit.transform
        sums = [
            delayed(_check_sums)(delayed(_pair_block)(src, dst, a, b, check_every, "checks"), T)
            for a, b in ranges
        ]
        (out,) = _compute(delayed(list)(sums), scheduler=scheduler)
        cnt = sum(o[0] for o in out)
        s1 = np.sum([o[1] for o in out], axis=0)
        s2 = np.sum([o[2] for o in out], axis=0)
        vmax = max(o[3] for o in out)
        rms, rmse, mean = np.sqrt(s2 / cnt), float(np.sqrt(s2.sum() / cnt)), s1 / cnt
    else:
        rms = mean = np.full(3, np.nan)
        rmse = vmax = float("nan")
    ctrl = n - n_check
    return CloudRegistration(
        fit,
        ctrl,
        n_check,
        rms,
        rmse,
        mean,
        vmax,
        float(np.sqrt(fit.extras["sum_squared_residuals"] / ctrl)),
        target_info.crs_name,
    )


def _cloud_crs(info, path) -> str | None:
    """The CRS record of a cloud as a CRS text (``EPSG:code`` when it has one, else WKT),
    refused when geographic; None without a record."""
    if info.crs is None:
        return None
    from .crs import cartesian_crs

    text = info.crs
    if info.crs_name and info.crs_name.startswith("EPSG:"):
        text = info.crs_name.split(" ", 1)[0]
    return cartesian_crs(
        text,
        what=f"{path} (its CRS record)",
        fix="transform the cloud to a projected CRS first (photogeom cloud transform --to-crs)",
    ).text


# --- per-image jobs of a block ----------------------------------------------------------------


def _localize_one(item, options: dict):
    path, (col, row, h) = item
    from .rpc import RPC

    lon, lat = RPC.from_file(path).localize(col, row, h, **options)
    return np.asarray(lon), np.asarray(lat)


def localize_files(
    paths: Sequence,
    points,
    *,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    **options,
) -> MapResult:
    """RPC localisation in many image files, one Dask task per file.

    Parameters
    ----------
    paths : sequence of path
        RPC files (any format :meth:`photogeom.RPC.from_file` reads).
    points : tuple (col, row, h) or sequence of such tuples
        Image points (pixels, centre of the first pixel at (0, 0)) and ellipsoidal heights
        (m): one tuple for all files, or one per file.
    scheduler : str, optional
        Where the tasks run, as in :func:`map_items` (default: a local cluster).
    progress : callable, optional
        ``progress(done, total)``, called on the client as files finish.
    options
        Passed to :meth:`photogeom.RPC.localize` (``tol``, ``max_iter``, ``on_failure``...).

    Returns
    -------
    MapResult
        ``results[i] = (lon, lat)`` (degrees) of file i; unreadable files and failed
        localisations are in ``failures``.
    """
    paths = [str(p) for p in paths]
    if isinstance(points, tuple) and len(points) == 3 and not isinstance(points[0], tuple):
        per_file = [points] * len(paths)
    else:
        per_file = list(points)
        if len(per_file) != len(paths):
            raise InputError(
                f"{len(per_file)} point sets for {len(paths)} files: give one (col, row, h) "
                "for all files or one per file"
            )
    import functools

    return map_items(
        functools.partial(_localize_one, options=options),
        list(zip(paths, per_file)),
        scheduler=scheduler,
        progress=progress,
    )


def _resect_one(item, io, options: dict):
    from .orientation.resection import space_resection

    ground, image, *rest = item
    return space_resection(ground, image, rest[0] if rest else io, **options)


def resect_images(
    problems: Sequence,
    io=None,
    *,
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    **options,
):
    """Space resection of many images, one Dask task per image.

    Parameters
    ----------
    problems : sequence of (ground, image) or (ground, image, io)
        Control points per image: object coordinates (n, 3) and image coordinates (n, 2),
        optionally the image's own interior orientation.
    io : InteriorOrientation, optional
        Interior orientation of every image without its own.
    scheduler : str, optional
        Where the tasks run, as in :func:`map_items` (default: a local cluster).
    progress : callable, optional
        ``progress(done, total)``, called on the client as images finish.
    options
        Passed to :func:`photogeom.space_resection` (``system``, ``calibrate``, ...).

    Returns
    -------
    MapResult
        ``results[i]`` is the :class:`~photogeom.ResectionFit` of image i; images that fail
        (too few points, no convergence, ...) are in ``failures``.
    """
    import functools

    problems = list(problems)
    if io is None and any(len(p) < 3 for p in problems):
        raise InputError("give io= or an interior orientation with every image's points")
    return map_items(
        functools.partial(_resect_one, io=io, options=options),
        problems,
        scheduler=scheduler,
        progress=progress,
    )
