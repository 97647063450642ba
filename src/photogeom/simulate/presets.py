"""Camera presets of the simulator: the three cameras of the UAV residual study.

Image sizes and pixel sizes are the study's (its Table 1); focal lengths, true calibration
deviations, overlaps and the strength of the image-variant local fields are our choices
(the study does not publish them), documented in ``docs/simulation.md``:

* ``"ILCE-7RM2"`` (Sony A7R II, full frame) with a 35 mm lens: f = 7777.8 px; the study's
  high flight at 4 cm GSD (H = 311 m), 250 images, an unstable camera (strong fields).
* ``"FC6310"`` (DJI Phantom 4 Pro, 1") with its 8.8 mm lens: f = 3384.6 px; low flight at
  2 cm GSD (H = 67.7 m), 195 images, a stable camera (weak fields).
* ``"FC300S"`` (DJI Phantom 3 Professional, 1/2.3") with its 3.6 mm lens: f = 2250 px; low
  flight at 2.5 cm GSD (H = 56.3 m), 82 images, a stable camera (weak fields).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from ..camera.metashape import MetashapeCalibration
from ..errors import InputError
from ..records import FrozenMapping

__all__ = ["PRESETS", "CameraPreset", "preset"]


@dataclass(frozen=True)
class CameraPreset:
    """A simulated camera and the study block it flew.

    Attributes
    ----------
    name : str
    width, height : int
        Image size, pixels.
    pixel_size : float
        Pixel pitch, millimetres.
    focal_length : float
        Nominal focal length, millimetres (``focal_px = focal_length / pixel_size``).
    gsd : float
        The study's ground sample distance, metres per pixel.
    study_strips : tuple of int
        Images per strip of the study-sized block (their sum is the study's image count).
    forward_overlap, side_overlap : float
        Default overlaps (fractions).
    true_calibration : mapping
        The true camera's deviations from the nominal one: ``f_scale`` (true f / nominal f),
        ``cx``, ``cy``, ``b1``, ``b2`` (pixels) and ``k1 .. k4``, ``p1``, ``p2``; read-only
        (a copy of the mapping given).
    local_field_rms : float
        Default RMS length of the image-variant local displacement field, pixels.
    """

    name: str
    width: int
    height: int
    pixel_size: float
    focal_length: float
    gsd: float
    study_strips: tuple[int, ...]
    forward_overlap: float
    side_overlap: float
    true_calibration: Mapping[str, float] = field(default_factory=dict)
    local_field_rms: float = 0.1

    def __post_init__(self) -> None:
        # read-only, a copy of the mapping given: the presets are shared by every simulation
        # of the process (a value written into sim.preset.true_calibration changed the
        # truth of every later uav_block of that camera)
        object.__setattr__(self, "true_calibration", FrozenMapping(self.true_calibration))

    @property
    def focal_px(self) -> float:
        """Nominal focal length in pixels."""
        return self.focal_length / self.pixel_size

    @property
    def study_images(self) -> int:
        return int(sum(self.study_strips))

    def flying_height(self, gsd: float | None = None) -> float:
        """Flying height above the terrain for a GSD: ``H = GSD * f_px`` (nominal f).

        Parameters
        ----------
        gsd : float, optional
            Ground sample distance, m/px; default the preset's :attr:`gsd`.

        Returns
        -------
        float
            m.
        """
        return (self.gsd if gsd is None else gsd) * self.focal_px

    def nominal_camera(self) -> MetashapeCalibration:
        """The camera as its data sheet gives it: nominal f, centred principal point, no distortion.

        Returns
        -------
        MetashapeCalibration
            px.
        """
        return MetashapeCalibration(self.width, self.height, self.focal_px)

    def true_camera(self, brown: bool = True) -> MetashapeCalibration:
        """The simulated true camera.

        The preset's f, principal point, affinity and (with ``brown``) its Brown distortion.

        Parameters
        ----------
        brown : bool, default True
            Include the Brown distortion terms ``k1 .. k4, p1, p2``.

        Returns
        -------
        MetashapeCalibration
            px.
        """
        t = dict(self.true_calibration)
        f = self.focal_px * t.pop("f_scale", 1.0)
        if not brown:
            t = {k: v for k, v in t.items() if k in ("cx", "cy")}
        return MetashapeCalibration(self.width, self.height, f, **t)


PRESETS: dict[str, CameraPreset] = {
    p.name: p
    for p in (
        CameraPreset(
            name="ILCE-7RM2",
            width=7952,
            height=5304,
            pixel_size=0.0045,
            focal_length=35.0,
            gsd=0.04,
            study_strips=(25,) * 10,
            forward_overlap=0.7,
            side_overlap=0.4,
            true_calibration=dict(
                f_scale=1.004,
                cx=12.0,
                cy=-18.0,
                k1=-0.045,
                k2=0.09,
                k3=-0.08,
                p1=2.0e-4,
                p2=-1.5e-4,
                b1=0.4,
                b2=-0.15,
            ),
            local_field_rms=1.0,
        ),
        CameraPreset(
            name="FC6310",
            width=4864,
            height=3648,
            pixel_size=0.0026,
            focal_length=8.8,
            gsd=0.02,
            study_strips=(15,) * 13,
            forward_overlap=0.8,
            side_overlap=0.7,
            true_calibration=dict(
                f_scale=1.006,
                cx=-6.0,
                cy=9.0,
                k1=-0.012,
                k2=0.015,
                k3=-0.01,
                p1=-1.0e-4,
                p2=2.0e-4,
                b1=0.2,
                b2=0.1,
            ),
            local_field_rms=0.15,
        ),
        CameraPreset(
            name="FC300S",
            width=4000,
            height=3000,
            pixel_size=0.0016,
            focal_length=3.6,
            gsd=0.025,
            study_strips=(14, 14, 14, 14, 13, 13),
            forward_overlap=0.8,
            side_overlap=0.7,
            true_calibration=dict(
                f_scale=0.995,
                cx=4.0,
                cy=-7.0,
                k1=-0.11,
                k2=0.1,
                k3=-0.035,
                p1=3.0e-4,
                p2=-2.0e-4,
                b1=-0.3,
                b2=0.2,
            ),
            local_field_rms=0.15,
        ),
    )
}


def preset(name: str | CameraPreset) -> CameraPreset:
    """The preset of a camera name (``"ILCE-7RM2"``, ``"FC6310"``, ``"FC300S"``).

    Parameters
    ----------
    name : str or CameraPreset
        A key of :data:`PRESETS`; a :class:`CameraPreset` is returned as it is.

    Returns
    -------
    CameraPreset

    Raises
    ------
    InputError
        For an unknown name (the presets are listed).
    """
    if isinstance(name, CameraPreset):
        return name
    try:
        return PRESETS[name]
    except (KeyError, TypeError):
        raise InputError(
            f"unknown camera preset {name!r}; choose from {', '.join(PRESETS)} or pass a "
            "CameraPreset"
        ) from None
