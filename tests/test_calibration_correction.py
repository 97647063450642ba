"""Applying residual grids: corrected coordinates, resampled images, files and folders."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from photogeom.calibration import (
    correct_folder,
    correct_image,
    correct_image_file,
    correct_observations,
    correct_points,
    field_at_pixels,
    fit_grid,
)
from photogeom.errors import InputError, PhotogeomError

W, H = 240, 180
XMP = b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF/></x:xmpmeta>'


def field(uv):
    """Modelled residual (px): smooth, up to about 2 px."""
    x, y = uv[:, 0] / W, uv[:, 1] / H
    return np.column_stack([1.5 * np.sin(2 * x) + 0.5 * y, -1.2 * np.cos(1.5 * y) + 0.8 * x * y])


@pytest.fixture(scope="module")
def grid():
    rng = np.random.default_rng(4)
    uv = np.column_stack([rng.uniform(0, W - 1, 2000), rng.uniform(0, H - 1, 2000)])
    return fit_grid(uv, field(uv), (W, H), 30, sigma_obs=0.1, sigma_constraint=0.05, folds=0)


def test_correct_points_and_observations(grid):
    uv = np.array([[10.0, 20.0], [200.5, 170.25]])
    np.testing.assert_allclose(correct_points(uv, grid), uv + grid.evaluate(uv))
    out = correct_observations({"a": uv, "b": uv[:1]}, {"a": grid, "b": grid})
    np.testing.assert_allclose(out["b"], uv[:1] + grid.evaluate(uv[:1]))
    with pytest.raises(InputError, match="no residual grid for image\\(s\\) c"):
        correct_observations({"c": uv}, {"a": grid})
    with pytest.raises(InputError, match=r"image a: .*outside"):
        correct_observations({"a": uv + 1000}, {"a": grid})


def test_field_at_pixels_matches_pointwise_evaluation(grid):
    yy, xx = np.mgrid[0:H, 0:W]
    pts = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    np.testing.assert_allclose(field_at_pixels(grid).reshape(-1, 2), grid.evaluate(pts), atol=1e-12)


@pytest.mark.parametrize("interpolation", ["bilinear", "bicubic"])
def test_image_correction_equals_remap_with_pointwise_maps(grid, interpolation):
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 1, (H, W, 3)).astype(np.float32)
    yy, xx = np.mgrid[0:H, 0:W]
    pts = np.column_stack([xx.ravel(), yy.ravel()]).astype(float)
    r = grid.evaluate(pts).reshape(H, W, 2)
    mx = (xx - r[..., 0]).astype(np.float32)
    my = (yy - r[..., 1]).astype(np.float32)
    flag = cv2.INTER_LINEAR if interpolation == "bilinear" else cv2.INTER_CUBIC
    ref = cv2.remap(img, mx, my, flag, borderMode=cv2.BORDER_REPLICATE)
    for threads in (1, 3):
        out = correct_image(img, grid, interpolation=interpolation, threads=threads)
        np.testing.assert_allclose(out, ref, atol=2e-3)


# Run in a process whose allocator returns every large block to the system at once, as
# in a Dask worker (its nanny sets MALLOC_TRIM_THRESHOLD_): each large array is then fresh
# memory, faulted in page by page, so the page faults count the bytes allocated.
_FAULTS = """
import resource, sys
import numpy as np
from photogeom.calibration import correct_image, fit_grid
w, h, threads = 2000, 1500, int(sys.argv[1])
rng = np.random.default_rng(0)
uv = np.column_stack([rng.uniform(0, w - 1, 400), rng.uniform(0, h - 1, 400)])
grid = fit_grid(uv, rng.normal(0, 0.5, (400, 2)), (w, h), 100.0, folds=0)
img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
correct_image(img, grid, threads=threads)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
out = correct_image(img, grid, threads=threads)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before, out.nbytes)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc and page faults")
@pytest.mark.parametrize("threads", [1, 2])
def test_correct_image_maps_are_not_allocated_per_chunk(threads):
    """The maps of the chunks of rows are built in one pair of buffers per thread: the
    memory touched is the output image and a few chunks, not 8 bytes of maps per pixel
    (a pair of maps per chunk was 6 700 page faults for these 3 Mpx, 27 MB, 3 times the
    output; 1 200 with the buffers)."""
    import os
    import subprocess

    env = {**os.environ, "MALLOC_TRIM_THRESHOLD_": "65536", "OPENBLAS_NUM_THREADS": "1"}
    env["PYTHONPATH"] = os.pathsep.join([*sys.path, env.get("PYTHONPATH", "")])
    done = subprocess.run(
        [sys.executable, "-c", _FAULTS, str(threads)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    faults, nbytes = map(int, done.stdout.split())
    pixels = nbytes // 3
    # the output (3 bytes a pixel) and less than a quarter of the full-size maps (8 bytes)
    assert faults * 4096 < nbytes + 2 * pixels, (faults, nbytes)


def _blobs(points, sigma=1.6):
    yy, xx = np.mgrid[0:H, 0:W].astype(float)
    img = np.zeros((H, W), np.float32)
    for u, v in points:
        img += np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma**2)).astype(np.float32)
    return img


