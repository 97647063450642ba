"""Failure injection: output names a plain ``open()`` accepts are accepted, failed
writes name the destination, and nothing is left behind."""

from __future__ import annotations

import errno
import json
import os

import numpy as np
import pytest

import photogeom as pg
from photogeom.atomicfile import _temporary_name, atomic_write_text
from photogeom.errors import OutputError
from photogeom.io import PointWriter, write_points

posix = pytest.mark.skipif(os.name != "posix", reason="POSIX file names")


def _limit(directory) -> int:
    try:
        return int(os.pathconf(directory, "PC_NAME_MAX"))
    except (AttributeError, OSError, ValueError):
        return 255


def _longest(directory, suffix: str, char: str = "a") -> str:
    """A file name exactly at the file system's limit (bytes), ending in ``suffix``."""
    room = _limit(directory) - len(suffix.encode())
    return char * (room // len(char.encode())) + "x" * (room % len(char.encode())) + suffix


def _names(d) -> list[str]:
    return sorted(p.name for p in d.iterdir())


@posix
@pytest.mark.parametrize("char", ["a", "\u00e9", "\u6c34"])  # 1, 2 and 3 UTF-8 bytes
def test_temporary_names_fit_the_limit(tmp_path, char):
    name = _longest(tmp_path, ".csv", char)
    tmp = _temporary_name(tmp_path, name, ".0123456789ab.tmp")
    raw = os.fsencode(tmp.name)
    assert len(raw) <= _limit(tmp_path)
    assert tmp.name.startswith(".") and tmp.name.endswith(".0123456789ab.tmp")
    raw.decode("utf-8")  # whole characters kept
    assert _temporary_name(tmp_path, "short.csv", ".x.tmp").name == ".short.csv.x.tmp"


@posix
def test_text_and_point_files_with_the_longest_names(tmp_path):
    """A 255-byte name failed with 'the file name is too long' (its temporary name did)."""
    p = tmp_path / _longest(tmp_path, ".json")
    atomic_write_text(p, "{}\n")
    atomic_write_text(p, "{}\n")  # replaced, too
    assert p.read_text() == "{}\n"
    q = tmp_path / _longest(tmp_path, ".csv", "\u00e9")
    write_points(q, ["a"], np.array([[1.0, 2.0]]), ["x", "y"])
    with PointWriter(q, ["x", "y"]) as w:
        w.write(["b"], np.array([[3.0, 4.0]]))
    assert q.read_text().splitlines()[-1] == "b,3.0,4.0"
    assert _names(tmp_path) == sorted([p.name, q.name])


@posix
@pytest.mark.parametrize("scheduler", [None, "threads"])
def test_clouds_with_the_longest_names(tmp_path, scheduler):
    pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    xyz = np.random.default_rng(1).uniform(0, 50, (300, 3))
    src = tmp_path / _longest(tmp_path, ".laz", "s")
    pg.io.write_cloud(src, xyz)
    dst = tmp_path / _longest(tmp_path, ".laz", "d")
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.1, [10.0, 20.0, 30.0])
    res = pg.io.transform_cloud(src, dst, T, scheduler=scheduler)
    assert res.point_count == 300
    assert np.allclose(pg.io.read_cloud_xyz(dst), T.apply(xyz), atol=1e-3)
    assert _names(tmp_path) == sorted([src.name, dst.name])


@posix
def test_cli_output_with_the_longest_name(cli, tmp_path):
    src = tmp_path / "in.csv"
    src.write_text("id,x,y\na,1,2\n")
    params = tmp_path / "p.json"
    fiducials = pg.datasets.path("lecture_fiducials")
    code, _, err = cli(
        "transform", "estimate", "similarity2d", fiducials, "--output-params", params
    )
    assert code == 0, err
    out = tmp_path / _longest(tmp_path, ".csv")
    code, _, err = cli("transform", "apply", params, src, "-o", out)
    assert code == 0, err
    assert out.read_text().splitlines()[-2] == "id,X,Y"


