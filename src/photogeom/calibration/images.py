"""Correct image files and folders with residual grids, keeping format and metadata.

Pixels are read with OpenCV (``IMREAD_UNCHANGED``: bit depth and alpha kept, EXIF
orientation not applied, so pixel coordinates stay those of the bundle adjustment) and the
metadata with Pillow. OpenCV turns TIFF pixels by their Orientation tag (274) whatever the
flags, so a TIFF is decoded from a copy whose tag says 1 (as stored): the image is
corrected and written in its stored layout, the original tag kept. The corrected image is
written in the original format:

* JPEG (8-bit grey or colour): Pillow, with the original quantisation tables and chroma
  subsampling (the quality is kept), EXIF, XMP and ICC profile, its other APPn and comment
  segments copied (comments, extended XMP, IPTC, vendors' segments); of a JPEG with preview
  images (a multi-picture index, APP2 "MPF") the main image, the previews left out (said
  in a note);
* TIFF with 8-bit channels or 16-bit grey: Pillow, with EXIF, XMP (tag 700) and ICC
  profile, with its compression;
* PNG (any bit depth and channels): in its own colour type and bit depth, the original's
  metadata chunks copied unchanged (EXIF, ICC profile, colour space, resolution, text and
  XMP; text and XMP on their side of the image data), also those that follow the image
  data. Grey with alpha stays grey with alpha (OpenCV
  decodes it as RGBA); a palette image keeps its palette and transparency and is resampled
  by nearest neighbour (blending indices would give unrelated colours; said in a note); the
  transparent colour (tRNS) of a grey image is kept (that of an RGB image is decoded by
  OpenCV as alpha and written as RGBA);
* other TIFFs (16-bit colour, float): the pixels by OpenCV (its compression kept where
  OpenCV writes it: none, LZW, Deflate, PackBits), the original's tags grafted onto its file
  (orientation, resolution, ICC profile, XMP, EXIF and GPS IFDs; from little- and
  big-endian TIFFs, written little-endian as OpenCV writes);
* anything else (a BigTIFF 16-bit colour TIFF): OpenCV, pixels exact, metadata not kept
  (said in the result's ``notes``).

Every file is encoded in memory and written atomically (temporary file, then rename):
an interrupted or failed image leaves no partial file.

Folders are processed in parallel: local processes, or a Dask cluster
(``dask.distributed``: a ``LocalCluster`` or the scheduler at an address). Dask is an
optional dependency (``pip install "photogeom[dask]"``).
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
import struct
import threading
import zlib
from collections.abc import Callable, Mapping
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, replace
from glob import escape as glob_escape
from pathlib import Path

import numpy as np

from ..atomicfile import atomic_write_bytes, remove_temporaries
from ..errors import FileFormatError, InputError, OutputError, PhotogeomError
from ..io.sources import device_message, input_kind, read_input_bytes
from .correction import INTERPOLATIONS, correct_image
from .grid import ResidualGrid

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".tif", ".tiff", ".png")
#: Values of output pixels whose source lies outside the image (``correct_image``'s border)
BORDER_MODES = ("replicate", "constant", "reflect")


@dataclass
class FolderResult:
    """Outcome of :func:`correct_folder`.

    Attributes
    ----------
    written : dict
        ``image id -> output path`` of the images corrected.
    failures : dict
        ``image id -> message`` of the images that could not be corrected (missing or
        unreadable files, size mismatch); nothing was written for them.
    skipped : list of str
        Image files of the folder without a grid (not corrected).
    notes : dict
        ``image id -> note`` (e.g. metadata that the format did not let us keep).
    missing : list
        The image ids of ``failures`` that have no file in the folder (the others' files
        were found and failed), in the order of the grids.
    """

    written: dict = field(default_factory=dict)
    failures: dict = field(default_factory=dict)
    skipped: list = field(default_factory=list)
    notes: dict = field(default_factory=dict)
    missing: list = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.failures

    def to_dict(self) -> dict:
        """JSON-ready summary.

        Returns
        -------
        dict
            ``written`` (image -> output path), ``failures`` (image -> reason), ``skipped``,
            ``notes``, ``missing`` (the failures without a file); keys as text.
        """
        return {
            "written": {str(k): str(v) for k, v in self.written.items()},
            "failures": {str(k): v for k, v in self.failures.items()},
            "skipped": list(self.skipped),
            "notes": {str(k): v for k, v in self.notes.items()},
            "missing": [str(k) for k in self.missing],
        }


# --------------------------------------------------------------------------- one file
def _decode_quietly(cv2, data: np.ndarray):
    """``cv2.imdecode(data, IMREAD_UNCHANGED)`` with OpenCV's own log lines silenced while it
    runs (a damaged TIFF prints libtiff's "TIFF_Error ..." lines on stderr beside the named
    failure photogeom reports). The log level is process-wide: restored afterwards."""
    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging is None:  # pragma: no cover - OpenCV builds without the logging module
        return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    level = logging.getLogLevel()
    logging.setLogLevel(logging.LOG_LEVEL_SILENT)
    try:
        return cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    finally:
        logging.setLogLevel(level)


# libjpeg's warnings about the entropy-coded data (it decodes on, with grey or smeared
# blocks where the data is damaged): "Corrupt JPEG data: bad Huffman code", "...: premature
# end of data segment", "...: N extraneous bytes before marker", "Premature end of JPEG file"
_JPEG_DAMAGE = (b"Corrupt JPEG data", b"Premature end of JPEG file")
_STDERR_LOCK = threading.Lock()


def _decode_capturing(cv2, data: np.ndarray, taken: tuple[bytes, ...]):
    """``_decode_quietly`` with the lines of standard error (file descriptor 2) that the
    codec libraries print with ``fprintf(stderr)`` while it runs and OpenCV does not pass
    on: ``(pixels, lines)``, the lines that start with one of ``taken`` (bytes, stripped);
    the others are written back to standard error."""
    import sys
    import tempfile

    with _STDERR_LOCK, tempfile.TemporaryFile() as captured:
        if sys.stderr is not None:
            sys.stderr.flush()
        try:
            saved: int | None = os.dup(2)
        except OSError:  # no standard error (a process started without one)
            saved = None
        try:
            os.dup2(captured.fileno(), 2)
            try:
                pixels = _decode_quietly(cv2, data)
            finally:
                if saved is None:
                    os.close(2)
                else:
                    os.dup2(saved, 2)
        finally:
            if saved is not None:
                os.close(saved)
        captured.seek(0)
        text = captured.read()
    lines = text.splitlines(keepends=True)
    other = b"".join(ln for ln in lines if not ln.startswith(taken))
    if other and saved is not None:
        os.write(2, other)
    return pixels, [ln.strip() for ln in lines if ln.startswith(taken)]


def _decode_jpeg_checked(cv2, data: np.ndarray, path: Path):
    """``_decode_quietly`` for a JPEG, refusing one whose data libjpeg found damaged.

    OpenCV's JPEG decoder returns an image whatever libjpeg warns: a JPEG with damaged
    scan data decodes to pixels that are partly garbage (in a test, half of a 640 x 480
    image off by 57 grey levels on average), which would be "corrected" and written as a
    good image. libjpeg prints its warnings on standard error, read while the file
    decodes (:func:`_decode_capturing`)."""
    pixels, damage = _decode_capturing(cv2, data, _JPEG_DAMAGE)
    if damage and pixels is not None:
        first = damage[0].decode("latin-1")
        more = f" (and {len(damage) - 1} more warning(s))" if len(damage) > 1 else ""
        raise FileFormatError(
            f"{path}: damaged JPEG data (libjpeg: {first}{more}); its decoded pixels would "
            "be partly wrong, so it is not corrected: copy the file again from the camera "
            "or the original source"
        )
    return pixels


def _decode_png_named(cv2, data: np.ndarray, path: Path):
    """``_decode_quietly`` for a PNG; a file libpng refuses is a named failure with
    libpng's reason, and its "libpng error: ..." line no longer appears beside it on
    standard error."""
    pixels, lines = _decode_capturing(cv2, data, (b"libpng error", b"libpng warning"))
    errors = [e for e in lines if e.startswith(b"libpng error")]
    # a metadata chunk with a wrong CRC is left out and said in the image's note
    # (_png_metadata_chunks); libpng's "libpng warning: iTXt: CRC error" beside it went
    # to standard error without the file's name
    copied = {*_PNG_BEFORE_IDAT, b"eXIf", *_PNG_ANYWHERE}
    other = [
        e
        for e in lines
        if e.startswith(b"libpng warning")
        and not (e.endswith(b": CRC error") and e.split(b":")[1].strip() in copied)
    ]
    if other:
        with contextlib.suppress(OSError):
            os.write(2, b"".join(e + b"\n" for e in other))
    if pixels is None and errors:
        why = b"; ".join(e.split(b":", 1)[-1].strip() for e in errors).decode("latin-1")
        raise FileFormatError(
            f"{path}: not a readable image (libpng: {why}); the file is damaged"
        )
    if errors:  # decoded all the same: the lines go where they were going
        with contextlib.suppress(OSError):
            os.write(2, b"".join(e + b"\n" for e in errors))
    return pixels


def _read(path: Path):
    """Pixels (OpenCV order: BGR[A]) and the Pillow metadata of an image file."""
    import cv2
    from PIL import Image

    kind = input_kind(path)
    if kind == "missing":
        raise FileFormatError(f"{path}: no such image file")
    if kind == "folder":
        raise FileFormatError(f"{path}: a folder, not an image file")
    if kind == "device":
        raise FileFormatError(device_message(path, "image"))
    try:  # decoded from memory, read once (a pipe once per command): no copy of the bytes
        raw = read_input_bytes(path, None)
    except OSError as exc:
        raise FileFormatError(f"cannot read image {path}: {exc.strerror or exc}") from None
    data = np.frombuffer(raw, dtype=np.uint8)
    # OpenCV turns TIFF pixels by their Orientation tag (274) even with IMREAD_UNCHANGED
    # (and IMREAD_IGNORE_ORIENTATION): decode a copy whose tag says "as stored" instead.
    stored = _tiff_as_stored(raw)
    if stored is None:
        raise FileFormatError(
            f"{path}: the TIFF Orientation tag (274) is not a single number, so the stored "
            "pixel layout cannot be read without turning the image; rewrite the file with "
            "a plain Orientation value (1-8)"
        )
    if stored is not raw:
        data = np.frombuffer(stored, dtype=np.uint8)
    damage = _png_chunk_beyond_end(raw)
    if damage:
        raise FileFormatError(f"{path}: {damage}; the file is damaged or cut short")
    try:
        if not data.size:
            pixels = None
        elif raw[:3] == b"\xff\xd8\xff":  # JPEG
            pixels = _decode_jpeg_checked(cv2, data, path)
        elif raw[:8] == _PNG_SIGNATURE:
            pixels = _decode_png_named(cv2, data, path)
        else:
            pixels = _decode_quietly(cv2, data)
    except cv2.error as exc:  # a damaged header: e.g. a width over OpenCV's limit
        msg = str(exc).strip().splitlines()[-1]
        raise FileFormatError(
            f"{path}: not a readable image (OpenCV refuses it: {msg}); the file is damaged "
            "or not an image"
        ) from None
    if pixels is None:
        raise FileFormatError(f"{path}: not a readable image (corrupt or unknown format)")
    meta: dict = {}
    try:
        with Image.open(io.BytesIO(raw)) as im:
            # a JPEG with a multi-picture index (APP2 "MPF": a camera's preview image after
            # the main one, as Sony and DJI cameras write) opens as "MPO": the main image
            # is an ordinary JPEG, written as one (the previews, of the uncorrected image,
            # are left out with their index); it was written by OpenCV, its EXIF, XMP, ICC
            # profile and quantisation tables lost
            meta["format"] = "JPEG" if im.format == "MPO" else im.format
            meta["mode"] = im.mode
            info = im.info
            if im.format in ("JPEG", "MPO"):
                meta["jpeg_previews"] = getattr(im, "n_frames", 1) - 1
                meta["jpeg_segments"] = _jpeg_metadata_segments(raw)
                from PIL import JpegImagePlugin

                meta["qtables"] = getattr(im, "quantization", None)
                try:
                    meta["subsampling"] = JpegImagePlugin.get_sampling(im)
                except Exception:  # pragma: no cover - unusual JPEG
                    meta["subsampling"] = None
                meta["xmp"] = info.get("xmp")
            elif im.format == "TIFF":
                # as stored: Pillow's im.size is turned by the Orientation tag
                meta["stored_size"] = (im.tag_v2.get(256), im.tag_v2.get(257))
                meta["xmp"] = im.tag_v2.get(700)
                meta["compression"] = info.get("compression")
            elif im.format == "PNG":
                meta["xmp"] = info.get("XML:com.adobe.xmp")
            exif = info.get("exif")
            if exif is None and im.format == "TIFF":
                exif = im.getexif()
                o = exif.get(_TIFF_ORIENTATION)
                if isinstance(o, bytes) and len(o) == 1:  # a BYTE tag: Pillow cannot save it
                    exif[_TIFF_ORIENTATION] = o[0]
            meta["exif"] = exif
            meta["orientation"] = _exif_orientation(im)
            meta["icc_profile"] = info.get("icc_profile")
            meta["dpi"] = info.get("dpi")
            if meta["format"] == "JPEG" and info.get("jfif_unit") not in (1, 2):
                # Pillow's dpi of a JPEG without a JFIF unit comes from the EXIF resolution,
                # or is its default of 72 when the EXIF has none: not the image's, not kept
                if _TIFF_XRESOLUTION not in im.getexif():
                    meta["dpi"] = None
    except Exception:
        # OpenCV decoded it; Pillow cannot read it: pixels only.
        meta = {}
    if meta.get("mode") == "CMYK" and pixels.ndim == 3 and pixels.shape[2] == 4:
        # OpenCV decodes a CMYK TIFF as RGB and an opaque alpha channel the original does
        # not have (written back as RGBA under the original's CMYK tags, the file was
        # unreadable): the RGB pixels only, as of a CMYK JPEG
        pixels = np.ascontiguousarray(pixels[..., :3])
    if raw[:8] == _PNG_SIGNATURE:
        meta["png_chunks"] = _png_metadata_chunks(raw)
        pixels = _png_own_coding(raw, pixels, meta)
    elif meta.get("format") == "TIFF" and not (
        pixels.dtype == np.uint8 or (pixels.dtype == np.uint16 and pixels.ndim == 2)
    ):  # written by OpenCV, not Pillow: the tags are grafted onto its file (see _encode)
        meta["tiff_bytes"] = raw
    stored_size = meta.get("stored_size")
    if stored_size is not None and stored_size != (pixels.shape[1], pixels.shape[0]):
        raise FileFormatError(  # pragma: no cover - OpenCV turned the pixels after all
            f"{path}: decoded as {pixels.shape[1]} x {pixels.shape[0]} px, the file stores "
            f"{stored_size[0]} x {stored_size[1]} px: the pixels were turned on reading"
        )
    return pixels, meta


#: What each EXIF orientation (tag 274) other than 1 does to the stored pixels when shown.
EXIF_TURNS = {
    2: "mirrored left-right",
    3: "turned by 180 degrees",
    4: "mirrored top-bottom",
    5: "mirrored and turned by 90 degrees",
    6: "turned by 90 degrees clockwise",
    7: "mirrored and turned by 90 degrees",
    8: "turned by 90 degrees counter-clockwise",
}


def _exif_orientation(im) -> int:
    """The EXIF orientation (tag 274) of an open Pillow image; 1 when it has none or it is
    not one number."""
    o = im.getexif().get(_TIFF_ORIENTATION, 1)
    if isinstance(o, bytes) and len(o) == 1:
        o = o[0]
    elif isinstance(o, tuple) and len(o) == 1:
        o = o[0]
    try:
        return int(o)
    except (TypeError, ValueError):
        return 1


def orientation_note(orientation: int) -> str | None:
    """The note of an image file whose EXIF orientation shows it otherwise than stored: it
    is corrected as stored, which is right only for a grid of the stored pixels.

    Parameters
    ----------
    orientation : int
        The file's EXIF orientation (tag 274; 1 or an unknown value: none).

    Returns
    -------
    str or None
        The note, or None for orientation 1 (and values EXIF does not define).
    """
    turn = EXIF_TURNS.get(orientation)
    if turn is None:
        return None
    return (
        f"EXIF orientation {orientation} (shown {turn}): corrected as stored, the tag kept, "
        "which is right for a grid of the stored pixels (COLMAP, Bundler and photogeom's own "
        "coordinates) and wrong for one fitted to coordinates of the image as shown (a tool "
        "that applied the orientation)"
    )


# JPEG header segments Pillow writes itself from what it read (JFIF, the EXIF it took,
# the main XMP packet, the ICC profile) or that describe how the original was coded or
# what follows it (Adobe APP14: the colour transform of the original coding; MPF: the
# offsets of preview images that are not written); every other APPn and comment (COM)
# segment is copied as it was.
_JPEG_WRITTEN_BY_PILLOW = (
    (0xE0, b"JFIF\0"),
    (0xE2, b"ICC_PROFILE\0"),
    (0xE2, b"MPF\0"),
    (0xEE, b"Adobe"),
)
_JPEG_EXIF = b"Exif\0\0"
_JPEG_XMP = b"http://ns.adobe.com/xap/1.0/\0"


def _jpeg_header_segments(data: bytes) -> list[tuple[int, int, int]]:
    """``(marker, start, end)`` of the marker segments before the first scan (SOS) or the
    first frame header's tables, bytes ``data[start:end]`` with marker and length; the
    walk stops at a malformed length (the decoder has accepted the file)."""
    out, i, n = [], 2, len(data)
    while i + 4 <= n and data[i] == 0xFF:
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte before a marker
            i += 1
            continue
        if marker == 0xDA or marker == 0xD9 or 0xD0 <= marker <= 0xD7 or marker == 0x01:
            break
        end = i + 2 + struct.unpack(">H", data[i + 2 : i + 4])[0]
        if end > n or end < i + 4:
            break
        out.append((marker, i, end))
        i = end
    return out


def _jpeg_metadata_segments(data: bytes) -> list[bytes]:
    """The original's APPn and COM segments (whole, marker and length included, in their
    order) that Pillow does not write: comments, extended XMP (the part of an XMP packet
    over 64 KB, APP1 ``http://ns.adobe.com/xmp/extension/``), IPTC (APP13), vendors' own
    segments (APP3-APP15 of cameras), a second EXIF segment."""
    segs = _jpeg_header_segments(data)
    pay = [(m, data[a + 4 : b]) for m, a, b in segs]
    exif = next((k for k, (m, p) in enumerate(pay) if m == 0xE1 and p[:6] == _JPEG_EXIF), None)
    xmps = [k for k, (m, p) in enumerate(pay) if m == 0xE1 and p[:29] == _JPEG_XMP]
    taken = {exif, xmps[-1] if xmps else None}  # the ones Pillow reads (first EXIF, last XMP)
    keep = []
    for k, (m, p) in enumerate(pay):
        if not (0xE0 <= m <= 0xEF or m == 0xFE) or k in taken:
            continue
        if any(m == wm and p.startswith(wp) for wm, wp in _JPEG_WRITTEN_BY_PILLOW):
            continue
        keep.append(data[segs[k][1] : segs[k][2]])
    return keep


def _jpeg_with_segments(encoded: bytes, segments: list[bytes]) -> bytes:
    """``encoded`` (Pillow's JPEG) with ``segments`` after its own APPn and COM segments,
    before its tables (so an extended XMP follows the main packet)."""
    if not segments:
        return encoded
    at = 2
    for m, _a, b in _jpeg_header_segments(encoded):
        if not (0xE0 <= m <= 0xEF or m == 0xFE):
            break
        at = b
    return encoded[:at] + b"".join(segments) + encoded[at:]


_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# PNG chunks of metadata that do not depend on how the pixels are coded (colour type,
# palette, compression): colour space and ICC profile, resolution, EXIF, text and XMP
_PNG_BEFORE_IDAT = (b"iCCP", b"sRGB", b"gAMA", b"cHRM", b"cICP", b"mDCV", b"cLLI", b"pHYs")
_PNG_ANYWHERE = (b"tEXt", b"zTXt", b"iTXt", b"tIME")


def _png_chunk_beyond_end(data: bytes) -> str | None:
    """Why the chunk list of a PNG file runs past its end, or None (also for other files).

    OpenCV's PNG decoder allocates a chunk of the length its header states before reading
    it: a 2 kB file whose image data chunk claimed 1.3 GB took 2.3 s and 1.2 GB of memory
    to be found unreadable. One walk over the chunk headers (linear in the chunks)."""
    if data[:8] != _PNG_SIGNATURE:
        return None
    at = len(_PNG_SIGNATURE)
    while at + 8 <= len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        kind = data[at + 4 : at + 8]
        end = at + 12 + length
        if end > len(data):
            return (
                f"PNG chunk {kind.decode('latin-1')!r} at byte {at} announces {length} bytes, "
                f"but the file ends at byte {len(data)}"
            )
        if kind == b"IEND":
            return None
        at = end
    return None


def _png_metadata_chunks(
    data: bytes,
) -> tuple[list[bytes], list[bytes], list[bytes], list[str]]:
    """The metadata chunks of a PNG file, whole (length, type, data, CRC): those that must
    come before the image data (colour space, ICC profile, resolution; EXIF, which some
    writers put after the image data and libpng then ignores), the text chunks (text,
    XMP, time) before the image data and those after it; and the metadata chunks left out
    because their CRC is wrong (``'iTXt' at byte 33``: libpng warns and ignores them, and
    copied they made the written file damaged in turn). A damaged chunk list ends the walk
    (the decoders report the damage)."""
    before: list[bytes] = []
    text_before: list[bytes] = []
    text: list[bytes] = []
    damaged: list[str] = []
    seen_data = False
    at = len(_PNG_SIGNATURE)
    while at + 12 <= len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        kind = data[at + 4 : at + 8]
        end = at + 12 + length
        if end > len(data):
            break
        kept = kind in _PNG_BEFORE_IDAT or kind == b"eXIf" or kind in _PNG_ANYWHERE
        (crc,) = struct.unpack(">I", data[end - 4 : end])
        if kept and zlib.crc32(data[at + 4 : end - 4]) != crc:
            damaged.append(f"{kind.decode('latin-1')!r} at byte {at}")
        elif kind in _PNG_BEFORE_IDAT or kind == b"eXIf":
            before.append(data[at:end])
        elif kind in _PNG_ANYWHERE:
            (text if seen_data else text_before).append(data[at:end])
        elif kind == b"IDAT":
            seen_data = True
        elif kind == b"IEND":
            break
        at = end
    return before, text_before, text, damaged


def _png_chunk(data: bytes, kind: bytes) -> bytes | None:
    """The first whole chunk (length, type, data, CRC) of type ``kind`` before the image
    data of a PNG file, or None."""
    at = len(_PNG_SIGNATURE)
    while at + 12 <= len(data):
        (length,) = struct.unpack(">I", data[at : at + 4])
        end = at + 12 + length
        if data[at + 4 : at + 8] == kind and end <= len(data):
            return data[at:end]
        if data[at + 4 : at + 8] in (b"IDAT", b"IEND") or end > len(data):
            return None
        at = end
    return None


def _png_own_coding(raw: bytes, pixels: np.ndarray, meta: dict) -> np.ndarray:
    """The pixels of a PNG in its own colour type where OpenCV decodes another.

    * palette (colour type 3): the indices (Pillow), the palette and its transparency
      kept in ``meta["png_palette"]`` (bit depth, PLTE chunk, tRNS chunk or None); OpenCV
      gives RGB(A);
    * grey with alpha (type 4): the grey and alpha channels ((h, w, 2); the bit depth in
      ``meta["png_grey_alpha"]``); OpenCV gives RGBA;
    * grey or RGB with a transparent colour (tRNS, types 0 and 2, 8 or 16 bits): OpenCV
      drops the chunk; it is kept in ``meta["png_trns"]`` (a colour key, valid for the
      pixels written in the same type and depth).
    """
    from PIL import Image

    if len(raw) < 33 or raw[12:16] != b"IHDR":
        return pixels
    depth, ctype = raw[24], raw[25]
    if ctype == 3:
        with Image.open(io.BytesIO(raw)) as im:
            if im.mode != "P":  # pragma: no cover - Pillow reads every palette PNG as P
                return pixels
            index = np.asarray(im, dtype=np.uint8)
        if index.shape != pixels.shape[:2]:  # pragma: no cover - the same file
            return pixels
        meta["png_palette"] = (depth, _png_chunk(raw, b"PLTE"), _png_chunk(raw, b"tRNS"))
        return np.ascontiguousarray(index)
    if ctype == 4 and pixels.ndim == 3 and pixels.shape[2] == 4:
        meta["png_grey_alpha"] = depth
        return np.ascontiguousarray(pixels[..., [0, 3]])
    if ctype in (0, 2) and depth in (8, 16):
        trns = _png_chunk(raw, b"tRNS")
        if trns is not None and pixels.shape[2:] == (() if ctype == 0 else (3,)):
            meta["png_trns"] = trns
    return pixels


def _png_whole_chunk(kind: bytes, data: bytes) -> bytes:
    """A PNG chunk: length, type, data, CRC."""
    import zlib

    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def _png_encode(pixels: np.ndarray, depth: int, colour_type: int, chunks: list) -> bytes:
    """A PNG of palette indices (colour type 3, bit depth 1-8) or grey and alpha (type 4,
    8 or 16 bits: ``pixels`` (h, w, 2)) with ``chunks`` (PLTE, tRNS) before the image data.

    Rows are filtered with "None" for indices (as the PNG specification advises for
    palettes) and "Up" otherwise, and compressed with zlib level 6.
    """
    import zlib

    h, w = pixels.shape[:2]
    if depth < 8:
        per = 8 // depth
        a = np.pad(pixels.astype(np.uint8), ((0, 0), (0, (-w) % per))).reshape(h, -1, per)
        shifts = (depth * np.arange(per - 1, -1, -1)).astype(np.uint8)
        rows = np.bitwise_or.reduce(a << shifts, axis=2).astype(np.uint8)
    else:
        big = pixels.astype(">u2" if depth == 16 else np.uint8)
        rows = np.ascontiguousarray(big).reshape(h, -1).view(np.uint8)
    filtered = rows.copy()
    kind = 0 if colour_type == 3 else 2
    if kind == 2:
        filtered[1:] -= rows[:-1]  # "Up": the byte above subtracted, modulo 256
    body = np.hstack([np.full((h, 1), kind, np.uint8), filtered])
    return b"".join([
        _PNG_SIGNATURE,
        _png_whole_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, depth, colour_type, 0, 0, 0)),
        *[c for c in chunks if c is not None],
        _png_whole_chunk(b"IDAT", zlib.compress(body.tobytes(), 6)),
        _png_whole_chunk(b"IEND", b""),
    ])  # fmt: skip


def _png_with_chunks(
    png: bytes, chunks: tuple[list[bytes], list[bytes], list[bytes]]
) -> bytes:
    """``png`` (an encoder's output without metadata) with the original's metadata chunks:
    colour space, ICC, resolution and EXIF right after IHDR, then the text chunks that
    came before the image data (XMP there, where readers that stop at the image data find
    it, as the XMP specification encourages), the others before IEND."""
    before, text_before, text = chunks
    (ihdr_length,) = struct.unpack(">I", png[8:12])
    head = 8 + 12 + ihdr_length  # signature and IHDR
    tail = png.rindex(b"IEND") - 4  # the IEND chunk: length, type, CRC
    return b"".join(
        [png[:head], *before, *text_before, png[head:tail], *text, png[tail:]]
    )


_TIFF_ORIENTATION = 274
_TIFF_XRESOLUTION = 282
# TIFF field types that hold one integer in an IFD entry's value field: size, format
_TIFF_INTEGERS = {
    1: (1, "B"),  # BYTE and SBYTE: written by some tools for small tags
    6: (1, "b"),
    3: (2, "H"),
    4: (4, "I"),
    8: (2, "h"),
    9: (4, "i"),
    16: (8, "Q"),
    17: (8, "q"),
}


def _tiff_as_stored(data: bytes) -> bytes | None:
    """TIFF bytes whose first image is decoded as stored (the same object for other files).

    The Orientation tag (274) of the first IFD is set to 1 in a copy; the pixel data and
    every other byte are unchanged. Returns ``data`` itself when it is not a TIFF, the
    IFD cannot be walked (the decoder reports the damage), or there is nothing to change;
    None when the tag is present but not a single integer (it cannot be neutralised).
    """
    if len(data) < 8 or data[:2] not in (b"II", b"MM"):
        return data
    e = "<" if data[:2] == b"II" else ">"
    magic = struct.unpack(e + "H", data[2:4])[0]
    try:
        if magic == 42:  # classic TIFF
            ifd = struct.unpack(e + "I", data[4:8])[0]
            (n,) = struct.unpack(e + "H", data[ifd : ifd + 2])
            first, size, count_fmt = ifd + 2, 12, "I"
        elif magic == 43:  # BigTIFF
            ifd = struct.unpack(e + "Q", data[8:16])[0]
            (n,) = struct.unpack(e + "Q", data[ifd : ifd + 8])
            first, size, count_fmt = ifd + 8, 20, "Q"
        else:
            return data
        for k in range(n):
            at = first + k * size
            tag, typ = struct.unpack(e + "HH", data[at : at + 4])
            if tag != _TIFF_ORIENTATION:
                continue
            count_size = struct.calcsize(count_fmt)  # the value field has the same size
            value_at = at + 4 + count_size
            (count,) = struct.unpack(e + count_fmt, data[at + 4 : value_at])
            if count != 1 or typ not in _TIFF_INTEGERS or _TIFF_INTEGERS[typ][0] > count_size:
                return None
            width, fmt = _TIFF_INTEGERS[typ]
            if struct.unpack(e + fmt, data[value_at : value_at + width])[0] == 1:
                return data
            out = bytearray(data)
            out[value_at : value_at + width] = struct.pack(e + fmt, 1)
            return bytes(out)
    except struct.error:
        return data  # a damaged IFD: the decoders say so
    return data


# TIFF tags that describe the pixel layout, not the picture: every TIFF has some, and the
# OpenCV writer sets its own (their loss is no loss of metadata)
_TIFF_LAYOUT_TAGS = frozenset(
    {254, 255, 256, 257, 258, 259, 262, 266, 273, 277, 278, 279, 280, 281, 282, 283, 284}
    | {296, 317, 320, 322, 323, 324, 325, 338, 339, 340, 341, 347, 530, 531, 532}
)


# TIFF field types: bytes per value (13: IFD, an offset)
_TIFF_TYPE_SIZES = dict(zip(range(1, 14), (1, 1, 2, 4, 8, 1, 1, 2, 4, 8, 4, 8, 4), strict=True))
# tags whose value is the offset of another IFD: EXIF, GPS, interoperability
_TIFF_SUB_IFDS = frozenset({34665, 34853, 40965})
# offsets into the original file that are not metadata: SubIFDs (thumbnails, DNG) and an
# old-style JPEG thumbnail; not copied
_TIFF_OTHER_OFFSETS = frozenset({330, 513, 514})
# resolution: a layout tag for the writer, but the image's DPI for its user
_TIFF_RESOLUTION = frozenset({282, 283, 296})
# the original's compressions that OpenCV writes as well: none, LZW, Deflate, PackBits
_TIFF_COMPRESSIONS = frozenset({1, 5, 8, 32773, 32946})


# bytes of one element of each TIFF field type: the unit whose byte order the file sets
_TIFF_ELEMENT_SIZES = dict(zip(range(1, 14), (1, 1, 2, 4, 4, 1, 1, 2, 4, 4, 4, 8, 4), strict=True))


def _tiff_order(data: bytes) -> str | None:
    """``"<"`` or ``">"``: the byte order of a classic TIFF; None for other files."""
    if data[:4] == b"II*\x00":
        return "<"
    if data[:4] == b"MM\x00*":
        return ">"
    return None


def _tiff_raw_ifd(data: bytes, at: int, order: str) -> list[tuple[int, int, int, bytes]]:
    """The entries ``(tag, type, count, value field)`` of the classic TIFF IFD at offset
    ``at`` in byte order ``order``; the value field as its 4 bytes."""
    (n,) = struct.unpack_from(order + "H", data, at)
    out = []
    for k in range(n):  # entries of one IFD (tens), not pixels
        p = at + 2 + 12 * k
        if p + 12 > len(data):
            raise struct.error("IFD beyond the end of the file")
        out.append((*struct.unpack_from(order + "HHI", data, p), bytes(data[p + 8 : p + 12])))
    return out


def _tiff_ifd(data: bytes, at: int, order: str = "<") -> list[tuple[int, int, int, int]]:
    """The entries ``(tag, type, count, value or offset)`` of the classic TIFF IFD at offset
    ``at``: one SHORT or BYTE as its value, anything else as the field read as a LONG."""
    out = []
    for tag, typ, count, raw in _tiff_raw_ifd(data, at, order):
        if count == 1 and typ in (3, 8):
            (value,) = struct.unpack(order + "H", raw[:2])
        elif count == 1 and typ in (1, 6):
            value = raw[0]
        else:
            (value,) = struct.unpack(order + "I", raw)
        out.append((tag, typ, count, value))
    return out


def _tiff_first_ifd(data: bytes) -> list[tuple[int, int, int, int]] | None:
    """The first IFD of a classic TIFF (either byte order), or None for other files."""
    order = _tiff_order(data)
    if order is None:
        return None
    return _tiff_ifd(data, struct.unpack_from(order + "I", data, 4)[0], order)


def _tiff_write_options(original: bytes) -> list[int]:
    """``cv2.imencode`` parameters that keep the original TIFF's compression (and
    predictor) where OpenCV writes them."""
    import cv2

    try:
        tags = {t: v for t, typ, c, v in _tiff_first_ifd(original) or () if c == 1 and typ == 3}
    except struct.error:
        return []
    params = []
    if tags.get(259) in _TIFF_COMPRESSIONS:
        params += [cv2.IMWRITE_TIFF_COMPRESSION, tags[259]]
        if tags.get(317) in (1, 2) and hasattr(cv2, "IMWRITE_TIFF_PREDICTOR"):
            params += [cv2.IMWRITE_TIFF_PREDICTOR, tags[317]]
    return params


def _tiff_graft_metadata(encoded: bytes, original: bytes) -> bytes | None:
    """OpenCV's TIFF ``encoded`` with the metadata tags of the ``original`` TIFF.

    A new first IFD is appended: OpenCV's layout tags (size, samples, compression, strips)
    and every other tag of the original's first IFD (orientation, resolution, ICC profile,
    XMP, make and model, ...), their values copied after the pixel data, the EXIF, GPS and
    interoperability IFDs copied whole with their offsets moved. The values of a
    big-endian original are converted to OpenCV's little-endian byte order element by
    element (SHORT, LONG, RATIONAL, DOUBLE, ...; bytes, text and undefined data as they
    are). Vendor maker notes are copied as they are (internal offsets of some vendors then
    point elsewhere, as with any TIFF editor that moves them). Returns None (metadata not
    kept) unless the original is a classic TIFF (not BigTIFF) and ``encoded`` a classic
    little-endian one, both of which can be walked.
    """
    order = _tiff_order(original)
    if order is None or encoded[:4] != b"II*\x00":
        return None
    out = bytearray(encoded)

    def align() -> None:
        if len(out) % 2:  # TIFF offsets are even
            out.append(0)

    def little_endian(data: bytes, unit: int) -> bytes:
        if order == "<" or unit == 1:
            return data
        return np.frombuffer(data, dtype=f">u{unit}").astype(f"<u{unit}").tobytes()

    def copy_entries(at: int, depth: int, keep=lambda tag: True) -> list:
        entries = []
        for tag, typ, count, raw in _tiff_raw_ifd(original, at, order):
            if not keep(tag):
                continue
            unit = _TIFF_ELEMENT_SIZES.get(typ, 0)  # a RATIONAL: two LONGs of 4 bytes
            size = _TIFF_TYPE_SIZES.get(typ, 0) * count
            if not size:
                continue  # an unknown type: its size is not known, so it cannot be copied
            (offset,) = struct.unpack(order + "I", raw)
            if tag in _TIFF_SUB_IFDS and count == 1 and depth < 3:
                value = struct.pack("<I", write_ifd(copy_entries(offset, depth + 1)))
            elif size > 4:
                data = original[offset : offset + size]
                if len(data) != size:
                    raise struct.error("value beyond the end of the file")
                align()
                value = struct.pack("<I", len(out))
                out.extend(little_endian(data, unit))
            else:  # in the entry, left-justified in either byte order
                value = little_endian(raw[:size], unit).ljust(4, b"\x00")
            entries.append((tag, typ, count, value))
        return entries

    def write_ifd(entries: list) -> int:
        align()
        at = len(out)
        out.extend(struct.pack("<H", len(entries)))
        for tag, typ, count, value in sorted(entries):
            out.extend(struct.pack("<HHI", tag, typ, count) + value)
        out.extend(struct.pack("<I", 0))
        return at

    try:
        first = struct.unpack_from(order + "I", original, 4)[0]
        layout = [
            e
            for e in _tiff_raw_ifd(encoded, struct.unpack_from("<I", encoded, 4)[0], "<")
            if e[0] in _TIFF_LAYOUT_TAGS and e[0] not in _TIFF_RESOLUTION
        ]
        ours = {e[0] for e in layout}

        def metadata(tag: int) -> bool:  # the original's first IFD but its layout
            if tag in ours or tag in _TIFF_OTHER_OFFSETS:
                return False
            return tag not in _TIFF_LAYOUT_TAGS or tag in _TIFF_RESOLUTION

        ifd = write_ifd(layout + copy_entries(first, 0, metadata))
    except (struct.error, IndexError, ValueError):
        return None
    out[4:8] = struct.pack("<I", ifd)
    return bytes(out)


def _has_metadata(exif) -> bool:
    """Whether EXIF data holds metadata (a TIFF's tag set: more than its layout tags)."""
    from PIL import Image

    if isinstance(exif, Image.Exif):
        return any(tag not in _TIFF_LAYOUT_TAGS for tag in exif)
    return bool(exif)


#: TIFF tags of a CMYK original's inks (InkSet, InkNames, NumberOfInks, DotRange,
#: TargetPrinter) and its colour space (PhotometricInterpretation), not those of the RGB
#: pixels written
_TIFF_INK_TAGS = frozenset({262, 332, 333, 334, 336, 337})

# ICC colour spaces (header bytes 16-19) of pixels that OpenCV may turn into others
_ICC_SPACES = frozenset({b"RGB ", b"GRAY", b"CMYK", b"CMY "})


def _icc_other(profile: bytes | None, space: bytes) -> bool:
    """Whether an ICC profile describes another of the colour spaces of ``_ICC_SPACES``
    than ``space`` (a profile that does not say is kept as it is)."""
    if profile is None or len(profile) < 20:
        return False
    own = bytes(profile[16:20])
    return own in _ICC_SPACES and own != space


#: Bytes of an ICC profile decompressed from a PNG iCCP chunk: its header, which names the
#: colour space at bytes 16-19 (all :func:`_icc_other` looks at).
_ICC_HEAD = 128


def _png_icc(chunk: bytes) -> bytes | None:
    """The first :data:`_ICC_HEAD` bytes of the ICC profile of a whole PNG iCCP chunk (name,
    0, method, zlib data), or None.

    Only the header is decompressed: the whole profile was, without a bound, so a PNG of
    1 MB whose iCCP chunk inflates to 1 GiB (a zlib bomb) took 2 GB of memory to read."""
    import zlib

    data = chunk[8:-4]
    try:
        return zlib.decompressobj().decompress(data[data.index(b"\x00") + 2 :], _ICC_HEAD)
    except (ValueError, zlib.error):
        return None


def _icc_note(space: bytes) -> str:
    """Why an ICC profile was not kept: it describes other pixels than those written."""
    kind = "grey" if space == b"GRAY" else "RGB"
    return (
        f"ICC profile not kept: it describes another colour space than the {kind} pixels "
        "written (OpenCV decodes CMYK images and grey images with alpha as RGB)"
    )


def _encode(pixels: np.ndarray, meta: dict, suffix: str) -> tuple[bytes, str | None]:
    """Encoded file bytes in the original format, and a note when metadata is lost."""
    import cv2
    from PIL import Image

    fmt = meta.get("format")
    channels = 1 if pixels.ndim == 2 else pixels.shape[2]
    # the colour space of what is written (palette indices stand for RGB colours)
    grey = channels in (1, 2) and meta.get("png_palette") is None
    space = b"GRAY" if grey else b"RGB "
    if meta.get("png_chunks") is not None:
        # PNG: in its own colour type and bit depth (palette indices and grey with alpha by
        # _png_encode, the others by OpenCV: any depth and channels, exact), the original's
        # metadata chunks copied as they were (EXIF, ICC, resolution, text, XMP: also of
        # 16-bit colour images, and those after the image data, which Pillow reads only on
        # decoding), a transparent colour (tRNS) too
        palette = meta.get("png_palette")
        if palette is not None:
            png = _png_encode(pixels, palette[0], 3, [palette[1], palette[2]])
        elif meta.get("png_grey_alpha") is not None:
            png = _png_encode(pixels, meta["png_grey_alpha"], 4, [])
        else:
            ok, enc = cv2.imencode(".png", pixels, [cv2.IMWRITE_PNG_COMPRESSION, 6])
            if not ok:  # pragma: no cover - OpenCV decoded these pixels from a PNG
                raise FileFormatError(
                    f"cannot encode a {pixels.dtype} image with {channels} channel(s) as PNG"
                )
            png = enc.tobytes()
        before, text_before, text, damaged = meta["png_chunks"]
        keep = [c for c in before if c[4:8] != b"iCCP" or not _icc_other(_png_icc(c), space)]
        notes = [_icc_note(space)] if len(keep) < len(before) else []
        if damaged:
            notes.append(
                f"PNG metadata chunk(s) {', '.join(damaged)} left out: their CRC is wrong "
                "(damaged in the original)"
            )
        note = "; ".join(notes) or None
        if meta.get("png_trns") is not None:
            keep = [*keep, meta["png_trns"]]  # after the colour space chunks, before IDAT
        return _png_with_chunks(png, (keep, text_before, text)), note
    pil_ok = fmt in ("JPEG", "TIFF", "PNG") and (
        (
            pixels.dtype == np.uint8
            and channels in (1, 3, 4)
            and not (fmt == "JPEG" and channels == 4)
        )
        or (pixels.dtype == np.uint16 and channels == 1 and fmt in ("TIFF", "PNG"))
    )
    if pil_ok:
        if channels in (3, 4):
            # Pillow copies the pixels into its own image in any case: it takes them in
            # OpenCV's channel order (raw mode BGR[A]) while copying; a colour conversion
            # before it was one more full-size copy (36 MB for 12 Mpx)
            mode, order = ("RGB", "BGR") if channels == 3 else ("RGBA", "BGRA")
            h, w = pixels.shape[:2]
            im = Image.frombuffer(mode, (w, h), np.ascontiguousarray(pixels), "raw", order, 0, 1)
        else:
            im = Image.fromarray(pixels)
        kw: dict = {}
        note = None
        if meta.get("exif") is not None:
            kw["exif"] = meta["exif"]
        if meta.get("icc_profile"):
            if not _icc_other(meta["icc_profile"], space):
                kw["icc_profile"] = meta["icc_profile"]
            else:
                note = _icc_note(space)
        if meta.get("dpi") and fmt != "TIFF":
            # a TIFF's resolution tags (282, 283, 296) travel with its other tags (the
            # "exif" set) as stored; Pillow's dpi of a TIFF is (1, 1) where it has none,
            # and converted to inches where the file states centimetres
            kw["dpi"] = meta["dpi"]
        xmp = meta.get("xmp")
        if isinstance(xmp, str):
            xmp = xmp.encode("utf-8")
        if fmt == "JPEG":
            if meta.get("qtables"):
                kw["qtables"] = meta["qtables"]
                if meta.get("subsampling") is not None and meta["subsampling"] >= 0:
                    kw["subsampling"] = meta["subsampling"]
            else:
                kw["quality"] = 95
            if xmp:
                kw["xmp"] = xmp
            if meta.get("jpeg_previews"):
                note = (
                    f"{meta['jpeg_previews']} preview image(s) after the main image (APP2 "
                    "MPF index) not kept: they show the uncorrected image"
                    + ("" if note is None else f"; {note}")
                )
        elif fmt == "TIFF":
            if meta.get("compression") and meta["compression"] != "raw":
                kw["compression"] = meta["compression"]
            if xmp:  # XMP is TIFF tag 700; Pillow takes one tag set, so it joins the EXIF
                tags = meta.get("exif")
                if not isinstance(tags, Image.Exif):
                    tags = Image.Exif()
                    if meta.get("exif"):
                        tags.load(meta["exif"])
                tags[700] = xmp
                kw["exif"] = tags
        if meta.get("mode") == "CMYK" and channels == 3:
            # OpenCV decodes CMYK as RGB without a colour profile (an approximate
            # conversion); Pillow could write CMYK back, but only from those RGB pixels.
            # A TIFF's ink tags describe the original's separations, not these pixels
            if isinstance(kw.get("exif"), Image.Exif):
                tags = Image.Exif()
                tags.update({k: v for k, v in kw["exif"].items() if k not in _TIFF_INK_TAGS})
                kw["exif"] = tags
            cmyk = (
                f"CMYK {fmt} written as RGB: OpenCV decodes CMYK as RGB without a colour "
                "profile, so the colours are approximate; convert the originals to RGB with "
                "their colour profile first where colours matter"
            )
            note = cmyk if note is None else f"{cmyk}; {note}"
        buf = io.BytesIO()
        im.save(buf, format=fmt, **kw)
        if fmt == "JPEG":  # comments, extended XMP, IPTC, vendors' segments
            return _jpeg_with_segments(buf.getvalue(), meta.get("jpeg_segments", [])), note
        return buf.getvalue(), note
    original = meta.get("tiff_bytes")
    params = _tiff_write_options(original) if original is not None else []
    ok, enc = cv2.imencode(suffix, pixels, params)
    if not ok:
        raise FileFormatError(
            f"cannot encode a {pixels.dtype} image with {channels} channel(s) as {suffix}"
        )
    if original is not None:
        grafted = _tiff_graft_metadata(enc.tobytes(), original)
        if grafted is not None:
            return grafted, None
    lost = _has_metadata(meta.get("exif")) or meta.get("xmp") or meta.get("icc_profile")
    note = (
        f"metadata (EXIF/XMP/ICC) not kept: {fmt or suffix} with {pixels.dtype} x {channels} "
        "channel(s) is written by OpenCV"
        if lost
        else None
    )
    return enc.tobytes(), note


def correct_image_file(
    src: str | os.PathLike,
    dst: str | os.PathLike,
    grid: ResidualGrid,
    *,
    interpolation: str = "bilinear",
    threads: int | None = None,
    border: str = "replicate",
) -> str | None:
    """Correct one image file into ``dst`` (same format, metadata kept where possible).

    Parameters
    ----------
    src, dst : path
        Image file to read and file to write (atomically). ``src`` may be a pipe
        (``<(curl ...)``, a named pipe): it is read once, whole (inside
        :func:`photogeom.io.sources.pipe_reads`, once per scope). A folder or a device is
        refused by name.
    grid : ResidualGrid
        The grid of this image (fitted for its size, px).
    interpolation : {"bilinear", "bicubic", "nearest"}
        Resampling (see :func:`correct_image`); a palette PNG is always resampled by
        nearest neighbour, its palette kept (said in the note returned).
    threads : int, optional
        Threads over chunks of rows (see :func:`correct_image`).
    border : {"replicate", "constant", "reflect"}
        Values of output pixels whose source lies outside the image (see
        :func:`correct_image`; ``"constant"``: 0).

    Returns
    -------
    str or None
        A note when metadata could not be kept, or when the file's EXIF orientation shows
        it otherwise than stored (:func:`orientation_note`: corrected as stored), else None.

    Raises
    ------
    FileFormatError
        Missing, empty, corrupt or unwritable file; a folder or a device as ``src``.
    InputError
        The image size differs from the grid's.
    """
    src, dst = Path(src), Path(dst)
    pixels, meta = _read(src)
    h, w = pixels.shape[:2]
    if (w, h) != grid.image_size:
        raise InputError(
            f"{src}: the image is {w} x {h} px, its grid was fitted for "
            f"{grid.image_size[0]} x {grid.image_size[1]} px: correct the original image of "
            "that size (not a resized or cropped copy), or fit the grids for this size"
        )
    palette_note = None
    if meta.get("png_palette") is not None and interpolation != "nearest":
        # blending palette indices gives colours of unrelated entries: nearest neighbour
        interpolation = "nearest"
        palette_note = (
            "palette image: resampled by nearest neighbour, its palette and colour type "
            "kept (bilinear or bicubic would blend palette indices into unrelated colours)"
        )
    out = correct_image(  # type: ignore[arg-type]
        pixels, grid, interpolation=interpolation, threads=threads, border=border
    )
    data, note = _encode(out, meta, src.suffix.lower() or ".png")
    atomic_write_bytes(dst, data)
    notes = [palette_note, orientation_note(meta.get("orientation", 1)), note]
    return "; ".join(n for n in notes if n is not None) or None


# --------------------------------------------------------------------------- folders
def _portable(grid: ResidualGrid) -> ResidualGrid:
    """The grid without its observations (what a worker needs: layout and nodes).

    Every array of one value per observation is left out (positions, standard deviations,
    outlier flags, data snooping): they were shipped with every image, so a task's arguments
    grew with the residuals of the fit (570 kB for 30 000 of them with data snooping, of
    which the worker uses the 20 kB of nodes); the arrays of one value per node stay.
    """
    return replace(
        grid,
        uv=None,
        _std=[],
        sigma_obs=np.zeros(0),
        outliers=np.zeros(0, bool),
        snooping=None,
    )


#: Tasks of this process inside :func:`_opencv_single_threaded`, and the OpenCV thread count
#: to restore when the last of them leaves (a Dask worker runs several tasks at once)
_OPENCV_SINGLE = {"inside": 0, "restore": 0}
_OPENCV_LOCK = threading.Lock()


@contextmanager
def _opencv_single_threaded():
    """OpenCV single-threaded while any task of the process is inside; the thread count it
    had before the first of them is restored when the last one leaves.

    OpenCV's thread count is one setting of the whole process: a task that set it to 1 and
    put back the count it had found could find the 1 of a task still running, and restore
    it after that task had restored its own (the process left single-threaded: an
    in-process cluster of 2 threads left OpenCV at 1 thread in the calling program), or
    give the running task the full count (as many OpenCV threads per task as cores).
    """
    import cv2

    with _OPENCV_LOCK:
        if _OPENCV_SINGLE["inside"] == 0:
            _OPENCV_SINGLE["restore"] = cv2.getNumThreads()
            cv2.setNumThreads(1)
        _OPENCV_SINGLE["inside"] += 1
    try:
        yield
    finally:
        with _OPENCV_LOCK:
            _OPENCV_SINGLE["inside"] -= 1
            if _OPENCV_SINGLE["inside"] == 0:
                cv2.setNumThreads(_OPENCV_SINGLE["restore"])


def _task(
    src: str,
    dst: str,
    grid: ResidualGrid,
    interpolation: str,
    threads: int | None,
    cv_single: bool = False,
    border: str = "replicate",
):
    """Worker: correct one file; returns (ok, note or message). Never raises for bad files.

    ``cv_single``: OpenCV runs single-threaded while the task runs (Dask workers already
    fill the cores; see :func:`_opencv_single_threaded`), its thread count restored when
    the last task of the process ends. Not in forked processes, where changing OpenCV's
    thread pool can deadlock.
    """
    try:
        with _opencv_single_threaded() if cv_single else nullcontext():
            note = correct_image_file(
                src, dst, grid, interpolation=interpolation, threads=threads, border=border
            )
        return True, note
    except (PhotogeomError, OSError) as exc:
        return False, str(exc)
    except Exception as exc:  # cv2/Pillow errors on damaged files
        return False, f"{Path(src).name}: {type(exc).__name__}: {exc}"


def _subfolder_id(k: str) -> tuple[str, str] | None:
    """``(subfolder, name)`` of an image id that is a relative path below the folder
    (``cam1/DSC00100.JPG``: COLMAP names an image by its path below the image folder, as
    rigs and multi-folder projects write them); None for a plain name, and for an id that
    would leave the folder (an absolute path, ``..``)."""
    if "/" not in k:
        return None
    parts = k.split("/")
    if k.startswith("/") or any(q in ("", ".", "..") for q in parts):
        return None
    return "/".join(parts[:-1]), parts[-1]


def _image_files(folder: Path) -> list[Path]:
    """The regular files of ``folder`` with an image suffix, sorted."""
    try:
        entries = list(folder.iterdir())
    except OSError:  # a sub-folder named by an id that is not one
        return []
    return sorted(p for p in entries if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)


def _match(files: list[Path], k: str) -> Path | None:
    """The file of ``files`` named ``k``, or the only one whose stem is ``k``."""
    named = [p for p in files if p.name == k]
    if named:
        return named[0]
    stems = [p for p in files if p.stem == k]
    return stems[0] if len(stems) == 1 else None


def find_images(folder: Path, ids) -> tuple[dict, list, list]:
    """Match image ids to files of ``folder`` (the file name, or its stem; an id that is a
    relative path, ``cam1/DSC00100.JPG``, to the file below ``folder``).

    Returns ``(id -> path, ids without a file, files of folder without an id)``.
    """
    files = _image_files(folder)
    by_name = {p.name: p for p in files}
    by_stem: dict = {}
    for p in files:
        by_stem.setdefault(p.stem, []).append(p)
    below: dict = {}  # sub-folder -> its image files, listed once
    found, missing = {}, []
    for key in ids:
        k = str(key)
        sub = _subfolder_id(k)
        if sub is not None:
            if sub[0] not in below:
                below[sub[0]] = _image_files(folder / sub[0])
            hit = _match(below[sub[0]], sub[1])
            if hit is not None:
                found[key] = hit
            else:
                missing.append(key)
        elif k in by_name:
            found[key] = by_name[k]
        elif len(by_stem.get(k, [])) == 1:
            found[key] = by_stem[k][0]
        else:
            missing.append(key)
    used = {p for p in found.values()}
    return found, missing, [p.name for p in files if p not in used]


def _near_names(key: str, unmatched) -> list[tuple[str, str]]:
    """Image files left without an id whose name is the id's but for letter case or the
    extension: ``(file name, the name that matches the id)`` pairs.

    ``DSC1.JPG`` for the id ``dsc1.jpg`` (case), ``DSC1.tif`` for the id ``DSC1.JPG`` (a
    copy in another format: COLMAP names an image with its extension), ``a.PNG`` for ``A``.
    """
    if _subfolder_id(key) is not None:  # matched below its folder: said by the caller
        return []
    k = key.lower()
    k_path = Path(key)
    k_stem = k_path.stem.lower() if k_path.suffix.lower() in IMAGE_SUFFIXES else None
    pairs = []
    for name in unmatched:
        p = Path(name)
        if name.lower() == k:
            pairs.append((name, key))
        elif p.stem.lower() == k or (k_stem is not None and p.stem.lower() == k_stem):
            pairs.append((name, key + p.suffix))
    return pairs


def _missing_message(folder: Path, key, unmatched=()) -> str:
    """Why image id ``key`` has no file in ``folder``: none of that name, or several files
    with that stem (the id does not say which one), or only files of unsupported formats;
    a file of ``unmatched`` (image files without an id) whose name differs from the id in
    letter case or extension only is named, with the name to give it."""
    k = str(key)
    # a pipe, folder or device of that name: read one by one, a folder holds files (a
    # named pipe blocks until something writes to it); it was "no image file named ..."
    kinds = {"pipe": "a named pipe (FIFO) or socket", "folder": "a folder", "device": "a device"}
    named = [folder / k, *folder.glob(f"{glob_escape(k)}.*")]
    other = sorted((p.name, input_kind(p)) for p in named if input_kind(p) in kinds)
    if other:
        name, kind = other[0]
        why = " (a named pipe would wait for a writer)" if kind == "pipe" else ""
        return (
            f"{name} in {folder} is {kinds[kind]}, not an image file: the images of a folder "
            f"are read as regular files{why}; write the image to a regular file of that name"
        )
    same = sorted(p.name for p in folder.glob(f"{glob_escape(k)}.*") if p.is_file())
    usable = [n for n in same if Path(n).suffix.lower() in IMAGE_SUFFIXES]
    if len(usable) > 1:
        return (
            f"image id {k} matches {len(usable)} files in {folder} ({', '.join(usable)}): "
            "keep one of them in the folder, or name the file in the grid's id "
            f"(e.g. {usable[0]})"
        )
    if same:
        return (
            f"no image file named {k} (or {k}.<ext>) in {folder} in a supported format "
            f"({', '.join(IMAGE_SUFFIXES)}); found {', '.join(same[:5])}"
        )
    sub = _subfolder_id(k)
    if sub is not None and sub[1] in set(unmatched):
        # the id names its folder (a COLMAP image path, a Bundler list's path) and the
        # folder given is that one: the file is there, the id's folder is not below it
        names = tuple(sub[0].split("/"))
        at = ""
        for f in (folder, folder.resolve()):  # as given, else absolute (folder '.')
            if len(f.parts) > len(names) and f.parts[-len(names):] == names:
                at = f" ({f.parents[len(names) - 1]})"
                break
        return (
            f"no image file {k} below {folder}: the image id names its folder ({sub[0]}/), "
            f"and {folder} holds {sub[1]} itself; give the folder that holds {sub[0]}/{at} "
            "as the images' folder"
        )
    near = _near_names(k, unmatched)
    if near:
        found = "; ".join(
            f"{name} differs from it in letter case only: rename it to {want}"
            if name.lower() == want.lower()
            else f"{name} has its name with another extension: rename it to {want}"
            for name, want in near[:5]
        )
        return (
            f"no image file named {k} (or {k}.<ext>) in {folder} (file names are matched "
            f"exactly, letter case included); {found}"
        )
    return f"no image file named {k} (or {k}.<ext>) in {folder}"


def correct_folder(
    src_dir: str | os.PathLike,
    dst_dir: str | os.PathLike,
    grids: Mapping,
    *,
    workers: int = 1,
    dask: bool | str = False,
    interpolation: str = "bilinear",
    progress: bool | Callable[[int, int], None] = True,
    border: str = "replicate",
) -> FolderResult:
    """Correct every image of a folder that has a grid, in parallel.

    Parameters
    ----------
    src_dir, dst_dir : path
        Input and output folders (must differ; ``dst_dir`` is created).
    grids : mapping
        ``image id -> ResidualGrid``; an id names a file by its name or its stem.
    workers : int
        Parallel workers (processes, or Dask workers of a local cluster).
    dask : bool or str
        False: local processes; True: a ``dask.distributed.LocalCluster`` with
        ``workers`` single-threaded workers; a string: the address of a running scheduler
        (``"tcp://host:8786"``).
    interpolation : {"bilinear", "bicubic", "nearest"}
        As :func:`correct_image_file` (palette PNGs: nearest neighbour).
    progress : bool or callable
        ``True``: a rich progress bar on the terminal; a callable: called as
        ``progress(done, total)`` (images) before the first and after every image.
    border : {"replicate", "constant", "reflect"}
        Values of output pixels whose source lies outside the image (see
        :func:`correct_image`; ``"constant"``: 0).

    Returns
    -------
    FolderResult
        Images written, failures (missing or corrupt files: listed, the rest processed),
        image files without a grid.

    Raises
    ------
    InputError
        No input folder, the output folder equal to it, bad ``workers`` or
        ``interpolation``.
    OutputError
        The output folder cannot be created or written (checked before any image is read).
    """
    src, dst = Path(src_dir), Path(dst_dir)
    if not src.is_dir():
        if src.exists():
            raise InputError(
                f"input folder {src} is a file, not a folder: give the folder that holds the "
                "images"
            )
        raise InputError(f"input folder {src} does not exist")
    if interpolation not in INTERPOLATIONS:
        raise InputError(
            f"interpolation must be one of {', '.join(INTERPOLATIONS)}, not {interpolation!r}"
        )
    if border not in BORDER_MODES:
        raise InputError(f"border must be one of {', '.join(BORDER_MODES)}, not {border!r}")
    if workers < 1:
        raise InputError(f"workers must be at least 1, not {workers}")
    if src.resolve() == dst.resolve():
        raise InputError("the output folder must differ from the input folder (originals are kept)")
    made = [d for d in (dst, *dst.parents) if not d.exists()]  # created here, innermost first
    _output_folder(dst)
    below: list[Path] = []  # sub-folders of dst made for images below src (cam1/ of a rig)
    try:
        result = _correct_jobs(
            src, dst, grids, workers, dask, interpolation, progress, border, below
        )
    except BaseException:
        # a job that could not start or was stopped (an unreachable scheduler, Ctrl-C,
        # SIGTERM): folders made for it and still empty are removed again, the sub-folders
        # made for images (cam1/) first; nothing is left half-made
        _remove_empty(below)
        for d in made:
            try:
                d.rmdir()
            except OSError:
                break
        raise
    _remove_empty(below)  # made for images that all failed
    return result


def _remove_empty(folders: list[Path]) -> None:
    """Remove those of ``folders`` that are empty, the deepest first (a folder emptied by
    the removal of its sub-folders goes too); a folder holding anything stays."""
    for d in sorted(folders, key=lambda p: len(p.parts), reverse=True):
        try:
            d.rmdir()
        except OSError:  # not empty (an image written, a file of the user's), or gone
            pass


def _correct_jobs(src, dst, grids, workers, dask, interpolation, progress, border, below):
    """The body of :func:`correct_folder` once the output folder exists; ``below`` receives
    the sub-folders of ``dst`` it creates."""
    result = FolderResult()
    found, missing, extra = find_images(src, list(grids))
    for key in missing:
        result.failures[key] = _missing_message(src, key, extra)
    result.missing = list(missing)
    result.skipped = extra
    # an image below the input folder (an id cam1/DSC00100.JPG) is written below the output
    # folder alike: cam1/0001.jpg and cam2/0001.jpg are two images
    out = {key: dst / p.relative_to(src) for key, p in found.items()}
    for key, d in list(out.items()):
        below.extend(p for p in (d.parent, *d.parent.parents) if p != dst and
                     p.is_relative_to(dst) and not p.exists())  # fmt: skip
        try:
            d.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            result.failures[key] = f"cannot create the output folder {d.parent}: {exc.strerror}"
            del out[key]
    jobs = [(key, str(found[key]), str(d), _portable(grids[key])) for key, d in out.items()]
    # threads inside a job: only when the jobs do not already fill the machine
    threads = 1 if (workers > 1 or dask) else None
    if dask or workers > 1:
        # the largest images first: the workers then end together, not one of them
        # correcting a large image alone after the others have run out of work
        order = _largest_first(jobs)
        queued = [jobs[i] for i in order]
        if dask:
            done = _run_dask(queued, workers, dask, interpolation, progress, border)
        else:
            done = _run_processes(queued, workers, interpolation, progress, border)
        outcomes: list = [None] * len(jobs)
        for i, outcome in zip(order, done):
            outcomes[i] = outcome
    else:
        outcomes = _run_serial(jobs, interpolation, threads, progress, border)
    for (key, _s, d, _g), (ok, msg) in zip(jobs, outcomes):
        if ok:
            result.written[key] = Path(d)
            if msg:
                result.notes[key] = msg
        else:
            result.failures[key] = msg
    return result


def _largest_first(jobs: list) -> list[int]:
    """Positions of ``jobs`` by decreasing work: pixels of the image (its grid's size), then
    bytes of the file; jobs of equal work keep their order.

    Parameters
    ----------
    jobs : list of (key, source path, output path, ResidualGrid)
        The images of a folder.

    Returns
    -------
    list of int
        Indices into ``jobs``.
    """

    def work(i: int) -> tuple[int, int]:
        _key, path, _dst, grid = jobs[i]
        w, h = grid.image_size
        try:
            size = os.stat(path).st_size
        except OSError:  # gone meanwhile: its task says so
            size = 0
        return w * h, size

    return sorted(range(len(jobs)), key=work, reverse=True)


def _output_folder(dst: Path) -> None:
    """Create the output folder and check that files can be made in it, before any image
    is read: a folder that cannot be written fails once, by name, not once per image.

    Raises
    ------
    OutputError
        ``dst`` cannot be created (a file in the way, no permission) or written.
    """
    from ..atomicfile import _failure

    try:
        dst.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        if isinstance(exc, FileExistsError):
            reason = "a file of that name is in the way"
        else:
            reason = str(_failure(dst, exc)).split(": ", 1)[-1]
        raise OutputError(
            f"output folder {dst} cannot be created ({reason}); choose another output folder",
            exc.errno,
        ) from None
    if not dst.is_dir():
        raise OutputError(f"output folder {dst} is not a folder; choose another output folder")
    if not os.access(dst, os.W_OK | os.X_OK):
        raise OutputError(
            f"output folder {dst} is not writable (permission denied); choose another "
            "output folder or make it writable"
        )


class _CallbackProgress:
    """The part of rich's Progress that the runners use, reporting to
    ``report(done, total)`` (images) instead of drawing."""

    def __init__(self, report, total: int) -> None:
        self.report, self.total, self.done = report, total, 0

    def __enter__(self) -> _CallbackProgress:
        self.report(0, self.total)
        return self

    def __exit__(self, *exc) -> None:
        return None

    def add_task(self, *args, **kwargs) -> int:
        return 0

    def advance(self, task: int, n: int = 1) -> None:
        self.done += n
        self.report(self.done, self.total)


def _progress(enabled, total: int):
    if callable(enabled):
        return _CallbackProgress(enabled, total)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    prog = Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        transient=True,
        disable=not enabled,
    )
    return prog


def _run_serial(jobs, interpolation, threads, progress, border):
    out = []
    with _progress(progress, len(jobs)) as prog:
        t = prog.add_task("correcting images", total=len(jobs))
        for _key, s, d, g in jobs:
            out.append(_task(s, d, g, interpolation, threads, border=border))
            prog.advance(t)
    return out


def _run_processes(jobs, workers, interpolation, progress, border):
    """``jobs`` on a pool of ``workers`` local processes (forked), one image per task.

    OpenCV is single-threaded in this process while the pool lives (its count restored
    after): the processes fork with it and run one OpenCV thread each. Before, each ran
    as many OpenCV threads as cores (``workers`` x cores threads). The processes cannot set
    it themselves: in a process forked from one whose OpenCV had started its threads,
    ``cv2.setNumThreads`` waits for threads that do not exist (a deadlock).

    A process that dies in a task (killed for memory, a crash inside a decoder) breaks the
    pool, whose other processes are terminated. The pool hands the images to its processes
    in order, at most one more than it has processes, so the image of the process that
    died is one of the first ``workers + 1`` not finished: those run again each in a pool
    of its own (the one whose process dies again is a failure of that image; the temporary
    files of the terminated writers are removed), the others on a new pool of ``workers``
    processes. Before, the pool's ``BrokenProcessPool`` was raised out of
    :func:`correct_folder` (the outcomes of the images written meanwhile lost with it) and
    temporary files were left in the output folder.
    """
    out: list = [None] * len(jobs)
    with _progress(progress, len(jobs)) as prog, _opencv_single_threaded():
        t = prog.add_task("correcting images", total=len(jobs))
        pending = list(range(len(jobs)))
        while pending:
            unfinished = _pool_run(jobs, pending, workers, interpolation, border, out, prog, t)
            suspects, pending = unfinished[: workers + 1], unfinished[workers + 1 :]
            _run_alone(jobs, suspects, interpolation, border, out, prog, t)
    return out


def _run_alone(jobs, indices, interpolation, border, out, prog, t) -> None:
    """Run each of ``jobs[i]``, ``i`` in ``indices``, in a pool of one process of its own,
    after removing its temporary files left by a terminated process; one whose process
    dies is a failure of that image (see :func:`_run_processes`)."""
    for i in indices:
        remove_temporaries(jobs[i][2])
        if _pool_run(jobs, [i], 1, interpolation, border, out, prog, t):
            remove_temporaries(jobs[i][2])
            out[i] = (
                False,
                f"{jobs[i][1]}: the process correcting it died (out of memory, or a crash "
                "in a decoder); nothing was written for it. Correct it alone with "
                "correct_image_file (grid correct-images on a folder of that image, "
                "without --workers) to see the error",
            )
            prog.advance(t)


def _pool_run(jobs, indices, workers, interpolation, border, out, prog, t) -> list[int]:
    """Run ``jobs[i]`` for ``i`` in ``indices`` on a new pool of ``workers`` processes,
    their outcomes into ``out[i]`` (``prog`` advanced for each); the indices of the jobs
    not finished because a process of the pool died (empty when none did).

    Parameters
    ----------
    jobs : list
        ``(key, source, destination, grid)`` per image.
    indices : iterable of int
        The jobs to run.
    workers : int
        Processes of the pool.
    interpolation, border : str
        As :func:`correct_folder`.
    out : list
        Outcomes by job index, filled in.
    prog, t
        The progress display and its task.

    Returns
    -------
    list of int
        Jobs to run again, in their order.
    """
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    unfinished = []
    ex = ProcessPoolExecutor(workers)
    try:
        futs = {
            ex.submit(_task, jobs[i][1], jobs[i][2], jobs[i][3], interpolation, 1, border=border): i
            for i in indices
        }
        for f in as_completed(futs):
            try:
                out[futs[f]] = f.result()
            except BrokenProcessPool:
                unfinished.append(futs[f])
                continue
            prog.advance(t)
    except BaseException:  # Ctrl-C: the images not started are dropped (the running
        ex.shutdown(wait=True, cancel_futures=True)  # ones finish, each written whole)
        raise
    ex.shutdown(wait=True)  # the processes have ended: none writes any more
    return sorted(unfinished)


def _local_cluster_message(workers: int, exc: BaseException) -> str:
    """Why the local Dask cluster of ``correct_folder(dask=True)`` did not start, and what
    to do (distributed says only ``Nanny failed to start``)."""
    return (
        f"a local Dask cluster of {workers} worker process(es) (dask=True, --dask) did not "
        f"start ({type(exc).__name__}: {exc}). Its workers are new Python processes that "
        "import the program's main module again: in a script, put the code that calls "
        "photogeom under 'if __name__ == \"__main__\":'; or correct the folder without "
        "Dask (dask=False, --workers N without --dask)"
    )


def _run_dask(jobs, workers, dask, interpolation, progress, border):
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise PhotogeomError(
            "correcting images on a Dask cluster needs dask.distributed: "
            'pip install "photogeom[dask]" (or run without --dask/--scheduler)'
        ) from None
    cluster = None
    if isinstance(dask, str):
        from ..distributed import connect_to_scheduler

        # the address checked and the start bounded in time (a silent or foreign server)
        client = connect_to_scheduler(dask)
    else:
        try:
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",
                silence_logs=logging.ERROR,
            )
        except Exception as exc:
            raise PhotogeomError(_local_cluster_message(workers, exc)) from exc
        client = Client(cluster)
    try:
        with _progress(progress, len(jobs)) as prog:
            t = prog.add_task("correcting images (dask)", total=len(jobs))
            # the folder is one graph: a submit per image was a graph update each (with a
            # result fetched per image, 8 images of no work on 2 workers: 62 ms of the
            # client's and scheduler's CPU and 50 ms of the workers', against 34 and 37 ms),
            # CPU taken from the cores that correct the images when the workers fill them
            futs = client.map(
                _task,
                [s for _k, s, _d, _g in jobs],
                [d for _k, _s, d, _g in jobs],
                [g for _k, _s, _d, g in jobs],
                interpolation=interpolation,
                threads=1,
                cv_single=True,
                border=border,
                pure=False,
            )
            index = {f.key: i for i, f in enumerate(futs)}
            out: list = [None] * len(jobs)
            # each outcome fetched as its task ends: one kept on its worker until the end
            # would be lost with that worker (and the image corrected again)
            for f, value in as_completed(futs, with_results=True, raise_errors=False):
                i = index[f.key]
                out[i] = value if f.status == "finished" else _dask_failure(jobs[i][1], value)
                prog.advance(t)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return out