def _centroid(img, u, v, r=6):
    i0, j0 = round(v), round(u)
    win = img[i0 - r : i0 + r + 1, j0 - r : j0 + r + 1].astype(float)
    yy, xx = np.mgrid[i0 - r : i0 + r + 1, j0 - r : j0 + r + 1]
    return np.array([np.sum(win * xx), np.sum(win * yy)]) / win.sum()


@pytest.mark.parametrize("interpolation", ["bilinear", "bicubic"])
def test_feature_moves_to_its_corrected_coordinates(grid, interpolation):
    """A point observed at p appears at p + r(p) in the corrected image (the point
    correction), up to the inverse-mapping approximation |grad r| |r|."""
    rng = np.random.default_rng(8)
    pts = np.column_stack([rng.uniform(20, W - 20, 12), rng.uniform(20, H - 20, 12)])
    pts = pts[np.argsort(pts[:, 0])]
    keep = [0]
    for k in range(1, len(pts)):  # blobs apart from each other
        if np.min(np.hypot(*(pts[keep] - pts[k]).T)) > 16:
            keep.append(k)
    pts = pts[keep]
    out = correct_image(_blobs(pts), grid, interpolation=interpolation)
    expected = correct_points(pts, grid)
    found = np.array([_centroid(out, *p) for p in expected])
    np.testing.assert_allclose(found, expected, atol=0.05)
    assert np.max(np.hypot(*(expected - pts).T)) > 1.0  # the field moved the points


def test_correct_image_bad_input(grid):
    with pytest.raises(InputError, match="does not match"):
        correct_image(np.zeros((H + 1, W), np.uint8), grid)
    with pytest.raises(InputError, match="channels"):
        correct_image(np.zeros((H, W, 5), np.uint8), grid)
    with pytest.raises(InputError, match="type"):
        correct_image(np.zeros((H, W), np.int64), grid)
    with pytest.raises(InputError, match="interpolation"):
        correct_image(np.zeros((H, W), np.uint8), grid, interpolation="lanczos")


# ------------------------------------------------------------------ files and folders
def _exif():
    ex = Image.Exif()
    ex[0x010F] = "SONY"
    ex[0x0110] = "ILCE-7RM2"
    return ex


