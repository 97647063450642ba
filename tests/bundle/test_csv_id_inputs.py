"""Ids of any text survive a CSV block round trip: quoted cells are kept exactly as written
(white space, a leading '#', commas, quotes, integer-like text), and what a CSV line cannot
hold is refused by the writer with a named error."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from photogeom.bundle import Block, read_csv_block, write_csv_block
from photogeom.camera.metashape import MetashapeCalibration
from photogeom.errors import FileFormatError, OutputError

#: Characters that break a line for the reader (str.splitlines) and NUL: refused in ids.
_LINE_BREAKS = "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029\x00"


def _arr(ids) -> np.ndarray:
    """Ids as an array: text kept whole (object, not a fixed-width string type)."""
    return np.array(ids, dtype=object if isinstance(ids[0], str) else np.int64)


def _block(image_ids, point_ids, camera_ids) -> Block:
    """A block in which every image observes every point (ids given as Python lists)."""
    cal = MetashapeCalibration(400, 300, 500.0)
    cams = {c: cal for c in camera_ids}
    m, p = len(image_ids), len(point_ids)
    ii, jj = np.meshgrid(np.arange(m), np.arange(p), indexing="ij")
    ii, jj = ii.ravel(), jj.ravel()
    return Block.from_arrays(
        cameras=cams,
        image_ids=_arr(image_ids),
        image_camera=_arr([camera_ids[k % len(camera_ids)] for k in range(m)]),
        exterior=np.column_stack([np.arange(m), np.zeros((m, 2)) + 50.0, np.zeros((m, 3))]),
        point_ids=_arr(point_ids),
        xyz=np.column_stack([np.arange(p), np.ones(p), np.zeros(p)]),
        obs_image_ids=_arr(image_ids)[ii],
        obs_point_ids=_arr(point_ids)[jj],
        uv=np.column_stack([ii * 10.0 + 1, jj * 7.0 + 2]),
    )


def _same_tables(a: Block, b: Block) -> None:
    assert a.image_ids.dtype.kind == b.image_ids.dtype.kind == "U"
    assert a.image_ids.tolist() == b.image_ids.tolist()
    assert a.point_ids.tolist() == b.point_ids.tolist()
    assert a.camera_ids.tolist() == b.camera_ids.tolist()
    assert b.point_ids.dtype.kind == "U" and b.camera_ids.dtype.kind == "U"
    assert b.observations.image_ids.tolist() == a.observations.image_ids.tolist()
    assert b.observations.point_ids.tolist() == a.observations.point_ids.tolist()
    np.testing.assert_array_equal(b.observations.uv, a.observations.uv)
    assert b.camera_ids[b.image_camera].tolist() == a.camera_ids[a.image_camera].tolist()


def test_the_reported_ids_come_back(tmp_path):
    ids = ["img0", "img1", "img2", "#3", " img4 ", 'say "x"', "a,b", "\tt"]
    pts = ["#p", " 1", "2 ", "7", "-3", "0"]  # integer-like text stays text
    b = _block(ids, pts, ["#cam", " c2 "])
    write_csv_block(b, tmp_path)
    r = read_csv_block(tmp_path)
    assert (r.n_images, r.n_points, r.n_observations) == (8, 6, 48)
    _same_tables(b, r)
    # what a person sees: quoted cells, '#' not at the start of a line
    text = (tmp_path / "images.csv").read_text()
    assert '\n"#3",' in text and '\n" img4 ",' in text and '"say ""x"""' in text
    assert '"7"' in (tmp_path / "points.csv").read_text()


def test_integer_ids_stay_integers_and_unquoted(tmp_path):
    b = _block([5, 6, 7], [1, 2], [3])
    write_csv_block(b, tmp_path)
    assert '"' not in (tmp_path / "observations.csv").read_text()
    r = read_csv_block(tmp_path)
    assert r.image_ids.dtype.kind == "i" and r.image_ids.tolist() == [5, 6, 7]
    assert r.camera_ids.tolist() == [3]


@settings(max_examples=60)
@given(
    st.lists(
        st.text(
            st.characters(blacklist_categories=("Cs",), blacklist_characters=_LINE_BREAKS),
            min_size=1,
            max_size=8,
        ),
        min_size=2,
        max_size=5,
        unique=True,
    ),
    st.lists(
        st.text(st.characters(codec="utf-8"), min_size=1, max_size=6),
        min_size=1,
        max_size=2,
        unique=True,
    ).filter(lambda c: not any(ch in _LINE_BREAKS for t in c for ch in t)),
)
def test_round_trip_of_arbitrary_id_texts(tmp_path_factory, ids, cams):
    pts = [f"P{t}" for t in ids] + list(ids)
    b = _block(ids, pts, cams)
    d = tmp_path_factory.mktemp("ids")
    write_csv_block(b, d)
    _same_tables(b, read_csv_block(d))


@pytest.mark.parametrize("bad", ["", "a\nb", "a\rb", "x\u2028y", "n\x00l"])
def test_ids_a_line_cannot_hold_are_refused_by_name(tmp_path, bad):
    ids = ["ok", bad] if bad else ["ok", "ok2"]
    pts = ["p1", "p2"] if bad else ["p1", ""]
    b = _block(ids, pts, ["c"])
    with pytest.raises(OutputError, match=r"cannot write (image|point) id .* to a CSV block"):
        write_csv_block(b, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_hand_written_quotes(tmp_path):
    (tmp_path / "cameras.csv").write_text("camera,width,height,f\nc,400,300,500\n")
    (tmp_path / "images.csv").write_text(
        "id,camera,X0,Y0,Z0,omega_deg,phi_deg,kappa_deg\n"
        '"#1" , c,0,0,50,0,0,0\n'
        ' "2",c,1,0,50,0,0,0\n'
    )
    (tmp_path / "points.csv").write_text("id,X,Y,Z\n1,0,0,0\n")
    (tmp_path / "observations.csv").write_text(
        'image_id,point_id,u,v\n"#1",1,1,1\n"2",1,"2.5",2\n'
    )
    r = read_csv_block(tmp_path)
    assert r.image_ids.tolist() == ["#1", "2"]
    assert r.observations.uv[1].tolist() == [2.5, 2.0]
    (tmp_path / "observations.csv").write_text('image_id,point_id,u,v\n"#1,1,1,1\n')
    with pytest.raises(FileFormatError, match=r"observations.csv, line 2: cell 1: a quote"):
        read_csv_block(tmp_path)
    (tmp_path / "observations.csv").write_text('image_id,point_id,u,v\n"#1"x,1,1,1\n')
    with pytest.raises(FileFormatError, match=r"line 2: cell 1: a quote"):
        read_csv_block(tmp_path)


def test_a_multi_line_wkt_crs_is_written_on_one_comment_line(tmp_path):
    """A pretty-printed WKT broke points.csv (its second line was read as the header)."""
    from pyproj import CRS

    import photogeom as pg

    sim = pg.simulate.uav_block(
        "FC300S", seed=1, strips=1, images_per_strip=3, tie_points_per_image=30
    )
    wkt = CRS.from_epsg(25832).to_wkt(pretty=True)
    assert "\n" in wkt
    write_csv_block(sim.block.replace(crs=wkt), tmp_path / "b")
    back = read_csv_block(tmp_path / "b")
    assert CRS.from_user_input(back.crs) == CRS.from_epsg(25832)
    assert back.n_observations == sim.block.n_observations
