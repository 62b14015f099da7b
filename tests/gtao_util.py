"""Helpers of the dome techniques' tests: a stage lit by a dome (a constant or given one) and a
brute-force cosine-ray visibility over a frame's G-buffer samples."""

from __future__ import annotations

import numpy as np
import warp as wp

import wsoft
from wsoft.lightspace.sky import cosine_direction
from wsoft.raster.gbuffer import GBufferGPU, gb_covered
from wsoft.scene.rays import Occluders, occluders, unoccluded


def with_dome(scene, dome=None, path="/World/Sky"):
    """``scene`` lit by one dome light (constant unless ``dome``, a :class:`~wsoft.scene.dome.Dome`,
    is given), in place of its lights."""
    from wsoft.scene.dome import LIGHT_DOME, Dome
    from wsoft.scene.types import Light

    light = Light(path=path, kind=LIGHT_DOME, position=np.zeros(3), frame=np.eye(3), dome=dome if dome is not None else Dome())
    scene.lights[:] = [light]
    return scene


@wp.kernel
def cosine_rays(
    gb: GBufferGPU,
    occ: Occluders,
    rays: int,
    max_t: float,
    eps: float,
    seed: int,
    # outputs
    vis: wp.array[float],
):
    """Per G-buffer sample, the fraction of ``rays`` cosine-distributed rays of length ``max_t`` (from
    ``eps`` off the surface along its normal) that leave free (stratified: a jittered grid when ``rays`` is square); 1 for the background."""
    i = wp.tid()
    if not gb_covered(gb, i):
        vis[i] = 1.0
        return
    n = gb.nrm[i]
    o = gb.pos[i] + n * eps
    state = wp.rand_init(seed, i)
    m = int(wp.sqrt(float(rays)))
    free = int(0)
    for s in range(rays):
        u = wp.vec2(wp.randf(state), wp.randf(state))
        if m * m == rays:
            u = wp.vec2((float(s % m) + u[0]) / float(m), (float(s / m) + u[1]) / float(m))
        d = cosine_direction(n, u)
        if unoccluded(occ, o, d, max_t):
            free += 1
    vis[i] = float(free) / float(rays)


def visibility_and_gbuffer(scene, technique, params, w=96, h=72, device="cpu"):
    """(V [H, W] of ``technique``'s frame (layer 0), the frame's G-buffer)."""
    from wsoft.pipeline import build_graph, execute
    from wsoft.techniques import create

    built = build_graph(scene, create(technique, params), width=w, height=h, device=device)
    keys = [k for k in built.ctx.graph.producers if k.kind in ("gbuffer", "visibility")]
    res, _, _ = execute(built, device, extra=keys)
    gb = next(res[k] for k in keys if k.kind == "gbuffer")
    vis = next(res[k] for k in keys if k.kind == "visibility")
    return vis.vis.numpy().reshape(gb.spp, gb.height, gb.width)[0], gb


def brute_force(scene, gb, rays=256, max_t=1e6, seed=7, device="cpu"):
    """The cosine-ray visible fraction at every G-buffer sample, [H, W] (layer 0)."""
    from wsoft.scene.device import upload_scene

    ds, _ = scene.device_copy(device, upload_scene)
    out = wp.empty(gb.count, dtype=float, device=device)
    wp.launch(cosine_rays, dim=gb.count, inputs=[gb.gpu(), occluders(ds), rays, float(max_t), 1e-5 * scene.diagonal, seed], outputs=[out], device=device)
    return out.numpy().reshape(gb.spp, gb.height, gb.width)[0]


Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # world <- dome for a Z-up stage: the dome's pole +Y is world +Z


def sun_sky_texture(h: int = 32, w: int = 64, sun=(40.0, 60.0), sun_radiance: float = 40.0) -> np.ndarray:
    """A latlong sky ``[h, w, 3]``: dim blue above the horizon, near black below, and a disk of 8
    degrees at (latitude, longitude) ``sun`` (degrees, dome frame) ``sun_radiance`` brighter."""
    lat = 0.5 * np.pi - np.pi * (np.arange(h) + 0.5) / h
    lon = np.pi - 2 * np.pi * (np.arange(w) + 0.5) / w
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    tex = np.where(la[..., None] > 0, np.float32([0.3, 0.4, 0.6]), np.float32([0.05, 0.05, 0.05])).astype(np.float32)
    d = np.stack([np.cos(la) * np.sin(lo), np.sin(la), np.cos(la) * np.cos(lo)], -1)
    a, b = np.radians(sun)
    s = np.array([np.cos(a) * np.sin(b), np.sin(a), np.cos(a) * np.cos(b)])
    return tex + (d @ s > np.cos(np.radians(8.0)))[..., None].astype(np.float32) * np.float32(sun_radiance)


def box_on_ground(dome=None, eye=(0, -4, 4), target=(0, 0, 0.3)):
    """A unit box on a ground of half-side 3 under a dome: the stage's own constant ``UsdLux.DomeLight``
    unless ``dome`` (a :class:`~wsoft.scene.dome.Dome`, e.g. an in-memory texture) replaces it."""
    from pxr import UsdLux

    from wsoft.stages import add_box, add_camera, add_quad, make_stage

    st = make_stage()
    add_quad(st, "/World/Ground", (0, 0, 0), 3)
    add_box(st, "/World/Box", (-0.5, -0.5, 0), (0.5, 0.5, 1))
    add_camera(st, "/World/Cam", eye, target)
    UsdLux.DomeLight.Define(st, "/World/Sky")
    scene = wsoft.load_scene(st)
    return scene if dome is None else with_dome(scene, dome)
