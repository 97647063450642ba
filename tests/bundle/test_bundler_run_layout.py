"""The folder layout Bundler's ``RunBundler.sh`` leaves: the images and the working folder,
``prepare/list.txt`` (names ``./IMG_0001.jpg``, relative to the working folder) and
``bundle/bundle.out``; ``list.txt`` is its copy in the working folder, which a shared run
(a public repository of a real Bundler run holds exactly this) may lack. Before, such a
``bundle.out`` found no list ('no image list ... give the images' size'), and the list
given with --image-list was read relative to ``prepare/``, where the images are not."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from photogeom import MetashapeCalibration
from photogeom.bundle import read_bundler, write_bundler
from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

PIL = pytest.importorskip("PIL.Image")
SIZE = (3000, 2000)


@pytest.fixture
def run_folder(tmp_path):
    """A Bundler run: images, prepare/list.txt with Bundler's './NAME 0 FOCAL' lines and
    bundle/bundle.out, no list.txt in the working folder."""
    cal = MetashapeCalibration(*SIZE, 2400.0, k1=-0.08, k2=0.03)
    block = grid_block(2, rows=1, cols=3, n_points=40, cal=cal)
    (tmp_path / "bundle").mkdir()
    write_bundler(block, tmp_path / "bundle" / "bundle.out", drop_extras=True)
    (tmp_path / "bundle" / "bundle.out.list.txt").unlink()  # Bundler writes none there
    names = [f"IMG_{k:04d}.jpg" for k in range(block.n_images)]
    for name in names:
        PIL.new("L", SIZE).save(tmp_path / name)
    (tmp_path / "prepare").mkdir()
    (tmp_path / "prepare" / "list.txt").write_text(
        "".join(f"./{n} 0 2400.0\n" for n in names)
    )
    return tmp_path


def test_a_bundler_run_without_its_working_list_is_read(run_folder):
    block = read_bundler(run_folder / "bundle" / "bundle.out")
    assert block.image_ids.tolist() == [f"./IMG_{k:04d}.jpg" for k in range(3)]
    np.testing.assert_array_equal(block.image_sizes(), np.tile(SIZE, (3, 1)))
    given = read_bundler(run_folder / "bundle" / "bundle.out",
                         image_list=run_folder / "prepare" / "list.txt")  # fmt: skip
    np.testing.assert_array_equal(given.observations.uv, block.observations.uv)


def test_the_cli_reads_it_with_the_list_given(cli, run_folder, tmp_path):
    code, out, err = cli("bundle", "convert", run_folder / "bundle" / "bundle.out",
                         tmp_path / "csv", "--to", "csv", "--image-list",
                         run_folder / "prepare" / "list.txt", "--json")  # fmt: skip
    assert code == 0, err
    assert '"images": 3' in out


def test_a_list_written_on_windows_finds_its_images(tmp_path):
    # a list with Windows paths relative to its folder ('images\IMG_0000.jpg', as a tool on
    # Windows writes it): the image sizes are read from the files there (before: 'is not at
    # .../images\IMG_0000.jpg', the backslashes taken as part of one file name)
    cal = MetashapeCalibration(*SIZE, 2400.0, k1=-0.08, k2=0.03)
    block = grid_block(2, rows=1, cols=3, n_points=40, cal=cal)
    write_bundler(block, tmp_path / "b.out", drop_extras=True)
    (tmp_path / "images").mkdir()
    for k in range(block.n_images):
        PIL.new("L", (SIZE[0], SIZE[1])).save(tmp_path / "images" / f"IMG_{k:04d}.jpg")
    names = [f"images\\IMG_{k:04d}.jpg" for k in range(2)] + [".\\images\\IMG_0002.jpg"]
    (tmp_path / "b.out.list.txt").write_text("".join(f"{n}\r\n" for n in names))
    got = read_bundler(tmp_path / "b.out")
    assert got.image_ids.tolist() == names  # the ids as the list writes them
    np.testing.assert_array_equal(got.image_sizes(), np.tile(SIZE, (3, 1)))
    want = read_bundler(tmp_path / "b.out", image_size=SIZE)
    np.testing.assert_array_equal(got.observations.uv, want.observations.uv)
    # an absolute Windows path is no path of this system: refused naming it and the fix
    (tmp_path / "b.out.list.txt").write_text("".join(f"D:\\photos\\{n}\n" for n in names))
    with pytest.raises(InputError, match=r"image 'D:\\\\photos\\\\images\\\\IMG_0000.jpg' of "
                       r".*names a Windows path \(drive D:\).*give the images' size"):  # fmt: skip
        read_bundler(tmp_path / "b.out")