def _dask_failure(src: str, error) -> tuple[bool, str]:
    """The outcome of the task of image ``src`` that Dask could not run: a worker that died
    while correcting it (``KilledWorker``) is a failure of that image; anything else is
    raised (not one image's problem: the workers cannot import photogeom, ...).

    A worker process that dies in a task (out of memory, or a crash inside a decoder on a
    hostile file) makes the scheduler give the task up after its ``allowed-failures``
    retries: that raised out of :func:`correct_folder`, and the outcomes of all the other
    images, written meanwhile, were lost with it.

    Parameters
    ----------
    src : str
        The image file.
    error : tuple or BaseException
        ``(type, exception, traceback)`` of an erred task, or the ``CancelledError`` of a
        cancelled one (as ``as_completed(..., raise_errors=False)`` gives them).

    Returns
    -------
    tuple
        ``(False, message)``.
    """
    from distributed import KilledWorker

    exc = error[1] if isinstance(error, tuple) else error
    if isinstance(exc, KilledWorker):
        return (
            False,
            f"{src}: the Dask worker correcting it died (out of memory, or a crash in a "
            "decoder); nothing was written for it. Correct it alone with correct_image_file "
            "(grid correct-images on a folder of that image, without --dask) to see the "
            "error, or give the workers more memory",
        )
    if isinstance(error, tuple):
        raise exc.with_traceback(error[2])
    raise exc