@pytest.mark.parametrize(("fmt", "channels"), [("JPEG", 3), ("TIFF", 3), ("TIFF", 4)])
def test_colour_images_are_encoded_without_a_converted_copy(fmt, channels):
    """Pillow takes the pixels in OpenCV's channel order as it copies them into its image:
    no colour-converted copy of the whole image is made before (the memory traced beyond
    what Pillow's own encoder takes stays well under the image's size; a conversion first
    was one more full-size array), and the file holds the same pixels."""
    import io
    import tracemalloc

    from photogeom.calibration.images import _encode

    def traced(make):
        tracemalloc.start()
        try:
            return make(), tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    yy, xx = np.mgrid[0:600, 0:800] // 100  # blocks of one colour
    bgr = np.dstack([xx * 40, yy * 40, (xx + yy) * 20, 255 - xx * 30][:channels])
    bgr = bgr.astype(np.uint8)
    want = np.ascontiguousarray(bgr[..., [2, 1, 0, 3][:channels]])  # as RGB(A)
    meta, suffix = {"format": fmt, "compression": "tiff_lzw"}, ".tif"
    kw = {"compression": "tiff_lzw"}
    if fmt == "JPEG":
        meta, suffix, kw = {"format": fmt}, ".jpg", {"quality": 95}  # _encode's quality
    ready = Image.fromarray(want)
    ready.save(io.BytesIO(), format=fmt, **kw)  # the encoder's modules loaded, untraced
    _, encoder = traced(lambda: ready.save(io.BytesIO(), format=fmt, **kw))
    (data, note), peak = traced(lambda: _encode(bgr, meta, suffix))
    assert note is None
    assert peak - encoder < bgr.nbytes / 2, (peak, encoder, bgr.nbytes)
    with Image.open(io.BytesIO(data)) as im:
        got = np.asarray(im)
    if fmt == "JPEG":
        assert np.abs(got.astype(int) - want).mean() < 2.0
    else:
        np.testing.assert_array_equal(got, want)


