"""The frame-graph side of virtual shadow maps, shared by the techniques that read one (``vsmap``,
``smrt``): :func:`add_page_pass` adds the pass that requests, draws and caches a light's pages
(:mod:`wsoft.accel.virtual_pages`) through the technique's
:class:`~wsoft.pipeline.technique_context.TechniqueContext`, :func:`report_unmapped` counts and
warns about samples no page holds, :func:`virtual_config` reads the layout from a technique's
parameters (``virtual_size``, ``page_size``, ``pool_pages``, ``clip_levels``, ``first_extent``,
``lod_bias``), :func:`cylinder_refusal` and the ``*_REFUSAL`` texts say which lights a virtual map
does not cover."""

from __future__ import annotations

import warp as wp

from wsoft.accel.virtual_pages import (VirtualConfig, VirtualPages, distant_layout, dynamic_corners, light_casters, local_layout,
                                       request_pages)
from wsoft.lightspace.view import frame_extent
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_DISTANT

CYLINDER_REFUSAL = "virtual maps here cover distant, rect, disk and sphere lights: use pcss or the reference for this light"
CYLINDER_MODEL = "none: a cylinder light is declined (virtual maps here cover distant, rect, disk and sphere lights)"
DISTANCE_REFUSAL = "its pages keep the caster nearest the light only"


def cylinder_refusal(light) -> str | None:
    """Why a virtual map declines ``light`` before any other reason (a cylinder light: its kind), else
    None (point lights and domes: the technique base's own reasons)."""
    return CYLINDER_REFUSAL if light.kind == LIGHT_CYLINDER else None


def virtual_config(p) -> VirtualConfig:
    """The :class:`VirtualConfig` of a technique's parameters (``vsmap``'s or ``smrt``'s)."""
    return VirtualConfig(virtual_size=p.virtual_size, page_size=p.page_size, pool_pages=p.pool_pages, clip_levels=p.clip_levels,
                         first_extent=p.first_extent, lod_bias=p.lod_bias, footprint=p.footprint)



def add_page_pass(tech, ctx, light, reach_texels: float, soft: bool):
    """The pass that requests and draws ``light``'s pages (shared by ``vsmap`` and ``smrt``): reads
    the scene and the G-buffer (and a local light's fitted view), writes the technique's
    ``virtual_pages`` resource: ``{"map": VirtualMapGPU, "level_of": wp.array, "stats": dict, "extent":
    the frame's extent (:func:`~wsoft.lightspace.view.frame_extent`)}``."""
    p = tech.params
    cfg = virtual_config(p)
    sk = ctx.scene_arrays()
    gbuf = ctx.gbuffer()
    local = light.kind != LIGHT_DISTANT
    vk = ctx.light_view(light, size=min(p.virtual_size, 8192), soft=soft) if local else None
    key = ctx.key("virtual_pages", light)
    name = ctx.pass_name(f"{tech.name}_pages", light)
    scene = ctx.scene
    camera = ctx.camera

    def run(res):
        ds, gb = res[sk], res[gbuf]
        if local:
            layout = local_layout(light, res[vk], cfg)
        else:
            lo, hi = scene.bounds
            layout = distant_layout(light, lo, hi, camera.position, cfg)
        prev = ctx.previous(light)
        pages = prev.get("pages") if prev else None
        if pages is None or pages.cfg != cfg or pages.device != ctx.device:
            pages = VirtualPages(cfg, ctx.device)
        requests, level_of = request_pages(layout, cfg, gb, camera, ctx.height, reach_texels, ctx.device)
        casters = light_casters(scene, light)
        if casters is not None and scene.casting_triangles(light) is not None:  # a collection:shadowLink leaves some out
            ctx.ctx.pass_counters(name)["casting_triangles"] = int(len(casters[2]))
        vm = pages.update(layout, requests, ds, casters, dynamic_corners(scene, light), alpha=scene.has_cutouts)
        ctx.keep(light, {"pages": pages})
        st = dict(pages.stats)
        st["pool_mib"] = round(pages.capacity * cfg.page_size ** 2 * 4 / 2 ** 20, 3)
        ctx.counters(light).update(st)
        if st["overflow_pages"]:
            ctx.ctx.warn(name, f"light {light.path}: {st['requested']} virtual-map pages requested, more than pool_pages={cfg.pool_pages}: "
                               f"{st['overflow_pages']} of them fell back to a coarser level (blurrier shadows there); raise pool_pages")
        pts = gb.pos.numpy()[gb.prim.numpy() >= 0]
        extent = frame_extent(pts, light)  # the frame's scale: depth biases are fractions of it
        return {key: {"map": vm, "level_of": wp.array(level_of, dtype=wp.int32, device=ctx.device), "stats": st, "extent": extent}}

    inputs = (sk, gbuf) if vk is None else (sk, gbuf, vk)
    return ctx.add_pass(name, inputs=inputs, outputs=(key,), run=run, stage="pages", light=light)


def report_unmapped(ctx, light, name: str, unmapped: wp.array) -> None:
    """Count (``unmapped_samples``) and warn about the samples the virtual map holds no depth for (left lit)."""
    n = int(unmapped.numpy().sum())
    ctx.counters(light)["unmapped_samples"] = n
    if n:
        ctx.ctx.warn(name, f"light {light.path}: {n} visible samples read virtual-map texels no level holds (beyond the last clipmap "
                           f"level or the light's view) and are left lit; raise clip_levels or first_extent")