# --- cloud transform --scheduler: failures name the output, nothing is left behind ---------


@pytest.fixture
def cloud_job(tmp_path):
    """(input cloud, parameter file, output folder holding an old output file)."""
    pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    xyz = np.random.default_rng(2).uniform(0, 50, (400, 3))
    src = tmp_path / "in.las"
    pg.io.write_cloud(src, xyz)
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.1, [10.0, 20.0, 30.0])
    params = tmp_path / "p.json"
    params.write_text(json.dumps({"model_parameters": T.to_dict()}))
    out = tmp_path / "out"
    out.mkdir()
    (out / "o.las").write_bytes(b"old")
    return src, params, out


def _run_cloud(cli, src, params, dst):
    return cli("cloud", "transform", src, dst, "--params", params, "-q", "--scheduler", "threads")


def test_scheduler_unwritable_output_folder_is_one_error_line(cli, cloud_job, monkeypatch):
    """A folder where no file may be made: PermissionError traceback from the folder of the
    pieces (mkdtemp), before; now the output is named."""
    src, params, out = cloud_job

    def refused(path, *args, **kwargs):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(os, "mkdir", refused)
    code, _, err = _run_cloud(cli, src, params, out / "new.las")
    monkeypatch.undo()
    assert code == 2, err
    assert err.strip() == (
        f"error: cannot write {out / 'new.las'}: permission denied; choose a writable location"
    )
    assert _names(out) == ["o.las"]


def test_scheduler_piece_that_cannot_be_written_names_the_output(cli, cloud_job, monkeypatch):
    """Disk full in a worker: the message named the (removed) temporary piece over two
    lines; now one line names the output; the old output and no piece are left."""
    import photogeom.io.cloud as cloud

    src, params, out = cloud_job

    def full(src, part, *args):
        with open(part, "wb") as fh:
            fh.write(b"half a piece")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(cloud, "_write_piece", full)
    code, _, err = _run_cloud(cli, src, params, out / "o.las")
    assert code == 2, err
    assert err.strip() == (
        f"error: cannot write {out / 'o.las'}: no space left on the device; free some space "
        "or write elsewhere"
    )
    assert _names(out) == ["o.las"] and (out / "o.las").read_bytes() == b"old"


@pytest.mark.parametrize("kind", ["folder", "read-only"])
def test_scheduler_refuses_the_destination_before_any_piece(cloud_job, monkeypatch, kind):
    import photogeom.distributed as distributed

    src, _params, out = cloud_job
    dst = out / "o.las"
    if kind == "folder":
        dst = out
    else:
        dst.chmod(0o444)

    def no_work(*args, **kwargs):
        raise AssertionError("pieces computed for an output that cannot be written")

    monkeypatch.setattr(distributed, "map_items", no_work)
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.1, [10.0, 20.0, 30.0])
    with pytest.raises(OutputError, match="cannot write"):
        pg.io.transform_cloud(src, dst, T, scheduler="threads")
    assert _names(out) == ["o.las"]


# --- a standard output that cannot be written ---------------------------------------------