def test_an_image_file_is_held_once_while_it_is_read(tmp_path):
    """The file's bytes are read once and decoded from there: the memory traced while
    reading is the pixels and one copy of the file (the file was read into an array and
    copied to bytes, two copies: 3 MB more for a 12 Mpx JPEG)."""
    import tracemalloc

    from photogeom.calibration.images import _read

    rng = np.random.default_rng(3)
    path = tmp_path / "noise.jpg"
    Image.fromarray(rng.integers(0, 256, (600, 800, 3), dtype=np.uint8)).save(path, quality=95)
    _read(path)  # the decoders' modules loaded, untraced
    tracemalloc.start()
    try:
        pixels, meta = _read(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    size = path.stat().st_size
    assert meta["format"] == "JPEG" and pixels.shape == (600, 800, 3)
    assert peak < pixels.nbytes + 1.5 * size, (peak, pixels.nbytes, size)


@pytest.fixture
def folder(tmp_path):
    rng = np.random.default_rng(2)
    src = tmp_path / "in"
    src.mkdir()
    rgb = rng.integers(0, 256, (H, W, 3), dtype=np.uint8)
    Image.fromarray(rgb).save(src / "IMG_1.JPG", exif=_exif(), xmp=XMP, quality=90)
    tags = _exif()
    tags[700] = XMP  # XMP is TIFF tag 700
    Image.fromarray(rgb).save(src / "IMG_2.tif", exif=tags, compression="tiff_lzw")
    Image.fromarray(rgb[..., 0]).save(src / "IMG_3.png", exif=_exif())
    (src / "IMG_4.jpg").write_bytes(b"\xff\xd8 not really a JPEG")
    return src, rgb


def test_image_files_keep_format_and_metadata(folder, grid, tmp_path):
    src, rgb = folder
    for name in ("IMG_1.JPG", "IMG_2.tif", "IMG_3.png"):
        dst = tmp_path / name
        assert correct_image_file(src / name, dst, grid) is None
        with Image.open(dst) as im, Image.open(src / name) as orig:
            assert im.format == orig.format and im.size == (W, H) and im.mode == orig.mode
            assert im.getexif()[0x0110] == "ILCE-7RM2"
            if im.format == "JPEG":
                assert im.info["xmp"] == XMP
                assert im.quantization == orig.quantization  # quality kept
            if im.format == "TIFF":
                assert bytes(im.tag_v2[700]) == XMP
                assert im.info["compression"] == "tiff_lzw"
    # lossless formats: the pixels are exactly the corrected array
    with Image.open(tmp_path / "IMG_2.tif") as im:
        np.testing.assert_array_equal(np.asarray(im), correct_image(rgb, grid))
    with Image.open(tmp_path / "IMG_3.png") as im:
        np.testing.assert_array_equal(np.asarray(im), correct_image(rgb[..., 0], grid))


def test_sixteen_bit_colour_kept_by_opencv(grid, tmp_path):
    """16-bit colour is beyond Pillow: OpenCV writes it, bit depth and pixels exact."""
    img = np.random.default_rng(0).integers(0, 65535, (H, W, 3)).astype(np.uint16)
    assert cv2.imwrite(str(tmp_path / "deep.png"), img)
    note = correct_image_file(tmp_path / "deep.png", tmp_path / "out.png", grid)
    out = cv2.imread(str(tmp_path / "out.png"), cv2.IMREAD_UNCHANGED)
    assert out.dtype == np.uint16 and out.shape == img.shape
    np.testing.assert_array_equal(out, correct_image(img, grid))
    assert note is None  # no metadata to lose


def test_folder_lists_failures_and_processes_the_rest(folder, grid, tmp_path):
    src, _ = folder
    (src / "other.png").write_bytes((src / "IMG_3.png").read_bytes())
    grids = {f"IMG_{k}": grid for k in (1, 2, 3, 4, 5)}
    small = fit_grid(
        np.array([[1.0, 1], [50, 40], [10, 60], [70, 5]]), np.zeros((4, 2)), (80, 70), 30
    )
    grids["IMG_3"] = small  # wrong size for the file
    dst = tmp_path / "out"
    res = correct_folder(src, dst, grids, progress=False)
    assert set(res.written) == {"IMG_1", "IMG_2"}
    assert set(res.failures) == {"IMG_3", "IMG_4", "IMG_5"}
    assert "no image file named IMG_5" in res.failures["IMG_5"]
    assert "not a readable image" in res.failures["IMG_4"]
    assert "80 x 70" in res.failures["IMG_3"]
    assert res.skipped == ["other.png"]
    assert sorted(p.name for p in dst.iterdir()) == ["IMG_1.JPG", "IMG_2.tif"]  # nothing half
    # two processes give the same files
    res2 = correct_folder(src, tmp_path / "out2", grids, workers=2, progress=False)
    assert set(res2.written) == {"IMG_1", "IMG_2"} and set(res2.failures) == set(res.failures)
    for name in ("IMG_1.JPG", "IMG_2.tif"):
        assert (tmp_path / "out2" / name).read_bytes() == (dst / name).read_bytes()
    with pytest.raises(InputError, match="must differ"):
        correct_folder(src, src, grids, progress=False)
    with pytest.raises(InputError, match="does not exist"):
        correct_folder(tmp_path / "nope", dst, grids, progress=False)


def test_folder_on_a_dask_scheduler(folder, grid, tmp_path):
    distributed = pytest.importorskip("distributed")
    src, _ = folder
    cluster = distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0"
    )
    try:
        res = correct_folder(
            src,
            tmp_path / "out",
            {"IMG_1": grid, "IMG_4": grid},
            dask=cluster.scheduler_address,
            progress=False,
        )
    finally:
        cluster.close()
    assert set(res.written) == {"IMG_1"} and set(res.failures) == {"IMG_4"}
    ref = tmp_path / "ref.jpg"
    correct_image_file(src / "IMG_1.JPG", ref, grid)
    assert (tmp_path / "out" / "IMG_1.JPG").read_bytes() == ref.read_bytes()


@pytest.mark.parametrize("dask", [True, "tcp://127.0.0.1:8786"])
def test_dask_tasks_ship_the_nodes_not_the_observations(folder, tmp_path, monkeypatch, dask):
    """What a Dask task is given does not grow with the residuals of the fit: the nodes
    (and the per-node support and counts), not the positions, standard deviations, outlier
    flags and data-snooping statistics of every observation."""
    import pickle

    import photogeom.calibration.images as images

    src, _ = folder
    rng = np.random.default_rng(5)
    shipped = {}
    for n in (300, 30000):
        uv = np.column_stack([rng.uniform(0, W - 1, n), rng.uniform(0, H - 1, n)])
        fitted = fit_grid(uv, field(uv), (W, H), 30, folds=0, snooping=True)

        def run(jobs, *args, n=n):
            shipped[n] = max(len(pickle.dumps(job, protocol=5)) for job in jobs)
            return [(True, None)] * len(jobs)

        monkeypatch.setattr(images, "_run_dask", run)
        correct_folder(src, tmp_path / f"out{n}", {"IMG_1": fitted}, dask=dask, progress=False)
        node_bytes = fitted.nodes.nbytes + fitted.counts.nbytes + fitted.support.nbytes
        assert shipped[n] < node_bytes + 4096, (n, shipped[n], node_bytes)
    assert abs(shipped[30000] - shipped[300]) < 64, shipped


