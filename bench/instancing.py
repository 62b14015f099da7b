"""Sweep ``instancing``: instanced USD kept instanced, against flattened.

Each row runs in a child process of its own (``python -m wsoft.bench.instancing CASE``), so that
its peak resident memory (``ru_maxrss``) is its own: a stage loaded flattened or instanced
(``load_scene(..., instancing=...)``), uploaded to the device (``upload_scene``: the BVHs, and for
instances the prototypes' BVHs and the top level), then the frames asked for at 640 x 480 (160 x
120 in ``--quick``), each light's in alternating rounds (:data:`ROUNDS`, medians): ``hard`` (a 2048²
map; 512² quick) at its defaults (``map_texels=auto``) and rasterizing the whole map
(``map_texels=all``), and ``reference`` at 16 and at 4 light samples. A warm-up frame at 32 x 24
compiles the kernels first, so frame times hold no compilation.

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


ROUNDS = 3  # alternating rounds of every frame setting; medians are reported


def frame_settings(case: dict) -> dict:
    """The frames of a light: ``hard`` at its defaults (``map_texels=auto``), ``hard`` rasterizing the
    whole map (``map_texels=all``), the reference at the case's samples and at 4 samples."""
    size = case["map"]
    return {"hard": ("hard", {"shadow_map_size": size}), "hard_raster": ("hard", {"shadow_map_size": size, "map_texels": "all"}),
            "reference": ("reference", {"samples": case["samples"]}), "reference4": ("reference", {"samples": 4})}


def technique_ms(timings: dict) -> float:
    """A frame's passes but the G-buffer's (and the scene's upload): what a technique itself costs."""
    return float(sum(v for k, v in timings.items() if k not in ("total", "compile", "upload_scene") and not k.startswith("gbuffer")))


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
        settings = frame_settings(case)
        for tech, kw in settings.values():
            render(scene, tech, width=32, height=24, light=light.path, device=dev, **kw)  # compile
        times = {k: [] for k in settings}
        last_v = {}
        for _ in range(ROUNDS):  # alternating rounds: each setting once per round
            for k, (tech, kw) in settings.items():
                fr = render(scene, tech, width=w, height=h, light=light.path, device=dev, **kw)
                tm = fr.stats["timings_ms"]
                times[k].append((tm["total"], technique_ms(tm)))
                lrow[k] = {"mean_V": float(np.nanmean(fr.V)), "nan": int(np.isnan(fr.V).sum()),
                           "instancing": fr.stats["scene"]["instancing"]["mode"], "passes_ms": tm,
                           "drawn_by": sorted({"rays" if "_read" in n else "rasterizer" for n in fr.stats["passes"] if n.startswith("light_depth")}),
                           "texels_read": sum(c.get("texels_read", 0) for c in fr.stats["counters"]["passes"].values())}
                if k.startswith("hard"):
                    last_v[k] = fr.V
        for k, t in times.items():
            lrow[k]["frame_ms"] = float(np.median([a for a, _ in t]))
            lrow[k]["technique_ms"] = float(np.median([b for _, b in t]))
            lrow[k]["rounds_technique_ms"] = [b for _, b in t]
        if "hard_raster" in last_v:  # the map of the texels read against the rasterized map: pixels whose V differs
            lrow["hard"]["pixels_differing_from_raster"] = int(np.count_nonzero(last_v["hard"] != last_v["hard_raster"]))
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
    from wsoft.reference import reference_pattern, shadow_rays, trace_ray_packets, trace_rays
    from wsoft.pipeline import frame_setup

    cam = camera_gpu(frame_setup(scene, w, h).camera)
    gb = render_gbuffer(ds, cam, w, h, 1, scene.has_cutouts)
    pattern = reference_pattern(samples, 0, True)
    o, d, t = shadow_rays(ds, light_gpu(light, scene.diagonal), gb, pattern, disk_shaped(light))
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
    L += ["", "## Frames", "",
          f"Every light's frames in {ROUNDS} alternating rounds in one process (medians): `hard` at its defaults (`map_texels=auto`: "
          "where the light's casting triangles, instances placed, outnumber the frame's samples 16 to one, only the texels the "
          "receivers read are drawn, one ray each, `wsoft.raster.raycast`), `hard` rasterizing the whole map (`map_texels=all`), "
          "and the reference at 4 samples and at the case's samples. *Technique ms*: the frame's passes but the G-buffer's. Where "
          "`hard`'s map is drawn by the rasterizer, its two columns are the same setting: their difference is the rounds' spread "
          "(`rounds_technique_ms` in the rows).", "",
          "| scene | mode | light | hard map drawn by | texels read | hard technique ms | hard, whole map rasterized, technique ms | reference 4 samples technique ms | "
          "hard / reference 4 | reference 16 frame ms | hard mean V | pixels where the two hard maps differ | reference 16 mean V | NaN |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for light, lr in r["lights"].items():
            h, hr, r4, ref = lr["hard"], lr.get("hard_raster"), lr.get("reference4"), lr["reference"]
            if hr is None or r4 is None:
                continue
            nan = sum(x["nan"] for x in (h, hr, r4, ref))
            L.append(f"| {r['scene']} | {r['mode']} ({h['instancing']}) | {light} | {', '.join(h['drawn_by'])} | {h['texels_read']:,} | "
                     f"{h['technique_ms']:.0f} | {hr['technique_ms']:.0f} | {r4['technique_ms']:.0f} | {h['technique_ms'] / r4['technique_ms']:.2f} | "
                     f"{ref['frame_ms']:.0f} | {h['mean_V']:.4f} | {h['pixels_differing_from_raster']:,} | {ref['mean_V']:.4f} | {nan} |")
    for r in rows:
        for light, lr in r["lights"].items():
            h, hr = lr["hard"], lr.get("hard_raster")
            if hr is None or "rays" not in h["drawn_by"] or not h["texels_read"]:
                continue
            L.append(f"\n{r['scene']} {light}: the whole map rasterized costs {1e6 * hr['technique_ms'] / r['triangles']:.0f} ns of wall time per "
                     f"placed triangle of the stage ({r['triangles']:,}; the map draws every instance whose box reaches the view); the texels the receivers "
                     f"read cost {1e3 * h['technique_ms'] / h['texels_read']:.2f} µs each ({h['texels_read']:,} rays, the technique's other "
                     "passes included).")
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