class _FullStream:
    """A standard output on a full disk: every write fails with ENOSPC."""

    encoding = "utf-8"
    errors = "strict"

    def __init__(self) -> None:
        self.buffer = self

    def write(self, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False

    def fileno(self) -> int:
        raise OSError(errno.EBADF, "no file descriptor")


def _main_with_full_stdout(monkeypatch, capsys, args) -> tuple[int, str]:
    import sys

    from photogeom.cli.main import main

    monkeypatch.setattr(sys, "stdout", _FullStream())
    try:
        main([str(a) for a in args])
        code = 0
    except SystemExit as exc:
        code = exc.code
    monkeypatch.undo()
    return code, capsys.readouterr().err


FIDUCIALS = pg.datasets.path("lecture_fiducials")


@pytest.mark.parametrize(
    "args",
    [
        ["transform", "estimate", "similarity2d", FIDUCIALS],  # rich console: a traceback
        ["orient", "absolute", pg.datasets.path("lidar_wang2014"), "--json"],  # typer.echo
        ["transform", "apply", "PARAMS", "POINTS"],  # PointWriter: "cannot write None"
    ],
    ids=["estimate", "absolute-json", "apply"],
)
def test_full_standard_output_is_one_error_line(monkeypatch, capsys, tmp_path, args):
    params = tmp_path / "p.json"
    fit = pg.estimate_transform("similarity2d", *_pairs())
    params.write_text(json.dumps({"model_parameters": fit.transform.to_dict()}))
    points = tmp_path / "in.csv"
    points.write_text("id,x,y\na,1,2\n")
    args = [{"PARAMS": params, "POINTS": points}.get(a, a) for a in args]
    code, err = _main_with_full_stdout(monkeypatch, capsys, args)
    assert code == 2, err
    assert err.strip() == (
        "error: cannot write the standard output: no space left on the device; free some "
        "space or write elsewhere"
    )


def _pairs():
    pairs = pg.io.read_point_pairs(FIDUCIALS)
    return pairs.source, pairs.target


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_stdout_redirected_to_a_full_device(tmp_path):
    """``photogeom ... > /dev/full``: one line, exit 2, no traceback, no second message
    from the interpreter flushing the standard output at exit."""
    import subprocess
    import sys
    from pathlib import Path

    env = dict(os.environ, PYTHONPATH=str(Path(pg.__file__).parents[1]))
    with open("/dev/full", "w") as full:
        res = subprocess.run(
            [sys.executable, "-m", "photogeom", "transform", "estimate", "similarity2d",
             str(FIDUCIALS)],
            stdout=full, stderr=subprocess.PIPE, text=True, env=env, timeout=120,
        )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip().splitlines() == [
        "error: cannot write the standard output: no space left on the device; free some "
        "space or write elsewhere"
    ]


# --- devices and named pipes as destinations ------------------------------------------------


class _Fifo:
    """A named pipe whose read end is open (non-blocking) before anything writes to it, so
    that a writer neither blocks nor needs a thread; outputs must fit the pipe's buffer."""

    def __init__(self, path) -> None:
        os.mkfifo(path)
        self.path = path
        self.fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)

    def read(self) -> bytes:
        chunks = []
        while True:
            try:
                chunk = os.read(self.fd, 1 << 16)
            except BlockingIOError:
                break
            if not chunk:
                break
            chunks.append(chunk)
        return b"".join(chunks)

    def still_a_pipe(self) -> bool:
        import stat

        return stat.S_ISFIFO(os.lstat(self.path).st_mode)

    def close(self) -> None:
        os.close(self.fd)


@pytest.fixture
def fifo(tmp_path):
    if not hasattr(os, "mkfifo"):
        pytest.skip("named pipes")
    f = _Fifo(tmp_path / "pipe")
    yield f
    f.close()


def test_text_into_a_named_pipe(fifo):
    """The pipe was replaced by a regular file (a rename over it); now it is written."""
    atomic_write_text(fifo.path, "hello\n")
    assert fifo.still_a_pipe()
    assert fifo.read() == b"hello\n"


def test_points_into_a_named_pipe(fifo):
    write_points(fifo.path, ["a"], np.array([[1.0, 2.0]]), ["x", "y"])
    assert fifo.still_a_pipe()
    assert fifo.read() == b"id,x,y\na,1.0,2.0\n"


def test_cli_outputs_into_a_named_pipe(cli, fifo, tmp_path):
    report = tmp_path / "report.html"
    code, _, err = cli(
        "transform", "estimate", "similarity2d", FIDUCIALS, "--output-params", fifo.path,
        "--report", report,
    )  # fmt: skip
    assert code == 0, err
    assert fifo.still_a_pipe()
    assert json.loads(fifo.read())["model"]
    assert report.read_text().startswith("<!DOCTYPE html>")
    assert _names(tmp_path) == ["pipe", "report.html"]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="mknod needs root")