def test_concurrent_dask_tasks_keep_opencv_single_threaded_and_restore_it(monkeypatch):
    """Tasks running at once in one worker process (a Dask worker of 2 threads): OpenCV
    stays single-threaded while any of them runs, and gets its own thread count back when
    the last one ends, whichever ends first (each task restoring the count it had found
    left the process at 1 thread, or gave a running task the full count)."""
    import threading

    import photogeom.calibration.images as images

    inside = {"a": threading.Event(), "b": threading.Event()}
    leave = {"a": threading.Event(), "b": threading.Event()}
    seen = {}

    def work(src, dst, grid, **kw):
        inside[src].set()
        assert leave[src].wait(30)
        seen[src] = cv2.getNumThreads()

    monkeypatch.setattr(images, "correct_image_file", work)
    own = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        runs = {
            k: threading.Thread(target=images._task, args=(k, "", None, "bilinear", 1, True))
            for k in "ab"
        }
        runs["a"].start()
        assert inside["a"].wait(30)
        runs["b"].start()
        assert inside["b"].wait(30)
        leave["a"].set()  # the first task to start ends first
        runs["a"].join(30)
        while_b_runs = cv2.getNumThreads()
        leave["b"].set()
        runs["b"].join(30)
        after = cv2.getNumThreads()
    finally:
        cv2.setNumThreads(own)
    assert seen == {"a": 1, "b": 1}
    assert while_b_runs == 1
    assert after == 3


_NO_GUARD = """
import sys
from pathlib import Path
import numpy as np
from PIL import Image
from photogeom import PhotogeomError
from photogeom.calibration import correct_folder, fit_grid

rng = np.random.default_rng(0)
uv = np.column_stack([rng.uniform(0, 59, 50), rng.uniform(0, 39, 50)])
grid = fit_grid(uv, rng.normal(0, 0.5, (50, 2)), (60, 40), 20.0, folds=0)
Image.fromarray(np.zeros((40, 60, 3), np.uint8)).save(sys.argv[1] + "/IMG.jpg")
try:
    correct_folder(sys.argv[1], sys.argv[2], {"IMG": grid}, dask=True, progress=False)
except PhotogeomError as exc:
    print("PhotogeomError:", exc)
"""


