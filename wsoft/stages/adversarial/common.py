"""What every case of the adversarial corpus shares: the frame size and map size the expectations
hold at, the base stage, small mesh and texture helpers, and the :class:`Case` and :class:`Result`
records."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from wsoft.stages.builders import add_camera, add_mesh, add_quad, add_rect_light, add_sun, make_stage

W, H = 48, 36  # frame size of every case (small: the corpus runs in CI)
MAP = 256  # texels (cells) per side of every technique's light map or grid (its size_param)
REF_SAMPLES = 64

# --------------------------------------------------------------------------- stage builders


def _save(stage, folder: str, name: str, ext: str = ".usda") -> str:
    """Export ``stage`` as ``folder/name + ext``; its path."""
    path = os.path.join(folder, name + ext)
    stage.GetRootLayer().Export(path)
    return path


def _base(light: str = "rect"):
    """Ground, a square occluder and a light above it, seen by a camera: the shadow every
    'unchanged' case compares with."""
    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 5)
    add_quad(st, "/World/Occluder", (0, 0, 1), 1)
    if light == "rect":
        add_rect_light(st, "/World/Light", (0, 0, 3), 1, 1)
    else:
        add_sun(st, "/World/Light", 2.0, (0, -20, 0))
    add_camera(st, "/World/Cam", (0, -6, 5), (0, 0, 0))
    return st


def _triangle(st, path: str, pts):
    """One triangle through ``pts`` (a minimal mesh)."""
    return add_mesh(st, path, (pts, [3], [0, 1, 2]), minimal=True)


def _sphere_mesh(st, path: str, center, radius: float, n: int = 16):
    """A closed, outward-wound UV sphere (a minimal mesh)."""
    pts = [(center[0], center[1], center[2] - radius)]
    for i in range(1, n):
        th = np.pi * i / n - np.pi / 2
        for j in range(2 * n):
            ph = np.pi * j / n
            pts.append((center[0] + radius * np.cos(th) * np.cos(ph), center[1] + radius * np.cos(th) * np.sin(ph), center[2] + radius * np.sin(th)))
    pts.append((center[0], center[1], center[2] + radius))
    top = len(pts) - 1
    counts, idx = [], []
    ring = lambda i, j: 1 + (i - 1) * 2 * n + (j % (2 * n))  # noqa: E731
    for j in range(2 * n):
        counts.append(3)
        idx += [0, ring(1, j + 1), ring(1, j)]
    for i in range(1, n - 1):
        for j in range(2 * n):
            counts.append(4)
            idx += [ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)]
    for j in range(2 * n):
        counts.append(3)
        idx += [ring(n - 1, j), ring(n - 1, j + 1), top]
    return add_mesh(st, path, (np.asarray(pts, dtype=np.float64), counts, idx), minimal=True)


def _cutout_occluder(st, texture: str, channel: str = "a"):
    """The base occluder made a cutout through ``texture`` (a path relative to the stage)."""
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(st, "/World/Looks/Cut")
    surf = UsdShade.Shader.Define(st, "/World/Looks/Cut/Surface")
    surf.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(st, "/World/Looks/Cut/St")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    tex = UsdShade.Shader.Define(st, "/World/Looks/Cut/Alpha")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(texture)
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    out = tex.CreateOutput(channel, Sdf.ValueTypeNames.Float)
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).ConnectToSource(out)
    surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.5)
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    occ = st.GetPrimAtPath("/World/Occluder")
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(occ).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    pv.Set([(0, 0), (1, 0), (1, 1), (0, 1)])
    UsdShade.MaterialBindingAPI.Apply(occ).Bind(mat)


def _checker(size: int = 8) -> np.ndarray:
    """A checker of opaque and transparent squares (1 = opaque), ``size`` x ``size`` texels."""
    i, j = np.indices((size, size))
    return ((i // (size // 4) + j // (size // 4)) % 2).astype(np.float64)


def _png(folder: str, name: str, alpha: np.ndarray, mode: str) -> str:
    from PIL import Image

    path = os.path.join(folder, name)
    if mode == "RGBA":
        a = (alpha * 255).astype(np.uint8)
        Image.fromarray(np.dstack([a, a, a, a]), "RGBA").save(path)
    elif mode == "I;16":
        Image.fromarray((alpha * 65535).astype(np.uint16)).save(path)  # 16-bit grey: opacity from outputs:r
    elif mode == "P":
        img = Image.fromarray((alpha * 255).astype(np.uint8), "L").convert("RGBA").convert("P")
        img.info["transparency"] = None
        img.save(path)
    return name


@dataclass
class Case:
    """One case: its stage builder (folder -> stage path) and what every technique must give."""

    name: str
    build: Callable[[str], str]
    expect: str = "ok"  # ok | error
    message: tuple[str, ...] = ()  # substrings of the error line (error) or of some warning (ok)
    check: Callable | None = None
    base: str = "base"  # the stage 'same as base' compares with
    silent_hazard: bool = False  # an input that, left unchecked, gives a silent wrong answer or a traceback (marked in the report)
    warn_instead: bool = False  # a technique that misses the answer must say so in a warning with ``message``
    map_size: int = MAP  # texels (cells) per side of the techniques' light maps or grids (their size_param)
    note: str = ""
    args: tuple[str, ...] = ()  # further ``wsoft render`` arguments (``--frames 0:10:5``, ``--time 3``)
    judged_time: float | None = None  # with ``--frames``: the time code whose frame (EXR and stats) is judged


@dataclass
class Result:
    """What a case gave through the command line: exit code, its one error line, the warnings,
    the frame's stats and channels (exit 0), everything it wrote to stderr."""

    rc: int
    error: str = ""  # the one error line (exit 2)
    warnings: list[str] = field(default_factory=list)
    stats: dict | None = None
    channels: dict | None = None
    stderr: str = ""
