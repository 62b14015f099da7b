"""How a frame maps onto pixels: the camera (its window conformed to the image), the image's size
and the data window kept, from what was given, the scene's UsdRender settings and wsoft's
defaults (:func:`frame_setup`)."""

from __future__ import annotations

from dataclasses import dataclass

from wsoft.errors import ParameterError
from wsoft.raster.camera import conform_aperture
from wsoft.scene.render_settings import RenderSettings, data_window_pixels
from wsoft.scene.types import Camera, Scene
from wsoft.scene.usd_lights import auto_camera


DEFAULT_SIZE = (640, 480)


@dataclass
class Framing:
    """How a frame maps onto pixels: the camera (its window conformed to the image), the full
    image's size, the data window that is kept, and where each came from. Built by
    :func:`frame_setup`; the stats' ``framing`` is :meth:`describe`."""

    camera: Camera
    """The camera, its window conformed (:func:`~wsoft.raster.camera.conform_aperture`)."""
    width: int
    """Full image width in pixels (the settings' ``resolution``, a flag, or 640)."""
    height: int
    """Full image height in pixels."""
    crop: tuple[int, int, int, int] | None
    """The data window (x0, y0, x1, y1), half-open, rows from the top; None: the whole image."""
    pixel_aspect: float
    """A pixel's width over its height."""
    conform_policy: str
    """The ``aspectRatioConformPolicy`` applied (``adjustApertureHeight`` without settings)."""
    camera_source: str
    """``flag`` (asked for), ``render settings`` (their ``camera`` relationship), ``first camera``
    (the stage's first) or ``automatic``."""
    size_source: str
    """``flag``, ``render settings`` (their ``resolution``) or ``default`` (640 x 480)."""
    settings: RenderSettings | None = None
    """The scene's :class:`~wsoft.scene.render_settings.RenderSettings`, or None."""
    settings_source: str = "none"
    """How they were chosen (``flag``, ``metadata``, ``GetStageRenderSettings``, ``none``)."""

    @property
    def out_size(self) -> tuple[int, int]:
        """The written image's (width, height): the data window's."""
        if self.crop is None:
            return self.width, self.height
        x0, y0, x1, y1 = self.crop
        return x1 - x0, y1 - y0

    def describe(self) -> dict:
        rs = self.settings
        out = rs.output if rs is not None else None
        return {
            "render_settings": rs.path if rs is not None else None,
            "render_settings_source": self.settings_source,
            "camera": self.camera.path,
            "camera_source": self.camera_source,
            "resolution": [self.width, self.height],
            "resolution_source": self.size_source,
            "pixel_aspect": self.pixel_aspect,
            "conform_policy": self.conform_policy,
            "data_window": list(self.crop) if self.crop is not None else None,
            "product": out.path if out is not None else None,
            "product_name": out.product_name if out is not None and out.product_name else None,
            "visibility_var": out.visibility_var if out is not None else None,
        }


def frame_setup(scene: Scene, width: int | None = None, height: int | None = None, camera=None) -> Framing:
    """The camera and image of a render of ``scene``: what is given wins, then the scene's render
    settings (``Scene.render_settings``), then wsoft's defaults.

    Size: ``width`` and ``height``; one of them alone keeps the settings' aspect (the other is
    derived from their resolution); else the settings' ``resolution``; else 640 x 480 (without
    settings, either alone replaces its side only: ``width=100`` gives 100 x 480). Camera:
    ``camera`` (a path or a :class:`Camera`), else the settings' ``camera``, else the stage's first camera, else an
    automatic one framing the scene. The window is conformed to the image with the settings'
    ``pixelAspectRatio`` and ``aspectRatioConformPolicy`` (without settings: square pixels and the
    horizontal field of view kept), and the settings' ``dataWindowNDC`` picks the pixels kept."""
    rs = scene.render_settings
    if width is not None and height is not None:
        size_source = "flag"
    elif rs is not None:
        rw, rh = rs.resolution
        if width is None and height is None:
            width, height, size_source = rw, rh, "render settings"
        elif width is None:
            width, size_source = max(1, int(round(height * rw / rh))), "flag"
        else:
            height, size_source = max(1, int(round(width * rh / rw))), "flag"
    else:
        size_source = "default" if width is None and height is None else "flag"
        width = DEFAULT_SIZE[0] if width is None else width
        height = DEFAULT_SIZE[1] if height is None else height
    check_sizes(width, height, 1)
    par = rs.pixel_aspect if rs is not None else 1.0
    policy = rs.conform_policy if rs is not None else "adjustApertureHeight"
    if isinstance(camera, Camera):
        cam, cam_source = camera, "flag"
    elif camera:
        cam, cam_source = scene.find_camera(str(camera)), "flag"
    elif rs is not None and rs.camera:
        cam, cam_source = scene.find_camera(rs.camera), "render settings"
    elif scene.cameras:
        cam, cam_source = scene.cameras[0], "first camera"
    else:
        cam, cam_source = auto_camera(scene, par * width / height), "automatic"
    crop = None
    if rs is not None and rs.has_data_window:
        crop = data_window_pixels(rs.data_window, width, height)
        if crop[0] == crop[2] or crop[1] == crop[3]:
            ndc = ", ".join(f"{x:g}" for x in rs.data_window)
            raise ParameterError(f"dataWindowNDC ({ndc}) selects no pixel of a {width}x{height} image", file=scene.path, prim=rs.path)
        if crop == (0, 0, width, height):
            crop = None
    return Framing(conform_aperture(cam, width, height, par, policy), width, height, crop, par, policy, cam_source, size_source,
                   rs, scene.render_settings_source)


def check_sizes(width: int | None, height: int | None, pixel_samples: int) -> None:
    """Image size (None: not given, resolved later) and samples per pixel in range."""
    if width is not None and height is not None and (width < 1 or height < 1 or width * height > 64 * 1024 * 1024):
        raise ParameterError(f"bad image size {width}x{height}")
    if (width is not None and width < 1) or (height is not None and height < 1):
        raise ParameterError(f"bad image size {'?' if width is None else width}x{'?' if height is None else height}")
    if not 1 <= pixel_samples <= 64:
        raise ParameterError(f"pixel_samples {pixel_samples} out of range [1, 64]")
