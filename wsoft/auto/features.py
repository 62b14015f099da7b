"""Features of one light of a stage that are cheap to compute before rendering: what the chooser
(:mod:`wsoft.auto.choose`) predicts a technique's frame time and error from.

One small frame graph runs the shared passes every render runs (no technique's): a low-resolution
G-buffer (:data:`PROBE_WIDTH` samples a row, the frame's aspect) through the frame's camera, and a
soft light view of the light with its depth map (:data:`PROBE_MAP` texels a side), the providers
of :class:`~wsoft.pipeline.context.RenderContext`. From them, in numpy:

* ``triangles``: triangles of the stage (instances' included); ``triangles_in_view``: the light's
  casting triangles whose centroid falls in the light view's window (and depth range);
  ``instances``: instances kept instanced; ``cutout_triangles``: triangles with a cutout material.
* ``pixels``: the frame's pixels; ``covered_pixels``: the G-buffer's covered fraction times them.
* ``light_size``: the light's extent (radius of its emitting region; half its angle in radians for
  a distant light); ``light_distance``: from the light to the receivers' centroid (0 for a distant light).
* ``shadowed_fraction``: covered samples whose texel in the probe map holds a caster nearer the
  light than the sample (by more than 1% of its depth).
* ``penumbra_px``: the median over those samples of the penumbra width the blocker-to-receiver
  distance implies (similar triangles: light diameter x (z_r - z_b) / z_b, for a distant light
  2 tan(angle/2) (z_r - z_b)), in the frame's pixels at the sample's distance from the camera.
* ``depth_ratio``: the receivers' light-space depth range, z_max / z_min (perspective) or
  1 + (z_max - z_min) / extent (orthographic).
* ``map_texels`` is not a stage feature: the chooser adds each setting's own.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

PROBE_WIDTH = 96  # G-buffer samples a row of the probe (rows follow the frame's aspect)
PROBE_MAP = 256  # texels a side of the probe's light depth map (the smallest a light view takes)

FEATURES = ("triangles", "triangles_in_view", "instances", "cutout_triangles", "pixels", "covered_pixels", "light_size",
            "light_distance", "shadowed_fraction", "penumbra_px", "depth_ratio")


def light_features(scene, light, *, width: int | None = None, height: int | None = None, camera=None, device: str = "cpu") -> dict:
    """The features of ``light`` (a :class:`~wsoft.scene.types.Light` of ``scene``, or its path or
    name) for a frame of ``width`` x ``height`` through ``camera`` (None: as a render resolves them,
    :func:`~wsoft.pipeline.framing.frame_setup`); a dict of :data:`FEATURES` (floats)."""
    import warp as wp

    from wsoft.lightspace.view import DEPTH_CLEAR
    from wsoft.pipeline.context import RenderContext
    from wsoft.pipeline.framing import frame_setup, local_origin

    if not hasattr(light, "kind"):
        light = scene.find_light(str(light))
    fr = frame_setup(scene, width, height, camera)
    origin, _ = local_origin(scene, fr.camera)
    cam = fr.camera
    if origin is not None:
        scene = scene.translated(-origin)
        m = np.array(cam.to_world, np.float64)
        m[:3, 3] -= origin
        cam = dataclasses.replace(cam, to_world=m)
        light = scene.find_light(light.path)
    pw = PROBE_WIDTH
    ph = max(1, round(PROBE_WIDTH * fr.height / fr.width))
    ctx = RenderContext(scene, cam, pw, ph, device)
    gk = ctx.gbuffer()
    dk = ctx.light_depth(light, PROBE_MAP, soft=True)
    with wp.ScopedDevice(device):
        res, _ = ctx.graph.execute([gk, dk], device)
    gb, dm = res[gk], res[dk]
    prim = gb.prim.numpy()
    hit = prim >= 0
    pos = gb.pos.numpy()[hit].astype(np.float64)
    dist = gb.dist.numpy()[hit].astype(np.float64)
    view = dm.view
    pixels = float(fr.width * fr.height)
    out = {"triangles": float(scene.total_triangles), "instances": float(scene.instances.count if scene.instanced else 0),
           "cutout_triangles": float(sum(scene.cutout_triangle_counts().values())), "pixels": pixels,
           "covered_pixels": pixels * float(hit.mean()) if hit.size else 0.0, "light_size": float(light.extent())}
    out["triangles_in_view"] = float(_triangles_in_view(scene, light, view))
    distant = not view.persp
    out["light_distance"] = 0.0 if distant or not len(pos) else float(np.linalg.norm(pos.mean(axis=0) - np.asarray(light.position, np.float64)))
    shadowed, pen, ratio = 0.0, 0.0, 1.0
    if len(pos):
        v = view.to_view(pos)
        z = v[:, 2]
        ok = z > (view.near if view.persp else -np.inf)
        x, y = (v[:, 0] / np.where(ok, z, 1.0), v[:, 1] / np.where(ok, z, 1.0)) if view.persp else (v[:, 0], v[:, 1])
        l, r, b, t = view.window
        tx = np.floor((x - l) / (r - l) * view.width).astype(np.int64)
        ty = np.floor((y - b) / (t - b) * view.height).astype(np.int64)
        inside = ok & (tx >= 0) & (tx < view.width) & (ty >= 0) & (ty < view.height)
        depth = dm.depth.numpy()
        zb = np.full(len(z), DEPTH_CLEAR)
        zb[inside] = depth[ty[inside], tx[inside]]
        blocked = inside & (zb < DEPTH_CLEAR) & (zb < z * 0.99 - 1e-6 * view.extent)
        shadowed = float(blocked.sum() / len(z))
        if blocked.any():
            gap = z[blocked] - zb[blocked]
            if view.persp:
                w_world = 2.0 * light.extent() * gap / np.maximum(zb[blocked], 1e-9)
            else:
                w_world = 2.0 * math.tan(light.extent()) * gap
            th = cam.tan_half[1]
            foot = (2.0 * th / fr.height) * (np.ones_like(dist[blocked]) if cam.orthographic else dist[blocked])
            pen = float(np.median(w_world / np.maximum(foot, 1e-12)))
        zr = z[ok]
        if len(zr):
            if view.persp:
                ratio = float(zr.max() / max(zr.min(), 1e-9))
            else:
                ratio = float(1.0 + (zr.max() - zr.min()) / max(view.extent, 1e-9))
    out.update(shadowed_fraction=shadowed, penumbra_px=pen, depth_ratio=ratio)
    return {k: out[k] for k in FEATURES}


def _triangles_in_view(scene, light, view) -> int:
    """The light's casting triangles (instances' counted by their bounds' centres, times the
    prototype's triangles) whose centroid lies inside the view's window and depth range."""
    tris = scene.casting_triangles(light)
    idx = scene.triangles if tris is None else scene.triangles[tris]
    n = 0
    if len(idx):
        c = scene.points[idx].astype(np.float64).mean(axis=1)
        n += int(_inside(view, c).sum())
    if scene.instanced:
        lo, hi = scene.instances.world_bounds()
        per = np.array([p.triangle_count for p in scene.instances.prototypes])[scene.instances.proto]
        n += int(per[_inside(view, 0.5 * (lo + hi))].sum())
    return n


def _inside(view, p: np.ndarray) -> np.ndarray:
    v = view.to_view(p)
    z = v[:, 2]
    if view.persp:
        front = z > view.near
        zz = np.where(front, z, 1.0)
        x, y = v[:, 0] / zz, v[:, 1] / zz
    else:
        front = np.ones(len(z), bool)
        x, y = v[:, 0], v[:, 1]
    l, r, b, t = view.window
    return front & (z <= view.far) & (x >= l) & (x <= r) & (y >= b) & (y <= t)
