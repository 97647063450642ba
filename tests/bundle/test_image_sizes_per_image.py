"""Image sizes given to BAL and Bundler files (``image_size``, ``--image-size``). One size for
every image was taken as given: a block of cameras of several formats (or a size too small)
got observations outside their image, a pixel origin hundreds of pixels off and grids of the
wrong extent, without a word (``--image-size 400x300`` on the bundled Dubrovnik file: u down
to -468 px). Observations outside the size given are now warned of (an ImageSizeWarning
naming the image and the size they need; read as given, since a file written with its
principal points off the centre measures from them), and sizes can be given per image (a
mapping; on the command line a CSV of ``image_id,width,height``)."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import photogeom as pg
from photogeom import MetashapeCalibration
from photogeom.bundle import read_bal, read_bundler, write_bundler
from photogeom.bundle.io_bal import SIZES_FIX, ImageSizeWarning
from photogeom.cli._common import SIZE_WORDS
from photogeom.errors import InputError

sys.path.insert(0, str(Path(__file__).parent))
from blocks import grid_block

DUBROVNIK = pg.datasets.path("dubrovnik-3-7")


def _bal_observations(path):
    """(camera, x, y) of each observation, read token by token (independent of read_bal)."""
    tok = open(path).read().split()
    n = int(tok[2])
    obs = np.array(tok[3 : 3 + 4 * n], dtype=float).reshape(n, 4)
    return obs[:, 0].astype(int), obs[:, 2], obs[:, 3]


def test_a_size_smaller_than_the_observations_is_said_with_the_size_they_need():
    cam, x, y = _bal_observations(DUBROVNIK)
    k = cam == 0
    need = (2 * int(np.ceil(np.abs(x[k]).max())), 2 * int(np.ceil(np.abs(y[k]).max())))
    with pytest.warns(ImageSizeWarning) as got:
        block = read_bal(DUBROVNIK, image_size=(400, 300))
    msg = str(got[0].message)
    assert "image 0 (and 2 more) has observations outside the image size given" in msg
    assert f"an image of at least {need[0]} x {need[1]} px" in msg
    assert "a mapping image id -> (width, height) for images of several sizes" in msg
    assert block.observations.uv.min() < -400  # read as given: outside the 400 x 300 image
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_bal(DUBROVNIK, image_size=(3000, 2400))  # holding them: no word
        read_bal(DUBROVNIK)  # the size guessed holds them


def test_each_image_takes_its_own_size():
    cam, x, y = _bal_observations(DUBROVNIK)
    sizes = {0: (2200, 1800), 1: (2400, 1600), 2: (3000, 2000)}
    block = read_bal(DUBROVNIK, image_size=sizes)
    np.testing.assert_array_equal(block.image_sizes(), [sizes[i] for i in range(3)])
    w, h = np.array([sizes[i] for i in cam], dtype=float).T  # u = x + (w - 1) / 2 per image
    want = np.column_stack([x + (w - 1) / 2, (h - 1) / 2 - y])
    np.testing.assert_array_equal(block.observations.uv, want)
    with pytest.raises(InputError, match=r"gives no size for image 2 \(of 1 without one\)"):
        read_bal(DUBROVNIK, image_size={0: (2200, 1800), 1: (2200, 1800)})


CAL = MetashapeCalibration(3000, 2000, 2400.0, k1=-0.08, k2=0.03)


@pytest.fixture(scope="module")
def bundler(tmp_path_factory):
    d = tmp_path_factory.mktemp("b")
    write_bundler(grid_block(2, rows=1, cols=3, n_points=60, cal=CAL), d / "b.out",
                  drop_extras=True)  # fmt: skip
    return d / "b.out"


def test_a_bundler_image_file_smaller_than_its_observations_is_refused(bundler, tmp_path):
    from PIL import Image

    names = bundler.with_name("b.out.list.txt").read_text().split()
    (tmp_path / "b.out").write_bytes(bundler.read_bytes())
    (tmp_path / "b.out.list.txt").write_text("\n".join(names) + "\n")
    for k, name in enumerate(names):  # the second a thumbnail of the 3000 x 2000 image
        Image.new("L", (750, 500) if k == 1 else (3000, 2000)).save(tmp_path / name, "JPEG")
    with pytest.warns(ImageSizeWarning, match=rf"image {names[1]!r} has observations outside "
                      rf"the size of its image file .*{names[1]}, 750 x 500 px"):  # fmt: skip
        read_bundler(tmp_path / "b.out")
    with pytest.warns(ImageSizeWarning, match=r"outside the image size given \(image_size\)"):
        read_bundler(bundler, image_size=(750, 500))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        got = read_bundler(tmp_path / "b.out", image_size={names[1]: (3000, 2000)})
    np.testing.assert_array_equal(got.image_sizes(), [[3000, 2000]] * 3)


def test_the_command_line_says_it_in_its_words_and_takes_a_csv_of_sizes(cli, tmp_path):
    assert SIZE_WORDS[0][0] == SIZES_FIX  # the library's words, as the command line has them
    code, _, err = cli("bundle", "convert", DUBROVNIK, tmp_path / "a", "--to", "csv",
                       "--image-size", "400x300")  # fmt: skip
    assert code == 0 and "warning:" in err
    assert "outside the image size given (--image-size), 400 x 300 px" in err
    assert "--image-size SIZES.csv, a CSV of image_id,width,height rows" in err
    assert "image_size" not in err.replace("--image-size", "")
    sizes = tmp_path / "sizes.csv"
    sizes.write_text("image_id,width,height\n0,2200,1800\n1,2400,1600\n2,3000,2000\n")
    code, _, err = cli("bundle", "convert", DUBROVNIK, tmp_path / "b", "--to", "csv",
                       "--image-size", sizes)  # fmt: skip
    assert code == 0, err
    assert "warning" not in err
    cams = pg.bundle.read_csv_block(tmp_path / "b")
    np.testing.assert_array_equal(cams.image_sizes(), [[2200, 1800], [2400, 1600], [3000, 2000]])
    sizes.write_text("image_id,width,height\n0,2200,1800\n1,2400,1600\n")
    code, _, err = cli("bundle", "convert", DUBROVNIK, tmp_path / "c", "--to", "csv",
                       "--image-size", sizes)  # fmt: skip
    assert code == 2 and "--image-size gives no size for image 2" in err, err
    assert "a CSV of sizes gives every image's" in err


@pytest.mark.parametrize(
    "text, words",
    [("image,width,height\n0,1,1\n", "needs the columns image_id,width,height"),
     ("image_id,width,height\n0,2200\n", "line 2: expected an image id and its width"),
     ("image_id,width,height\n0,2200,0\n", "line 2: expected an image id and its width"),
     ("image_id,width,height\n0,2200,1800\n0,2200,1800\n", "line 3: image '0' has a size")],
)  # fmt: skip
def test_a_csv_of_sizes_that_cannot_be_read_is_refused_by_line(cli, tmp_path, text, words):
    sizes = tmp_path / "sizes.csv"
    sizes.write_text(text)
    code, _, err = cli("bundle", "convert", DUBROVNIK, tmp_path / "b", "--to", "csv",
                       "--image-size", sizes)  # fmt: skip
    assert code == 2 and words in err, err


def test_two_rows_naming_one_integer_id_are_refused_naming_both_lines(cli, tmp_path):
    # rows 0 and 00 both set image 0 of a BAL file: the later one (100 x 100) won silently
    sizes = tmp_path / "sizes.csv"
    sizes.write_text("image_id,width,height\n0,2200,1800\n1,2400,1600\n2,3000,2000\n00,100,100\n")
    code, _, err = cli("bundle", "convert", DUBROVNIK, tmp_path / "b", "--to", "csv",
                       "--image-size", sizes)  # fmt: skip
    assert code == 2, err
    assert "lines 2 and 5: rows '0' and '00' both name image 0" in " ".join(err.split())
    assert not (tmp_path / "b").exists()
    # 00 alone is image 0, as the integer it spells
    sizes.write_text("image_id,width,height\n00,2200,1800\n1,2400,1600\n2,3000,2000\n")
    code, _, err = cli("bundle", "convert", DUBROVNIK, tmp_path / "c", "--to", "csv",
                       "--image-size", sizes)  # fmt: skip
    assert code == 0, err
    got = pg.bundle.read_csv_block(tmp_path / "c").image_sizes()
    np.testing.assert_array_equal(got, [[2200, 1800], [2400, 1600], [3000, 2000]])


def test_a_bundler_file_without_a_list_refuses_two_rows_naming_one_camera(cli, bundler, tmp_path):
    (tmp_path / "b.out").write_bytes(bundler.read_bytes())  # no list: ids are camera indices
    sizes = tmp_path / "sizes.csv"
    sizes.write_text("image_id,width,height\n0,3000,2000\n01,3000,2000\n1,3000,2000\n2,3000,2000\n")
    code, _, err = cli("bundle", "convert", tmp_path / "b.out", tmp_path / "c", "--to", "csv",
                       "--image-size", sizes)  # fmt: skip
    assert code == 2, err
    assert "lines 3 and 4: rows '01' and '1' both name image 1" in " ".join(err.split())


def test_text_ids_of_a_csv_of_sizes_match_exactly(tmp_path):
    from photogeom.cli._common import image_sizes_option

    sizes = tmp_path / "sizes.csv"
    sizes.write_text("image_id,width,height\n0,2200,1800\n00,100,100\n")
    got = image_sizes_option(str(sizes))
    assert got["0"] == (2200, 1800) and got["00"] == (100, 100)  # two images of a text block
    with pytest.raises(InputError, match=r"lines 2 and 3: rows '0' and '00' both name image 0"):
        0 in got  # noqa: B015 (an integer block's lookup)