def test_folder_cluster_started_without_main_guard_names_the_guard(tmp_path):
    """A script that corrects a folder on a local cluster at its top level: the workers
    import the script again and cannot start; the error says why and what to do (it was
    distributed's ``RuntimeError: Nanny failed to start.``)."""
    import os
    import subprocess

    pytest.importorskip("distributed")
    script = tmp_path / "job.py"
    script.write_text(_NO_GUARD, encoding="utf-8")
    (tmp_path / "in").mkdir()
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    env["PYTHONPATH"] = os.pathsep.join([*sys.path, env.get("PYTHONPATH", "")])
    out = subprocess.run(
        [sys.executable, str(script), str(tmp_path / "in"), str(tmp_path / "out")],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    said = [line for line in out.stdout.splitlines() if line.startswith("PhotogeomError:")]
    assert said, (out.stdout[-2000:], out.stderr[-2000:])
    assert "did not start" in said[-1] and 'if __name__ == "__main__":' in said[-1]
    assert "dask=False" in said[-1] and "--dask" in said[-1]


def test_missing_dask_is_named(folder, grid, tmp_path, monkeypatch):
    src, _ = folder
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(PhotogeomError, match=r"photogeom\[dask\]"):
        correct_folder(src, tmp_path / "out", {"IMG_1": grid}, dask=True, progress=False)


def test_dask_folder_is_one_graph(folder, grid, tmp_path):
    """The images of a folder go to the scheduler as one graph (a submit per image was a
    graph update each: Dask's CPU taken from the workers' cores); each outcome is fetched
    once, as its task ends (one kept on its worker until the end would be lost with that
    worker); the progress counts every image, and the files equal those corrected one by
    one."""
    distributed = pytest.importorskip("distributed")
    src, _ = folder
    for k in (5, 6):
        (src / f"IMG_{k}.JPG").write_bytes((src / "IMG_1.JPG").read_bytes())
    calls = {"update_graph": 0, "gather": 0}

    class Graphs(distributed.diagnostics.plugin.SchedulerPlugin):
        def update_graph(self, scheduler, **kwargs):
            calls["update_graph"] += 1

    cluster = distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0"
    )
    try:
        scheduler = cluster.scheduler
        scheduler.add_plugin(Graphs())
        gather = scheduler.handlers["gather"]

        def counted(*args, **kwargs):
            calls["gather"] += 1
            return gather(*args, **kwargs)

        scheduler.handlers["gather"] = counted
        seen = []
        grids = {"IMG_1": grid, "IMG_4": grid, "IMG_5": grid, "IMG_6": grid}
        res = correct_folder(
            src,
            tmp_path / "out",
            grids,
            dask=cluster.scheduler_address,
            progress=lambda done, total: seen.append((done, total)),
        )
    finally:
        cluster.close()
    assert calls == {"update_graph": 1, "gather": 4}
    assert seen == [(k, 4) for k in range(5)]
    assert set(res.written) == {"IMG_1", "IMG_5", "IMG_6"} and set(res.failures) == {"IMG_4"}
    assert "not a readable image" in res.failures["IMG_4"]
    ref = tmp_path / "ref.jpg"
    correct_image_file(src / "IMG_1.JPG", ref, grid)
    for name in ("IMG_1.JPG", "IMG_5.JPG", "IMG_6.JPG"):
        assert (tmp_path / "out" / name).read_bytes() == ref.read_bytes()


@pytest.mark.parametrize("how", [{"workers": 2}, {"dask": True}])
def test_parallel_folder_queues_the_largest_images_first(tmp_path, monkeypatch, how):
    """Parallel workers take the images largest first (pixels, then file bytes; equal ones
    in their order), so that they end together: in name order, a large image that came
    last was corrected by one worker alone after the others had run out of work. The
    outcomes still go to their own images."""
    import photogeom.calibration.images as images

    src = tmp_path / "in"
    src.mkdir()
    rng = np.random.default_rng(3)
    sizes = {"a": (60, 40), "b": (120, 80), "c": (60, 40), "d": (90, 60), "e": (60, 40)}
    grids = {}
    for k, (w, h) in sizes.items():
        uv = np.column_stack([rng.uniform(0, w - 1, 60), rng.uniform(0, h - 1, 60)])
        grids[k] = fit_grid(uv, rng.normal(0, 0.3, (60, 2)), (w, h), 20.0, folds=0)
        # file bytes: c larger than a and e (of as many pixels), a and e equal
        (src / f"{k}.jpg").write_bytes(b"\xff\xd8" + bytes(500 if k == "c" else 100))
    queued = []

    def run(jobs, *args):
        queued.extend(Path(s).stem for _k, s, _d, _g in jobs)
        return [(True, f"note of {Path(s).stem}") for _k, s, _d, _g in jobs]

    monkeypatch.setattr(images, "_run_dask", run)
    monkeypatch.setattr(images, "_run_processes", run)
    res = correct_folder(src, tmp_path / "out", grids, progress=False, **how)
    assert queued == ["b", "d", "c", "a", "e"]
    assert list(res.written) == list("abcde")  # in the order of the grids, as before
    assert res.notes == {k: f"note of {k}" for k in "abcde"}
    assert all(res.written[k] == tmp_path / "out" / f"{k}.jpg" for k in "abcde")