def test_a_null_device_stays_a_device(cli, tmp_path):
    """``--output-params /dev/null`` (here a copy of its device node): replaced by a
    regular file, before (as root: the system's /dev/null)."""
    import stat

    null = tmp_path / "null"
    os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    code, _, err = cli("transform", "estimate", "similarity2d", FIDUCIALS, "--output-params", null)
    assert code == 0, err
    assert stat.S_ISCHR(os.lstat(null).st_mode)
    points = tmp_path / "in.csv"
    points.write_text("id,x,y\na,1,2\n")
    params = tmp_path / "p.json"
    cli("transform", "estimate", "similarity2d", FIDUCIALS, "--output-params", params)
    code, _, err = cli("transform", "apply", params, points, "-o", null)
    assert code == 0, err
    assert stat.S_ISCHR(os.lstat(null).st_mode)
    assert _names(tmp_path) == ["in.csv", "null", "p.json"]


@pytest.mark.parametrize("scheduler", [None, "threads"])
def test_cloud_into_a_named_pipe_is_refused(fifo, tmp_path, scheduler):
    pytest.importorskip("laspy")
    pytest.importorskip("lazrs")
    src = tmp_path / "in.las"
    pg.io.write_cloud(src, np.random.default_rng(3).uniform(0, 9, (50, 3)))
    T = pg.Similarity3D.from_angles(1.0, 0.0, 0.0, 0.0, [1.0, 2.0, 3.0])
    with pytest.raises(OutputError, match="a device or a named pipe; a LAS/LAZ output must"):
        pg.io.transform_cloud(src, fifo.path, T, scheduler=scheduler)
    assert fifo.still_a_pipe() and fifo.read() == b""
    assert _names(tmp_path) == ["in.las", "pipe"]


# --- owner and group of a replaced file -------------------------------------------------------


def _writers(tmp_path):
    """Each writer of photogeom (single files, point CSVs, clouds) replacing ``path``."""
    xyz = np.random.default_rng(4).uniform(0, 9, (20, 3))
    out = {
        "text": lambda p: atomic_write_text(p, "new\n"),
        "points": lambda p: write_points(p, ["a"], np.array([[1.0, 2.0]]), ["x", "y"]),
    }
    try:
        import laspy  # noqa: F401
        import lazrs  # noqa: F401
    except ImportError:
        return out
    out["cloud"] = lambda p: pg.io.write_cloud(p, xyz)
    return out


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() != 0, reason="chown needs root")
@pytest.mark.parametrize("writer", ["text", "points", "cloud"])
def test_replaced_file_keeps_its_owner_and_group(tmp_path, writer):
    """Rewritten by root (sudo), a user's file became root's (a plain write keeps its owner
    and group)."""
    write = _writers(tmp_path).get(writer)
    if write is None:
        pytest.skip("laspy/lazrs")
    p = tmp_path / ("out.las" if writer == "cloud" else "out.txt")
    p.write_text("old\n")
    os.chown(p, 65534, 65534)
    p.chmod(0o664)
    write(p)
    st = os.stat(p)
    assert (st.st_uid, st.st_gid, st.st_mode & 0o777) == (65534, 65534, 0o664)
    assert p.read_bytes() != b"old\n"


@pytest.mark.skipif(not hasattr(os, "fchown"), reason="POSIX owners")
@pytest.mark.parametrize("writer", ["text", "points", "cloud"])
def test_group_is_kept_when_the_owner_cannot_be(tmp_path, writer, monkeypatch):
    """A user in a shared project group: its files kept the group only with a plain write."""
    write = _writers(tmp_path).get(writer)
    if write is None:
        pytest.skip("laspy/lazrs")
    p = tmp_path / ("out.las" if writer == "cloud" else "out.txt")
    p.write_text("old\n")
    st = os.stat(p)
    other_uid, other_gid = st.st_uid + 1, st.st_gid + 1
    real_stat = os.stat
    calls = []

    def stat_(path, *a, **k):  # the destination as if it belonged to another user and group
        res = real_stat(path, *a, **k)
        if os.fspath(path) == os.fspath(p):
            fields = list(res)
            fields[4], fields[5] = other_uid, other_gid
            return os.stat_result(fields)
        return res

    def fchown(fd, uid, gid):  # this user may set the group, not the owner
        calls.append((uid, gid))
        if uid != -1:
            raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "stat", stat_)
    monkeypatch.setattr(os, "fchown", fchown)
    write(p)
    monkeypatch.undo()
    assert calls == [(other_uid, other_gid), (-1, other_gid)]
    assert _names(tmp_path) == [p.name]


