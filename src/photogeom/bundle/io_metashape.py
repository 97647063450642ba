"""Camera poses of an Agisoft Metashape camera export (``cameras.xml``) as start values.

Metashape's File > Export > Export Cameras (format "Agisoft XML") writes a ``<document>``
with one ``<chunk>`` holding

* ``<sensors>``: one ``<sensor id=".." label=".." type="frame">`` per camera group, with its
  ``<resolution width=".." height=".."/>`` and calibrations (read by
  :func:`photogeom.camera.metashape_export.sensor_calibration`); a property
  ``<property name="fixed" value="true"/>`` marks a calibration Metashape kept fixed;
* ``<components>`` (Metashape 1.6 and later): each ``<component id="..">`` may hold a
  ``<transform>`` (``<rotation>`` 9 numbers row by row, ``<translation>`` 3, ``<scale>`` 1)
  from the component's frame into the chunk's;
* ``<cameras>``: one ``<camera id=".." label=".." sensor_id=".." component_id="..">`` per
  image, possibly inside ``<group>`` elements (Metashape's camera folders, not camera
  groups in photogeom's sense). An aligned camera has a ``<transform>`` of 16 numbers, the
  4 x 4 matrix row by row that maps the camera's frame (x right, y down, z forward: the
  computer-vision axes) into its component's (or, without components, the chunk's) frame.
  A camera Metashape did not align has no ``<transform>``; ``enabled="false"`` marks a
  camera left out of Metashape's adjustment; ``<orientation>`` is the image's EXIF
  orientation flag (1: as stored); ``master_id`` names the master camera of a camera of
  a multi-camera system (its pose is the master's with its sensor's offset: not read);
* ``<transform>`` (``<rotation>``, ``<translation>``, ``<scale>``): the chunk's frame into
  the world frame, and ``<reference>`` the chunk's CRS as WKT. For a georeferenced chunk
  (a geographic or projected CRS) the world frame is *geocentric* (ECEF), in metres
  (WGS 84's for a CRS based on it); for a local CRS (``LOCAL_CS``) it is that local frame; a chunk
  without ``<transform>`` has only its internal frame (arbitrary origin, axes and scale).

With ``R_c, t_c`` the camera's transform, ``s_k, R_k, t_k`` its component's and ``s, R, t``
the chunk's, a camera-frame point ``x`` is at ``s R (s_k R_k (R_c x + t_c) + t_k) + t`` in
the world frame. The projection centre is that of ``x = 0``; the rotation world -> camera
(computer-vision axes) is ``(R R_k R_c)^T``, and photogeom's ``M`` (object -> image system,
x right, y up, z backwards) is ``diag(1, -1, -1) (R R_k R_c)^T``, as for COLMAP's poses
(:mod:`photogeom.bundle.io_colmap`); omega, phi, kappa are those of ``M``.

A camera export holds poses and calibrations but no tie points, so it is no block format:
:func:`start_from_metashape` puts its poses and calibrations into a block whose tie points
come from a Bundler file or COLMAP model of the same Metashape project (images matched by
label) and triangulates the tie points with them.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import PurePosixPath, PureWindowsPath

import numpy as np

from ..camera.metashape import MAX_CAMERA_EXPORT_BYTES, check_xml_size
from ..camera.metashape_export import SensorCalibration, sensor_calibration
from ..errors import FileFormatError, InputError
from ..numbers import parse_decimal
from ._angles import opk_from_rotations
from .block import Block

__all__ = ["MetashapePoses", "read_metashape_cameras", "start_from_metashape"]

_FLIP = np.diag([1.0, -1.0, -1.0])
#: Largest departure of a transform's rotation from orthonormality (``|R R' - I|``).
ROTATION_TOLERANCE = 1e-6
#: Names listed in an error at most.
LISTED = 10


@dataclass(frozen=True)
class MetashapePoses:
    """The cameras of a Metashape camera export (see the module docstring).

    Attributes
    ----------
    labels : numpy.ndarray of str, shape (m,)
        Each camera's ``label`` (Metashape names a camera after its image file, usually
        without the extension).
    camera_ids : numpy.ndarray of str, shape (m,)
        Each camera's ``id``.
    sensor_ids : numpy.ndarray of str, shape (m,)
        Each camera's ``sensor_id``.
    exterior : numpy.ndarray, shape (m, 6)
        X0, Y0, Z0 (world frame, see ``frame``) and omega, phi, kappa (rad) per camera;
        NaN rows for cameras without a ``<transform>`` (not aligned).
    aligned : numpy.ndarray of bool, shape (m,)
        Cameras with a ``<transform>``.
    enabled : numpy.ndarray of bool, shape (m,)
        Cameras not marked ``enabled="false"``.
    orientation : numpy.ndarray of int, shape (m,)
        EXIF orientation flag of each image (1 when the camera has none).
    master_ids : numpy.ndarray of str, shape (m,)
        The ``master_id`` of each camera of a multi-camera system other than its master
        (empty for the others).
    frame : str
        ``"geocentric"`` (a georeferenced chunk: ECEF metres of the CRS's datum),
        ``"local"`` (the chunk's local CRS) or ``"internal"`` (a chunk without
        ``<transform>``: Metashape's internal frame, arbitrary scale).
    crs : str or None
        The CRS of the world frame: ``"EPSG:4978"`` when ``frame`` is ``"geocentric"`` and
        the chunk's CRS is based on WGS 84; None otherwise (for another datum Metashape's
        geocentric frame may be that datum's or WGS 84's, which the file does not say).
    reference : str or None
        The chunk's ``<reference>`` (its CRS as Metashape wrote it).
    source : str
        The file, named in messages.
    """

    labels: np.ndarray
    camera_ids: np.ndarray
    sensor_ids: np.ndarray
    exterior: np.ndarray
    aligned: np.ndarray
    enabled: np.ndarray
    orientation: np.ndarray
    master_ids: np.ndarray
    frame: str
    crs: str | None
    reference: str | None
    source: str
    _root: ET.Element = field(repr=False, compare=False)
    _lines: dict = field(repr=False, compare=False)

    def sensor(self, sensor_id: str) -> SensorCalibration:
        """The calibration of the sensor with id ``sensor_id``.

        Parameters
        ----------
        sensor_id : str
            The sensor's ``id``.

        Returns
        -------
        SensorCalibration
            As :func:`photogeom.camera.metashape_export.sensor_calibration`.

        Raises
        ------
        FileFormatError
            A sensor of another type than ``frame`` (named), without a calibration, or
            none of that id.
        """
        return sensor_calibration(self._root, self.source, f"id:{sensor_id}", lines=self._lines)

    def sensor_fixed(self, sensor_id: str) -> bool:
        """Whether the sensor's calibration was kept fixed in Metashape
        (``<property name="fixed" value="true"/>``)."""
        for s in _chunk(self._root, self.source).iter("sensor"):
            if s.get("id") == sensor_id:
                for p in s.findall("property"):
                    if p.get("name") == "fixed":
                        return (p.get("value") or "").strip().lower() in ("true", "1")
        return False


def _line(el: ET.Element | None, lines: dict) -> str:
    n = None if el is None else lines.get(id(el))
    return "" if n is None else f", line {n}"


def _chunk(root: ET.Element, where: str) -> ET.Element:
    if root.tag == "chunk":
        return root
    if root.tag != "document":
        raise FileFormatError(
            f"{where}: root element <{root.tag}>: not a Metashape camera export (File > "
            "Export > Export Cameras, Agisoft XML: root <document>)"
        )
    chunks = root.findall("chunk")
    if len(chunks) != 1:
        raise FileFormatError(
            f"{where}: a Metashape camera export with {len(chunks)} chunks; export the cameras "
            "of one chunk (File > Export > Export Cameras exports the active chunk)"
        )
    return chunks[0]


def _numbers(el: ET.Element, count: int, what: str, where: str, lines: dict) -> np.ndarray:
    toks = (el.text or "").split()
    if len(toks) != count:
        raise FileFormatError(
            f"{where}{_line(el, lines)}: {what} holds {len(toks)} numbers, expected {count}"
        )
    try:
        v = np.array([parse_decimal(t) for t in toks])
    except ValueError:
        raise FileFormatError(
            f"{where}{_line(el, lines)}: {what} holds a token that is not a number"
        ) from None
    if not np.all(np.isfinite(v)):
        raise FileFormatError(f"{where}{_line(el, lines)}: {what} holds NaN or infinity")
    return v


def _check_rotations(R: np.ndarray, what, where: str, els, lines: dict) -> None:
    """Refuse the first of the matrices ``R`` (k, 3, 3) that is no rotation
    (:func:`~photogeom.bundle._textio.rotation_defects`), naming ``what(i)`` and the line of
    ``els[i]``."""
    from ._textio import rotation_defects

    bad, off, det = rotation_defects(R, ROTATION_TOLERANCE)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{where}{_line(els[i], lines)}: the rotation of {what(i)} is not a rotation "
            f"(|R R' - I| = {off[i]:.3g}, det {det[i]:.6g})"
        )


def _transforms(tfs: list[ET.Element], labels: list[str], where: str, lines: dict) -> np.ndarray:
    """The cameras' ``<transform>`` matrices (k, 4, 4), each refused naming its camera and
    line: not 16 numbers, NaN or infinity, a last row other than (0, 0, 0, 1), a 3 x 3 part
    that is not a rotation."""
    from ._textio import numbers

    texts = [tf.text or "" for tf in tfs]
    try:
        vals = numbers(" ".join(texts), where)
    except FileFormatError:
        vals = None
    if vals is None or vals.size != 16 * len(tfs):  # find the camera at fault
        for tf, lab in zip(tfs, labels):
            _numbers(tf, 16, f"the <transform> of camera {lab!r}", where, lines)
        raise FileFormatError(
            f"{where}: the cameras' <transform> elements hold something other than numbers"
        )
    A = vals.reshape(-1, 4, 4)
    bad = ~np.all(np.isfinite(A), axis=(1, 2))
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{where}{_line(tfs[i], lines)}: the <transform> of camera {labels[i]!r} holds NaN "
            "or infinity"
        )
    bad = np.any(A[:, 3] != [0.0, 0.0, 0.0, 1.0], axis=1)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise FileFormatError(
            f"{where}{_line(tfs[i], lines)}: the <transform> of camera {labels[i]!r} has the "
            f"last row {A[i, 3].tolist()}, expected [0, 0, 0, 1]"
        )
    _check_rotations(A[:, :3, :3], lambda i: f"camera {labels[i]!r}", where, tfs, lines)
    return A


def _similarity(el: ET.Element | None, what: str, where: str, lines: dict):
    """``(s, R, t)`` of a ``<transform>`` with ``<rotation>``, ``<translation>``,
    ``<scale>`` (each optional: identity, zero, one), or of 16 numbers; None without one."""
    if el is None:
        return None
    if len(el) == 0 and (el.text or "").strip():
        A = _numbers(el, 16, f"the <transform> of {what}", where, lines).reshape(4, 4)
        if np.any(A[3] != [0.0, 0.0, 0.0, 1.0]):
            raise FileFormatError(
                f"{where}{_line(el, lines)}: the <transform> of {what} has the last row "
                f"{A[3].tolist()}, expected [0, 0, 0, 1]"
            )
        det = float(np.linalg.det(A[:3, :3]))
        if not det > 0:  # the scale would be its cube root
            why = (
                f"mirrors (det {det:.6g} < 0): a similarity (rotation, translation, "
                "scale > 0) does not"
                if det < 0
                else "is singular (det 0)"
            )
            raise FileFormatError(f"{where}{_line(el, lines)}: the <transform> of {what} {why}")
        s = float(np.cbrt(det))
        R = A[:3, :3] / s
        _check_rotations(R[None], lambda _: what, where, [el], lines)
        return s, R, A[:3, 3]
    rot, tr, sc = el.find("rotation"), el.find("translation"), el.find("scale")
    R = np.eye(3) if rot is None else _numbers(rot, 9, f"<rotation> of {what}", where, lines)
    R = R.reshape(3, 3)
    _check_rotations(R[None], lambda _: what, where, [rot], lines)
    t = np.zeros(3) if tr is None else _numbers(tr, 3, f"<translation> of {what}", where, lines)
    s = 1.0 if sc is None else float(_numbers(sc, 1, f"<scale> of {what}", where, lines)[0])
    if not s > 0:
        raise FileFormatError(f"{where}{_line(sc, lines)}: the <scale> of {what} is {s:g}, not > 0")
    return s, R, t


def _world_crs(reference: str | None, has_transform: bool) -> tuple[str, str | None]:
    """``(frame, crs)`` of the world frame of a chunk (see :class:`MetashapePoses`)."""
    if not has_transform:
        return "internal", None
    text = (reference or "").lstrip().upper()
    if not text or text.startswith(("LOCAL_CS", "ENGCRS", "ENGINEERINGCRS", "LOCAL")):
        return "local", None
    try:
        import pyproj
        from pyproj.exceptions import CRSError
    except ImportError:  # pyproj is optional: the frame is geocentric, its CRS unnamed
        return "geocentric", None
    try:
        geodetic = pyproj.CRS.from_user_input(reference).geodetic_crs
    except CRSError:  # a WKT PROJ does not read: the frame is still geocentric
        return "geocentric", None
    if geodetic is None or geodetic.datum is None:
        return "geocentric", None
    name = geodetic.datum.name.replace("_", " ")
    if name.startswith("World Geodetic System 1984") or name in ("WGS 1984", "WGS 84"):
        return "geocentric", "EPSG:4978"  # WKT1 names it so; WKT2 "... 1984 ensemble"
    # another datum: Metashape's geocentric frame may be that datum's or WGS 84's (through
    # the CRS's TOWGS84), which the file does not say; the CRS is left unset, not guessed
    return "geocentric", None


def read_metashape_cameras(path: str | os.PathLike) -> MetashapePoses:
    """Read the camera poses of a Metashape camera export (File > Export > Export Cameras).

    Parameters
    ----------
    path : str or os.PathLike
        The XML file (at most ``MAX_CAMERA_EXPORT_BYTES``).

    Returns
    -------
    MetashapePoses
        Every camera of the chunk (those in ``<group>`` elements too), aligned or not, in
        file order; poses in the world frame (see the module docstring).

    Raises
    ------
    FileFormatError
        An unreadable file, not a camera export (another root, several chunks, no
        ``<cameras>``), two cameras with one label, a camera without a ``label``, a
        transform that is not 16 numbers or whose rotation is not one, a component or
        sensor a camera names that is not in the file, an ``enabled`` or ``<orientation>``
        that is neither of Metashape's values; each naming the line.
    """
    from ..io.sources import read_input_bytes
    from ..xmlsafe import parse_xml_lines

    where = str(path)
    try:
        data = read_input_bytes(path, MAX_CAMERA_EXPORT_BYTES)
    except OSError as exc:
        raise FileFormatError(f"cannot read {path}: {exc.strerror or exc}") from exc
    check_xml_size(data, where)
    root, lines = parse_xml_lines(data, where)
    chunk = _chunk(root, where)
    cams_el = chunk.find("cameras")
    if cams_el is None:
        raise FileFormatError(
            f"{where}: the chunk has no <cameras>: not a camera export with poses (File > "
            "Export > Export Cameras)"
        )
    sensors = {s.get("id"): s for s in chunk.iter("sensor")}
    components = {}
    comps = chunk.find("components")
    if comps is not None:
        for c in comps.findall("component"):
            components[c.get("id")] = _similarity(
                c.find("transform"), f'<component id="{c.get("id")}">', where, lines
            )
    chunk_tf = _similarity(chunk.find("transform"), "the chunk", where, lines)
    ref_el = chunk.find("reference")
    reference = None if ref_el is None else (ref_el.text or "").strip() or None
    frame, crs = _world_crs(reference, chunk_tf is not None)
    s0, R0, t0 = chunk_tf if chunk_tf is not None else (1.0, np.eye(3), np.zeros(3))

    elements = list(cams_el.iter("camera"))
    m = len(elements)
    labels, ids, sids = [], [], []
    exterior = np.full((m, 6), np.nan)
    aligned = np.zeros(m, dtype=bool)
    enabled = np.ones(m, dtype=bool)
    orientation = np.ones(m, dtype=np.int64)
    masters = []
    tfs: list[ET.Element] = []
    comp: list[str | None] = []
    seen: dict[str, ET.Element] = {}
    for k, el in enumerate(elements):  # parsing: one XML element each
        label = el.get("label")
        if not label:
            raise FileFormatError(
                f"{where}{_line(el, lines)}: <camera id=\"{el.get('id', '')}\"> has no label; "
                "photogeom matches cameras to images by label"
            )
        if label in seen:
            raise FileFormatError(
                f"{where}{_line(el, lines)}: two cameras have the label {label!r} (the other"
                f"{_line(seen[label], lines).replace(',', '')}); photogeom matches cameras "
                "to images by label: rename one in Metashape"
            )
        seen[label] = el
        sid = el.get("sensor_id")
        if sid not in sensors:
            raise FileFormatError(
                f"{where}{_line(el, lines)}: camera {label!r} names sensor_id {sid!r}, which "
                "is not among the chunk's <sensors>"
            )
        labels.append(label)
        ids.append(el.get("id", ""))
        sids.append(sid)
        en = (el.get("enabled") or "true").strip().lower()
        if en not in ("true", "1", "false", "0"):
            raise FileFormatError(
                f"{where}{_line(el, lines)}: camera {label!r} has enabled={en!r}; Metashape "
                "writes true or false"
            )
        enabled[k] = en in ("true", "1")
        master = el.get("master_id")
        masters.append("" if master in (None, el.get("id")) else master)
        ori = el.find("orientation")
        if ori is not None:
            o = (ori.text or "").strip()
            if o not in tuple("12345678"):
                raise FileFormatError(
                    f"{where}{_line(ori, lines)}: camera {label!r} has <orientation> {o!r}; "
                    "an EXIF orientation flag is 1 to 8"
                )
            orientation[k] = int(o)
        tf = el.find("transform")
        if tf is None:
            continue
        cid = el.get("component_id")
        if cid is not None and cid not in components:
            raise FileFormatError(
                f"{where}{_line(el, lines)}: camera {label!r} names component_id {cid!r}, "
                "which is not among the chunk's <components>"
            )
        aligned[k] = True
        tfs.append(tf)
        comp.append(cid)
    if tfs:  # the transforms' numbers in one vectorised call, checked all at once
        A = _transforms(tfs, [labels[k] for k in np.flatnonzero(aligned)], where, lines)
        R, t = A[:, :3, :3], A[:, :3, 3]
        comp_ids = np.array([c if c is not None else "" for c in comp])
        for cid, sim in components.items():  # component -> chunk, per component
            sel = comp_ids == cid
            if sim is not None and np.any(sel):
                sk, Rk, tk = sim
                R[sel] = Rk @ R[sel]
                t[sel] = sk * t[sel] @ Rk.T + tk
        exterior[aligned, :3] = s0 * t @ R0.T + t0
        Rw = R0 @ R  # camera -> world rotation
        exterior[aligned, 3:] = opk_from_rotations(_FLIP @ np.transpose(Rw, (0, 2, 1)))
    return MetashapePoses(
        labels=np.array(labels, dtype=str),
        camera_ids=np.array(ids, dtype=str),
        sensor_ids=np.array(sids, dtype=str),
        exterior=exterior,
        aligned=aligned,
        enabled=enabled,
        orientation=orientation,
        master_ids=np.array(masters, dtype=str),
        frame=frame,
        crs=crs,
        reference=reference,
        source=where,
        _root=root,
        _lines=lines,
    )


def _keys(name: str) -> tuple[str, ...]:
    """The names an image id may match a label by: itself, its file name, its stem."""
    base = PureWindowsPath(PurePosixPath(name).name).name
    stem = base.rsplit(".", 1)[0] if "." in base[1:] else base
    return tuple(dict.fromkeys((name, base, stem)))


def match_labels(image_ids, labels) -> np.ndarray:
    """The camera (row of ``labels``) of each image id, matched by label.

    An image id matches the camera whose label equals it, else its file name (the folders
    left out), else that name without its extension (Metashape's labels are the image
    files' names, usually without extension; Bundler lists and COLMAP models name the
    files).

    Parameters
    ----------
    image_ids : sequence (n,)
        The block's image ids (names or numbers).
    labels : sequence of str (m,)
        The cameras' labels (distinct).

    Returns
    -------
    numpy.ndarray of int, shape (n,)
        The row in ``labels`` of each image, -1 where none matches.

    Raises
    ------
    InputError
        Two images that match the same camera.
    """
    row = {lab: k for k, lab in enumerate(labels)}
    stems: dict[str, list[int]] = {}
    for k, lab in enumerate(labels):  # labels written with an extension match a stem too
        s = _keys(lab)[-1]
        if s != lab:
            stems.setdefault(s, []).append(k)
    out = np.full(len(image_ids), -1, dtype=np.int64)
    for i, iid in enumerate(image_ids):  # ids, one dictionary look-up each
        for key in _keys(str(iid)):
            if key in row:
                out[i] = row[key]
                break
            if len(stems.get(key, ())) == 1:
                out[i] = stems[key][0]
                break
    hit = out[out >= 0]
    u, c = np.unique(hit, return_counts=True)
    if np.any(c > 1):
        k = int(u[c > 1][0])
        names = [str(image_ids[i]) for i in np.flatnonzero(out == k)]
        raise InputError(
            f"images {', '.join(names)} all match the Metashape camera {labels[k]!r}: "
            "give the images distinct names"
        )
    return out


def _some(names, k: int = LISTED) -> str:
    names = [str(n) for n in names]
    return ", ".join(names[:k]) + (f" (and {len(names) - k} more)" if len(names) > k else "")


@dataclass(frozen=True)
class MetashapeStart:
    """What :func:`start_from_metashape` did.

    Attributes
    ----------
    n_images : int
        Images whose poses were taken.
    sensors : tuple of str
        The sensor ids that became the block's camera groups.
    fixed : tuple of str
        Those whose calibration Metashape kept fixed (no parameter free for them).
    disabled : tuple
        Images whose camera is disabled in Metashape (their poses were taken all the same).
    dropped_points : int
        Tie points that could not be triangulated with the Metashape poses (left out, with
        their observations).
    rms_px : float
        RMS of the reprojection residuals of the triangulated tie points, px: small (about
        the observations' noise) when the poses and the tie points are of the same project.
    frame : str
        As :attr:`MetashapePoses.frame`.
    """

    n_images: int
    sensors: tuple[str, ...]
    fixed: tuple[str, ...]
    disabled: tuple
    dropped_points: int
    rms_px: float
    frame: str

    def to_dict(self) -> dict:
        """JSON-ready fields (``rms_px`` None when no point was triangulated)."""
        return {
            "n_images": self.n_images,
            "sensors": list(self.sensors),
            "fixed": list(self.fixed),
            "disabled": [str(i) for i in self.disabled],
            "dropped_points": self.dropped_points,
            "rms_px": self.rms_px if np.isfinite(self.rms_px) else None,
            "frame": self.frame,
        }

    def summary(self) -> str:
        """One line for the command's output."""
        where = {
            "geocentric": "geocentric (ECEF) coordinates, m",
            "local": "the chunk's local coordinates",
            "internal": "Metashape's internal frame (the chunk has no transform: arbitrary "
            "scale)",
        }[self.frame]
        parts = [
            f"start values from Metashape: {self.n_images} image poses in {where}, "
            f"{len(self.sensors)} sensor(s) as camera groups"
            + (f" ({', '.join(self.fixed)} fixed in Metashape)" if self.fixed else ""),
            f"tie points triangulated (RMS {self.rms_px:.3g} px)",
        ]
        if self.dropped_points:
            parts.append(f"{self.dropped_points} tie point(s) not triangulated, left out")
        if self.disabled:
            parts.append(f"disabled in Metashape: {_some(self.disabled, 5)}")
        return "; ".join(parts)


def start_from_metashape(block: Block, poses: MetashapePoses) -> tuple[Block, MetashapeStart]:
    """The block with the poses and calibrations of a Metashape camera export as start values.

    Each image of ``block`` is matched to a Metashape camera by label
    (:func:`match_labels`). The block's camera groups become Metashape's sensors (a group
    per sensor the images use, its id the sensor's id), each with the sensor's calibration
    (the adjusted one, else the initial one) and the free parameters of the block's group of
    its first image (none for a sensor Metashape kept fixed); per-image offsets are reset.
    The exterior orientations are the cameras' poses in the export's world frame and the
    block's CRS that frame's (:attr:`MetashapePoses.crs`); the tie points are triangulated
    with them, and tie points that cannot be (too few rays, too small an angle, behind a
    camera) are left out with their observations.

    Parameters
    ----------
    block : Block
        A block of tie points (e.g. read from a Bundler file or COLMAP model that Metashape
        exported from the same project); control points, GNSS and IMU are refused (they are
        in the block's frame, the poses in Metashape's).
    poses : MetashapePoses
        From :func:`read_metashape_cameras`.

    Returns
    -------
    (Block, MetashapeStart)
        The new block and what was done.

    Raises
    ------
    InputError
        Images of the block that match no camera (listed, with some of the labels), images
        whose camera Metashape did not align or is a non-master camera of a multi-camera
        system (listed), images with an EXIF orientation
        other than 1 (listed), an image size that is not its sensor's resolution, a block
        with control or check points, GNSS or IMU.
    FileFormatError
        A sensor the images use that is not a frame camera (its type named) or has no
        calibration.
    """
    from .triangulate import triangulate

    src = poses.source
    if np.any(block.role != "tie"):
        raise InputError(
            f"the block has {int(np.sum(block.role != 'tie'))} control/check point(s): their "
            f"coordinates are in the block's frame, the poses of {src} in Metashape's; start "
            "a block of tie points (a Bundler file or COLMAP model Metashape exported) from "
            "it, or give the block its own start values"
        )
    if np.any(np.isfinite(block.gnss)) or np.any(np.isfinite(block.imu)):
        raise InputError(
            f"the block has GNSS/IMU observations in its own frame and the poses of {src} "
            "are in Metashape's: leave out the GNSS/IMU, or give the block its own start values"
        )
    rows = match_labels(block.image_ids.tolist(), poses.labels.tolist())
    if np.any(rows < 0):
        missing = block.image_ids[rows < 0].tolist()
        raise InputError(
            f"{len(missing)} image(s) of the block match no camera label of {src}: "
            f"{_some(missing)}; its labels are {_some(poses.labels.tolist(), 5)} (an image "
            "matches the label equal to its name, its file name or that without extension)"
        )
    slave = poses.master_ids[rows] != ""
    if np.any(slave):
        k = rows[slave]
        raise InputError(
            f"{int(slave.sum())} image(s) of the block are cameras of a Metashape multi-camera "
            f"system other than its master: {_some(poses.labels[k])} (master_id "
            f"{poses.master_ids[k[0]]} of the first); their poses are the master's with the "
            "sensor's offset, which photogeom does not read: remove those images from the "
            "block, or export them from a chunk without the multi-camera system"
        )
    unaligned = ~poses.aligned[rows]
    if np.any(unaligned):
        raise InputError(
            f"{int(unaligned.sum())} image(s) of the block are not aligned in {src} (their "
            f"cameras have no <transform>): {_some(poses.labels[rows[unaligned]])}; align "
            "them in Metashape (Workflow > Align Photos) and export again, or remove them "
            "from the block"
        )
    rotated = poses.orientation[rows] != 1
    if np.any(rotated):
        raise InputError(
            f"{int(rotated.sum())} image(s) have an EXIF orientation other than 1 in {src}: "
            f"{_some(poses.labels[rows[rotated]])}; photogeom takes the pixels as stored, "
            "unrotated: export the images without an orientation flag"
        )
    sensor_of = poses.sensor_ids[rows]
    used = list(dict.fromkeys(sensor_of.tolist()))
    cals, fixed, free, variant = {}, [], {}, {}
    sizes = block.image_sizes()
    keys = [int(s) if s.isdigit() else s for s in used]
    if len(set(keys)) != len(keys) or not all(isinstance(k, int) for k in keys):
        keys = used
    for key, sid in zip(keys, used):
        sc = poses.sensor(sid)
        cal = sc.calibration
        imgs = np.flatnonzero(sensor_of == sid)
        bad = np.any(sizes[imgs] != [cal.width, cal.height], axis=1)
        if np.any(bad):
            i = int(imgs[bad][0])
            raise InputError(
                f"image {block.image_ids[i]} is {sizes[i, 0]:g} x {sizes[i, 1]:g} px in the "
                f"block but its sensor {sid} ({sc.label!r}) in {src} is {cal.width} x "
                f"{cal.height} px: the block's pixels and Metashape's calibration must be of "
                "the same images"
            )
        cals[key] = cal
        group = block.camera_ids[block.image_camera[imgs[0]]].item()
        if poses.sensor_fixed(sid):
            fixed.append(sid)
            free[key] = ()
        else:
            free[key] = block.free[group]
        variant[key] = block.image_variant[group]
    new = Block.from_arrays(
        cameras=cals,
        image_ids=block.image_ids,
        image_camera=[keys[used.index(s)] for s in sensor_of.tolist()],
        exterior=poses.exterior[rows],
        point_ids=block.point_ids,
        xyz=np.zeros_like(block.xyz),
        obs_image_ids=block.observations.image_ids,
        obs_point_ids=block.observations.point_ids,
        uv=block.observations.uv,
        sigma=block.observations.sigma,
        free=free,
        image_variant=variant,
        crs=poses.crs,
    )
    new = new.replace(colmap_images=block.colmap_images)
    tri = triangulate(new)
    ok = tri.ok
    xyz = np.where(ok[:, None], tri.xyz, 0.0)
    new = new.replace(xyz=xyz)
    dropped = int(np.sum(~ok))
    if dropped:
        new = new.select_points(ok)
    rms = float(np.sqrt(np.mean(tri.rms[tri.ok] ** 2))) if np.any(tri.ok) else float("nan")
    info = MetashapeStart(
        n_images=int(block.n_images),
        sensors=tuple(used),
        fixed=tuple(fixed),
        disabled=tuple(block.image_ids[~poses.enabled[rows]].tolist()),
        dropped_points=dropped,
        rms_px=rms,
        frame=poses.frame,
    )
    return new, info
