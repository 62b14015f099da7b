"""Sweep ``instancing``: instanced USD kept instanced, against flattened.

Each row runs in a child process of its own (``python -m wsoft.bench.instancing CASE``), so that
its peak resident memory (``ru_maxrss``) is its own: a stage loaded flattened or instanced
(``load_scene(..., instancing=...)``), uploaded to the device (``upload_scene``: the BVHs, and for
instances the prototypes' BVHs and the top level), then the frames asked for at 640 x 480 (160 x
120 in ``--quick``): ``hard`` (a 2048² map; 512² quick) and ``reference`` (16 light samples). A
warm-up frame at 32 x 24 compiles the kernels first, so frame times hold no compilation.

* ``city`` (344 instanceable buildings of 12 prototypes, 1.04M triangles flattened): both ways,
  with the shadow rays of the reference's 16 samples per pixel traced again from arrays, the same
  rays through the flattened BVH one ray at a time (``trace_rays``) and in packets
  (``trace_ray_packets``), and through the instances' top level (rays/s).
* ``forest`` (a PointInstancer of >= 10,000 trees, >= 50M instanced triangles): instanced only; the
  flattened stage is not loaded (estimated from city's bytes per flattened triangle, marked so).
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

SCENES = ("city", "forest")


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    size = [160, 120] if quick else [640, 480]
    for dev in devices:
        for mode in ("flattened", "instanced"):
            out.append({"scene": "city", "mode": mode, "device": dev, "size": size, "map": 512 if quick else 2048, "samples": 16,
                        "rays": True})
        out.append({"scene": "forest", "mode": "instanced", "device": dev, "size": size, "map": 512 if quick else 2048, "samples": 16,
                    "rays": False})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    """Run ``case`` in a child process (its own peak memory) and return its row."""
    env = dict(os.environ)
    proc = subprocess.run([sys.executable, "-m", "wsoft.bench.instancing", json.dumps(case)], capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        from wsoft.errors import WsoftError

        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        raise WsoftError(f"instancing row {case['scene']} {case['mode']} failed: {tail[0]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _device_bytes(ds) -> int:
    """Bytes of the device scene's arrays plus its BVHs (Warp's nodes: 2 per primitive, 32 bytes each)."""
    import warp as wp

    seen, total = set(), 0

    def add(a):
        nonlocal total
        if isinstance(a, wp.array) and a.ptr not in seen:
            seen.add(a.ptr)
            total += a.capacity

    for a in ds.arrays().values():
        add(a)
    from wsoft.scene.surfaces import Surfaces

    for name in Surfaces.vars:
        add(getattr(ds.cutouts, name))
    for a in (ds.tri_baked, ds.tri_has_baked):
        add(a)
    total += 64 * (int(ds.indices.shape[0]) // 3)  # the soup's BVH
    if ds.instances is not None:
        total += ds.instances.memory_bytes()
    return int(total)


def measure(case: dict) -> dict:
    import warp as wp

    from wsoft.bench.harness import scene_file
    from wsoft.parallel import resolve_device
    from wsoft.pipeline import render
    from wsoft.scene.device import upload_scene
    from wsoft.scene.usd import load_scene

    wp.config.quiet = True
    dev = resolve_device(case["device"])
    path = scene_file(case["scene"])
    rss0 = _rss_mib()
    t0 = time.perf_counter()
    scene = load_scene(path, instancing=case["mode"] == "instanced")
    t_load = time.perf_counter() - t0
    rss_load = _rss_mib()
    t0 = time.perf_counter()
    ds, _ = scene.device_copy(dev, upload_scene)
    wp.synchronize_device(dev)
    t_build = time.perf_counter() - t0
    rss_build = _rss_mib()
    row = {"scene": case["scene"], "mode": case["mode"], "device": dev, "triangles": scene.total_triangles,
           "soup_triangles": scene.triangle_count, "instances": scene.instances.count if scene.instanced else 0,
           "prototypes": len(scene.instances.prototypes) if scene.instanced else 0,
           "prototype_triangles": scene.instances.prototype_triangles if scene.instanced else 0,
           "load_s": t_load, "build_s": t_build, "device_bytes": _device_bytes(ds),
           "rss_start_mib": rss0, "rss_after_load_mib": rss_load, "rss_after_build_mib": rss_build, "lights": {}}
    w, h = case["size"]
    for light in scene.lights:
        lrow = {}
        for tech, kw in (("hard", {"shadow_map_size": case["map"]}), ("reference", {"samples": case["samples"]})):
            render(scene, tech, width=32, height=24, light=light.path, device=dev, **kw)  # compile
            fr = render(scene, tech, width=w, height=h, light=light.path, device=dev, **kw)
            lrow[tech] = {"frame_ms": fr.stats["timings_ms"]["total"], "passes_ms": fr.stats["timings_ms"],
                          "mean_V": float(np.nanmean(fr.V)), "nan": int(np.isnan(fr.V).sum()),
                          "instancing": fr.stats["scene"]["instancing"]["mode"]}
        if case["rays"]:
            lrow["rays"] = _rays(scene, ds, light, w, h, case["samples"], dev)
        row["lights"][light.name] = lrow
    row["rss_peak_mib"] = _rss_mib()
    return row


def _rays(scene, ds, light, w, h, samples, dev) -> dict:
    """The reference's shadow rays of one frame from arrays: rays/s one by one (flattened or through
    the instances) and, flattened, in packets; and how many rays each way finds blocked."""
    import warp as wp

    from wsoft.lightspace.light import disk_shaped, light_gpu
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.raster.shadow_rays import ray_epsilon
    from wsoft.reference import reference_pattern, shadow_rays, trace_ray_packets, trace_rays
    from wsoft.pipeline import frame_setup

    cam = camera_gpu(frame_setup(scene, w, h).camera)
    gb = render_gbuffer(ds, cam, w, h, 1, scene.has_cutouts)
    pattern = reference_pattern(samples, 0, True)
    o, d, t = shadow_rays(ds, light_gpu(light, scene.diagonal), gb, pattern, disk_shaped(light), ray_epsilon(gb, light))
    out = {"rays": int(o.shape[0])}
    for name, fn in (("one_by_one", lambda: trace_rays(ds, o, d, t)), ("packets", lambda: trace_ray_packets(ds, o, d, t, samples))):
        if name == "packets" and ds.instances is not None:
            continue
        fn()  # compile, warm
        best = 1e9
        for _ in range(3):
            t0 = time.perf_counter()
            hit = fn()
            wp.synchronize_device(dev)
            best = min(best, time.perf_counter() - t0)
        out[name] = {"mrays_s": o.shape[0] / best / 1e6, "blocked": int(hit.numpy().sum())}
    return out


def _mib(b) -> str:
    return f"{b / 2**20:,.0f}"


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = [line for line in report_header("instancing", rows, md, ctx)
         if not line.startswith(("Error is against", "penumbra =", "Times:", "Rows:"))]
    L.append(f"Rows: {len(rows)}; every number below is read from them.")
    L += ["", "Instanced USD stays instanced. `load_scene(..., instancing=True)` keeps PointInstancers and "
          "instanceable prims as prototypes plus per-instance transforms; on the device each prototype is one BVH and a "
          "top-level BVH over the instances' world boxes finds the instances a ray meets (`wsoft.scene.instancing`); the "
          "light-view rasterizer draws (instance, prototype triangle) pairs of the instances whose boxes reach the view. "
          "Each row ran in a child process of its own, so its peak resident memory is its own; frame times follow a "
          "warm-up frame (no compilation).", ""]
    L += ["| scene | mode | triangles (placed) | instances / prototypes | prototype triangles | load s | build s | device MiB | peak RSS MiB |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        L.append(f"| {r['scene']} | {r['mode']} | {r['triangles']:,} | {r['instances']:,} / {r['prototypes']} | {r['prototype_triangles']:,} | "
                 f"{r['load_s']:.2f} | {r['build_s']:.2f} | {_mib(r['device_bytes'])} | {r['rss_peak_mib']:,.0f} |")
    city = {r["mode"]: r for r in rows if r["scene"] == "city"}
    if len(city) == 2:
        f, i = city["flattened"], city["instanced"]
        L += ["", f"city: the instanced device scene holds {i['device_bytes'] / f['device_bytes']:.3f}× the flattened one's bytes "
              f"({_mib(i['device_bytes'])} vs {_mib(f['device_bytes'])} MiB); peak RSS {i['rss_peak_mib']:,.0f} vs {f['rss_peak_mib']:,.0f} MiB; "
              f"load + build {i['load_s'] + i['build_s']:.2f} s vs {f['load_s'] + f['build_s']:.2f} s."]
        per_tri = f["device_bytes"] / max(f["triangles"], 1)
        for r in rows:
            if r["scene"] == "forest":
                L.append(f"forest flattened would hold about {r['triangles'] * per_tri / 2**30:,.1f} GiB on the device "
                         f"(an estimate: city's {per_tri:.0f} bytes per flattened triangle × {r['triangles']:,} triangles; not loaded), "
                         f"against {_mib(r['device_bytes'])} MiB instanced.")
    L += ["", "## Frames", "", "| scene | mode | light | hard ms | reference ms | hard mean V | reference mean V | NaN |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for light, lr in r["lights"].items():
            L.append(f"| {r['scene']} | {r['mode']} ({lr['hard']['instancing']}) | {light} | {lr['hard']['frame_ms']:.0f} | {lr['reference']['frame_ms']:.0f} | "
                     f"{lr['hard']['mean_V']:.4f} | {lr['reference']['mean_V']:.4f} | {lr['hard']['nan'] + lr['reference']['nan']} |")
    if len(city) == 2:
        L += ["", "## Ray throughput on city (the same shadow rays, from arrays)", "",
              "| light | rays | flattened, one by one Mrays/s | flattened, packets Mrays/s | instanced, one by one Mrays/s | instanced / flattened (one by one) | blocked (flat / instanced) |",
              "|---|---|---|---|---|---|---|"]
        for light in city["flattened"]["lights"]:
            a = city["flattened"]["lights"][light]["rays"]
            b = city["instanced"]["lights"][light]["rays"]
            L.append(f"| {light} | {a['rays']:,} | {a['one_by_one']['mrays_s']:.2f} | {a['packets']['mrays_s']:.2f} | {b['one_by_one']['mrays_s']:.2f} | "
                     f"{b['one_by_one']['mrays_s'] / a['one_by_one']['mrays_s']:.2f} | {a['one_by_one']['blocked']:,} / {b['one_by_one']['blocked']:,} |")
        L += ["", "The rays are generated from each way's own G-buffer, whose points agree to float rounding; the blocked counts "
              "show they meet the same geometry."]
    md.write_text("\n".join(L) + "\n")


if __name__ == "__main__":
    print(json.dumps(measure(json.loads(sys.argv[1]))))
