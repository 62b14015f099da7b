"""The generators of the bundled stages (``wsoft.usd_scenes``), one module per family of scenes.

Each generator takes an output folder, writes its stage there (and the textures it reads, under
``textures/``) and returns what it wrote: ``{"file": path, "triangles": n, ...}``. All randomness
uses fixed seeds and nothing time-dependent is written, so a run writes byte-identical files.
:mod:`wsoft.stages.bundled` lists them and regenerates them.

Every bundled stage has a perspective camera at ``/World/Camera`` (:func:`add_scene_camera`).
"""

from __future__ import annotations

from wsoft.stages.builders import add_camera

CAMERA = "/World/Camera"
APERTURES = {"4:3": (36.0, 27.0), "1:1": (24.0, 24.0)}  # horizontal, vertical (mm)


def add_scene_camera(stage, eye, target, up, aspect: str = "4:3", focal: float = 24.0, clip=(0.1, 1000.0)):
    """The bundled stages' camera: :func:`~wsoft.stages.add_camera` at ``/World/Camera``, projection
    authored, apertures of ``aspect`` (``"4:3"`` or ``"1:1"``)."""
    return add_camera(stage, CAMERA, eye, target, up, focal, aperture=APERTURES[aspect], clip=clip, projection=True)