# --- an interrupted folder of images ----------------------------------------------------------


def test_interrupted_correct_folder_leaves_whole_images_and_no_temporary(tmp_path, monkeypatch):
    """docs/cli.md said that Ctrl-C changes no output file; grid correct-images writes one
    image at a time: those finished stay (complete), the others are untouched."""
    import sys
    from pathlib import Path

    pytest.importorskip("cv2")
    Image = pytest.importorskip("PIL.Image")
    import photogeom.calibration.images as images
    from photogeom.calibration import GridLayout, correct_folder

    sys.path.insert(0, str(Path(__file__).parent))
    from residual_grids import grid_with_nodes

    layout = GridLayout(60, 40, 20)
    grid = grid_with_nodes(layout, np.full((*layout.shape, 2), 1.0))
    src, dst = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    dst.mkdir()
    for k in "abc":
        Image.fromarray(np.zeros((40, 60), np.uint8)).save(src / f"{k}.png")
        (dst / f"{k}.png").write_bytes(b"old")
    real = images.atomic_write_bytes
    calls = []

    def interrupted(path, data):
        calls.append(path)
        if len(calls) == 2:  # Ctrl-C while the second image is written
            raise KeyboardInterrupt
        return real(path, data)

    monkeypatch.setattr(images, "atomic_write_bytes", interrupted)
    with pytest.raises(KeyboardInterrupt):
        correct_folder(src, dst, {k: grid for k in "abc"}, progress=False)
    assert _names(dst) == ["a.png", "b.png", "c.png"]
    assert (dst / "a.png").read_bytes().startswith(b"\x89PNG")
    assert (dst / "b.png").read_bytes() == b"old" and (dst / "c.png").read_bytes() == b"old"


# --- file systems without modes (FAT, exFAT: chmod refused) ----------------------------------


def _no_chmod(monkeypatch):
    def refused(fd, mode):
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "fchmod", refused)


@pytest.mark.parametrize("writer", ["text", "points", "cloud"])
def test_replacing_a_file_of_the_same_mode_needs_no_chmod(tmp_path, writer, monkeypatch):
    """On a FAT/exFAT stick every chmod fails: replacing a file whose mode the new one
    already has made the point writer end in a PermissionError traceback."""
    write = _writers(tmp_path).get(writer)
    if write is None:
        pytest.skip("laspy/lazrs")
    p = tmp_path / ("out.las" if writer == "cloud" else "out.txt")
    write(p)  # a first version: the mode of a new file
    _no_chmod(monkeypatch)
    write(p)
    assert _names(tmp_path) == [p.name]


@pytest.mark.parametrize("writer", ["text", "points", "cloud"])
def test_a_mode_that_cannot_be_kept_is_an_output_error(tmp_path, writer, monkeypatch):
    write = _writers(tmp_path).get(writer)
    if write is None:
        pytest.skip("laspy/lazrs")
    p = tmp_path / ("out.las" if writer == "cloud" else "out.txt")
    p.write_bytes(b"old")
    p.chmod(0o600)
    _no_chmod(monkeypatch)
    with pytest.raises(OutputError, match=f"cannot write {p}: operation not permitted"):
        write(p)
    assert _names(tmp_path) == [p.name] and p.read_bytes() == b"old"


# --- two outputs of one command in one file -----------------------------------------------------


@pytest.fixture(scope="module")
def small_block(tmp_path_factory):
    from photogeom.cli.main import main

    d = tmp_path_factory.mktemp("block") / "blk"
    args = ["bundle", "simulate", str(d), "--strips", "2", "--images-per-strip", "3",
            "--tie-points-per-image", "40"]  # fmt: skip
    try:
        main(args)
    except SystemExit as exc:
        assert exc.code in (0, None)
    return d


def test_report_and_result_in_one_file_are_refused_before_adjusting(
    cli, small_block, tmp_path, monkeypatch
):
    """bundle adjust --report F --result F: exit 0, the report silently replaced the result
    record (one dict entry per path); now refused by both option names, before the work."""
    import photogeom.bundle as bundle

    def no_work(*args, **kwargs):
        raise AssertionError("adjusted although the outputs collide")

    monkeypatch.setattr(bundle, "bundle_adjust", no_work)
    same = tmp_path / "same.out"
    code, _, err = cli("bundle", "adjust", small_block, "--report", same, "--result", same)
    assert code == 2, err
    assert err.strip() == (
        f"error: --report and --result both name {same}: one output would replace the other; "
        "give different files"
    )
    code, _, err = cli("bundle", "adjust", small_block, "-o", tmp_path / "b.bal",
                       "--output-format", "bal", "--drop-extras",
                       "--result", tmp_path / "b.bal")  # fmt: skip
    assert code == 2 and "--output and --result both name" in err, err
    assert _names(tmp_path) == []


def test_report_named_like_a_file_of_the_output_block(cli, small_block, tmp_path):
    """-o adj --report adj/images.csv: exit 0 and a block whose images.csv was the HTML
    report; now one error line and nothing written."""
    out = tmp_path / "adj"
    out.mkdir()
    code, _, err = cli("bundle", "adjust", small_block, "-o", out, "--report",
                       out / "images.csv")  # fmt: skip
    assert code == 2, err
    assert "would be written twice, as a file of the output block" in err
    assert _names(out) == []


# --- Ctrl-C stops the items not yet started ---------------------------------------------------


def test_interrupted_thread_jobs_drop_the_items_not_started():
    """map_items(scheduler='threads') (cloud transform --scheduler threads): after Ctrl-C
    every queued item still ran (40 of 40) before the interrupt took effect."""
    import threading

    from photogeom.distributed import map_items

    workers = os.cpu_count() or 1
    total = 4 * workers + 20
    ran = []
    lock = threading.Lock()
    never = threading.Event()

    def item(i):
        if i:
            never.wait(0.2)  # bounded: items 1.. are still running or queued at the Ctrl-C
        with lock:
            ran.append(i)
        return i

    def interrupt(done, n):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        map_items(item, range(total), scheduler="threads", progress=interrupt)
    assert len(ran) <= 1 + 2 * workers < total


def test_interrupted_image_processes_drop_the_images_not_started(tmp_path, monkeypatch):
    """grid correct-images --workers N: Ctrl-C in the main process waited for every queued
    image (30 of 30 written); the pool is now shut down with its queued jobs cancelled."""
    import concurrent.futures as cf

    import photogeom.calibration.images as images

    shutdowns = []

    class Pool(cf.ThreadPoolExecutor):  # in-process, recording how it is shut down
        def __init__(self, workers):
            super().__init__(workers)

        def shutdown(self, wait=True, *, cancel_futures=False):
            shutdowns.append(cancel_futures)
            super().shutdown(wait=wait, cancel_futures=cancel_futures)

    real_as_completed = cf.as_completed

    def first_then_interrupt(fs):
        yield next(iter(real_as_completed(fs)))
        raise KeyboardInterrupt

    monkeypatch.setattr(cf, "ProcessPoolExecutor", Pool)
    monkeypatch.setattr(cf, "as_completed", first_then_interrupt)
    monkeypatch.setattr(images, "_task", lambda *a, **k: (True, None))
    jobs = [(k, "src", "dst", None) for k in range(6)]
    with pytest.raises(KeyboardInterrupt):
        images._run_processes(jobs, 2, "bilinear", False, "replicate")
    assert shutdowns[0] is True
