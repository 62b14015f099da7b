"""Sweep ``foundation``'s rows of the reference's shadow rays: a frame's reference passes per ray
against packets (``reference_frame``) and the throughput of its rays beside Embree's (embreex) on
the same rays and thread count (``ray_throughput``), and their sections of the report."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from wsoft.bench.common import install_command
from wsoft.bench.harness import load


def _reference_frame(case: dict, ctx: dict) -> dict:
    """``reference samples=N`` on every light of a scene, per-ray against packet traversal: the
    reference passes' time (median of 3 after a warm-up), whether V is identical and, where not,
    how many pixels differ and by how much. A stage kept instanced (:func:`~wsoft.pipeline.load_stage`)
    is traced ray by ray only: packets walk the triangle soup."""
    import wsoft

    scene = load(case["scene"])
    kw = {"width": case["width"], "height": case["height"], "device": case["device"], "samples": case["samples"], "seed": 1}
    out = {"scene": case["scene"], "lights": len(scene.lights), "triangles": scene.total_triangles, "instanced": bool(scene.instanced)}
    frames = {}
    for mode in ("ray",) if scene.instanced else ("ray", "packet"):
        wsoft.render(scene, "reference", traversal=mode, **kw)
        runs = []
        for _ in range(3):
            fr = wsoft.render(scene, "reference", traversal=mode, **kw)
            st = fr.stats
            runs.append(sum(ms for name, ms in st["timings_ms"].items() if name.startswith("reference")))
        frames[mode] = fr
        out[f"{mode}_ms"] = float(np.median(runs))
        out[f"{mode}_frame_ms"] = st["timings_ms"]["total"]
    if scene.instanced:
        return out
    out["packet_over_ray"] = out["ray_ms"] / out["packet_ms"]
    chans = [c for c in frames["ray"].channels if c.startswith("V")]
    out["identical"] = all(np.array_equal(frames["ray"][c], frames["packet"][c]) for c in chans)
    differ = np.zeros(frames["ray"].V.shape, bool)
    for c in chans:
        differ |= frames["ray"][c] != frames["packet"][c]
    out["differing_pixels"] = int(differ.sum())
    out["max_abs_dv"] = float(max(np.abs(frames["ray"][c] - frames["packet"][c]).max() for c in chans if not c.endswith("stderr")))
    return out


def _throughput(case: dict, ctx: dict) -> dict:
    from wsoft.parallel import cpu_threads
    from wsoft.lightspace.light import disk_shaped
    from wsoft.reference import reference_pattern, shadow_rays, trace_ray_packets, trace_reference, trace_rays
    from wsoft.reference.packets import packed_bvh
    from wsoft.pipeline import RenderContext, frame_setup
    from wsoft.raster.camera import camera_gpu
    from wsoft.raster.gbuffer import render_gbuffer
    from wsoft.scene.device import upload_scene

    scene = load(case["scene"])
    light = scene.find_light(case["light"]) if case["light"] else scene.lights[0]
    dev, w, h, n = case["device"], case["width"], case["height"], case["samples"]
    ds, _ = scene.device_copy(dev, upload_scene)
    ctx_r = RenderContext(scene, frame_setup(scene, w, h).camera, w, h, dev)
    gb = render_gbuffer(ds, camera_gpu(ctx_r.camera), w, h, 1, scene.has_cutouts)
    L = ctx_r.light_gpu(light)
    covered = int((gb.prim.numpy() >= 0).sum())
    nrays = covered * n
    pattern = reference_pattern(n, 0, True)
    disk = disk_shaped(light)
    threads = cpu_threads() if dev == "cpu" else None
    o, d, t = shadow_rays(ds, L, gb, pattern, disk)
    packed_stats = packed_bvh(ds)[1]  # built once, outside the timings
    row = {"scene": case["scene"], "light": light.path, "device": dev, "rays": nrays, "threads": threads, "samples": n,
           "packed_bvh": packed_stats}
    # the reference pass (ray generation included) and the explicit rays (tracing only), per ray and in packets
    timed = {"pass_ray": lambda: trace_reference(ds, L, gb, pattern, disk, "ray"),
             "pass_packet": lambda: trace_reference(ds, L, gb, pattern, disk, "packet"),
             "rays_ray": lambda: trace_rays(ds, o, d, t),
             "rays_packet": lambda: trace_ray_packets(ds, o, d, t, n)}
    plan = []  # (key, Warp's CPU threads: None = all, the function): every one timed once a round, in this order
    for key, fn in timed.items():
        plan.append((key, None, fn))
        if dev == "cpu":
            plan.append((f"{key}_1t", 1, fn))
    if dev == "cpu":  # what generation costs inside the pass, without tracing (bench/generation.py), on one thread
        import warp as wp

        from wsoft.bench.generation import covered_receivers, generate_packets, random_draws
        from wsoft.parallel import launch_chunked
        from wsoft.reference import PER_THREAD

        ls = pattern.on(dev, disk)
        sink = wp.empty(gb.count, dtype=float, device=dev)
        plan += [("generation_1t", 1, lambda: launch_chunked(generate_packets, gb.count, inputs=[L, ls, gb.gpu(), -1.0], outputs=[sink],
                                                               device=dev, min_chunk=256, per_thread=PER_THREAD)),
                 ("random_draws_1t", 1, lambda: launch_chunked(random_draws, gb.count, inputs=[ls, gb.gpu()], outputs=[sink], device=dev,
                                                                min_chunk=256, per_thread=PER_THREAD)),
                 ("launch_1t", 1, lambda: launch_chunked(covered_receivers, gb.count, inputs=[gb.gpu()], outputs=[sink], device=dev,
                                                          min_chunk=256, per_thread=PER_THREAD))]
    warp_hits = trace_rays(ds, o, d, t).numpy()
    row["packets_identical"] = bool(np.array_equal(trace_ray_packets(ds, o, d, t, n).numpy(), warp_hits)
                                    and np.array_equal(timed["pass_ray"]()[0].numpy(), timed["pass_packet"]()[0].numpy()))
    row["occluded_fraction"] = float(warp_hits.mean())
    es = None
    try:
        from embreex import mesh_construction, rtcore, rtcore_scene
    except ImportError:
        row["embree"] = f"embreex not installed ({install_command('peers')})"
    else:
        if scene.has_cutouts:
            row["embree"] = "skipped: scene has cutouts (embreex has no alpha-test filter)"
        else:
            es = rtcore_scene.EmbreeScene(rtcore.EmbreeDevice())
            mesh_construction.TriangleMesh(es, scene.points.astype(np.float32), scene.triangles.astype(np.int32))
    if es is not None:
        on, dn, tn = o.numpy().astype(np.float32), d.numpy().astype(np.float32), t.numpy().astype(np.float32)
        es.run(on[:1000], dn[:1000], dists=tn[:1000], query="OCCLUDED")  # builds the BVH
        # embreex traces a batch on the calling thread; run one batch per thread for the n-thread figure
        nt = threads or 1
        parts = [slice(i * len(on) // nt, (i + 1) * len(on) // nt) for i in range(nt)]
        from concurrent.futures import ThreadPoolExecutor

        pool = ThreadPoolExecutor(nt)
        res = {}

        def one():
            res["hits"] = es.run(on, dn, dists=tn, query="OCCLUDED")

        def many():
            list(pool.map(lambda sl: es.run(on[sl], dn[sl], dists=tn[sl], query="OCCLUDED"), parts))

        plan += [("embree_1t", 1, one), ("embree", None, many)]
    best = alternating_rounds(plan, ROUNDS)
    row["rounds"] = ROUNDS
    for key in timed:
        wall, cpu = best[key]
        row[f"{key}_ms"], row[f"{key}_mrays_s"], row[f"{key}_cpu_over_wall"] = 1e3 * wall, nrays / wall / 1e6, cpu / wall
        if f"{key}_1t" in best:  # one thread: its CPU time
            row[f"{key}_1t_mrays_s"] = nrays / best[f"{key}_1t"][1] / 1e6
    for key in ("generation", "random_draws", "launch"):
        if f"{key}_1t" in best:
            row[f"{key}_1t_ns_per_ray"] = 1e9 * best[f"{key}_1t"][1] / nrays
    if es is None:
        return row
    pool.shutdown()
    emb_hits = (res["hits"] >= 0).astype(np.int32)
    e1_wall, en_wall, en_cpu = best["embree_1t"][1], best["embree"][0], best["embree"][1]  # one thread: its CPU time
    row.update({
        "embree_1t_mrays_s": nrays / e1_wall / 1e6,
        "embree_mrays_s": nrays / en_wall / 1e6, "embree_cpu_over_wall": en_cpu / en_wall,
        "agreement_with_embree": float(np.mean(emb_hits == warp_hits)),
    })
    for key in timed:
        row[f"{key}_over_embree"] = row[f"{key}_mrays_s"] / row["embree_mrays_s"]
        if f"{key}_1t_mrays_s" in row:
            row[f"{key}_over_embree_1t"] = row[f"{key}_1t_mrays_s"] / row["embree_1t_mrays_s"]
    return row


ROUNDS = 5  # alternating rounds of every timed function in a ray_throughput row (the fastest round is kept)


def alternating_rounds(plan: list[tuple[str, int | None, object]], rounds: int) -> dict[str, tuple[float, float]]:
    """Each ``(key, threads, fn)`` of ``plan`` called once to warm up, then ``rounds`` rounds that call
    every one once in turn (``threads``: Warp's CPU threads for that call, None: all), so a slower
    stretch of a shared machine falls on all of them alike: per key the fewest wall seconds of a round
    and the fewest CPU seconds of a round (the process's: on one thread, the work itself, whatever
    else the machine runs)."""
    import time

    import warp as wp

    def call(threads, fn):
        wp.synchronize()
        t0, c0 = time.perf_counter(), time.process_time()
        if threads is None:
            fn()
        else:
            with _threads(threads):
                fn()
        wp.synchronize()
        return time.perf_counter() - t0, time.process_time() - c0

    for _, threads, fn in plan:
        call(threads, fn)
    best: dict[str, tuple[float, float]] = {}
    for _ in range(rounds):
        for key, threads, fn in plan:
            t = call(threads, fn)
            best[key] = (min(t[0], best[key][0]), min(t[1], best[key][1])) if key in best else t
    return best


class _threads:
    """Temporarily set the number of CPU threads Warp launches use."""

    def __init__(self, n: int):
        self.n = n

    def __enter__(self):
        import os

        self.old = os.environ.get("WSOFT_THREADS")
        os.environ["WSOFT_THREADS"] = str(self.n)

    def __exit__(self, *exc):
        import os

        if self.old is None:
            os.environ.pop("WSOFT_THREADS", None)
        else:
            os.environ["WSOFT_THREADS"] = self.old


# Why a stage's packet and per-ray references differ, for the stages the sweep finds not identical
PACKET_DIFFERENCES = {
    "city": ["On `city` (pixel (79, 247) of the Rect light, one ray of 64) the ray passes through the shared edge of two",
             "axis-aligned triangles; Warp's per-ray walk drops their zero-thickness boxes, the packet reaches them, and a brute",
             "force over every triangle with Warp's own test finds the hit",
             "(`tests/test_packets.py::test_a_ray_grazing_a_shared_edge_that_warps_per_ray_walk_drops`)."],
    "fence_mesh": ["On `fence_mesh` (pixel (372, 426), one ray of 64) the ray meets two triangles at the same t = 2.1116 (their",
                   "shared edge): the per-ray walk reports it unblocked, the packet and a brute force over every triangle blocked (as",
                   "on `city`)."],
}


def _cell(v, fmt: str = ".2f") -> str:
    """A table cell: ``v`` formatted, or a dash where the row has no value (not measured there:
    the 1-thread figures on CUDA, Embree where embreex is missing)."""
    return "-" if v is None else format(v, fmt)


def rays_sections(rows: list[dict]) -> list[str]:
    """The report's sections of the ``ray_throughput`` and ``reference_frame`` rows."""
    thr = [r for r in rows if r["case"]["kind"] == "ray_throughput"]
    L: list[str] = []
    if thr:
        L += ["", "## Reference shadow-ray throughput beside Embree (same rays, same thread count)", ""]
        L.append("Embree runs through embreex, which traces a batch on the calling thread: the 1-thread columns are the like-for-like")
        L.append("figure; for N threads Embree gets one batch per Python thread (embreex holds the GIL part of the time: see its CPU/wall).")
        L.append("`pass`: the reference's tracing kernel, which generates each ray from its light sample (the stratified sample, the")
        L.append("light point, the direction) before tracing it; `rays`: the same rays written out first and traced from arrays, as")
        L.append("Embree traces them. `ray`: one ray at a time through Warp's `mesh_query_ray_anyhit`; `packet`: a receiver's rays 32")
        L.append("at a time through the same BVH (`wsoft.reference.packets`). Target: packet ≥ 1.0× Embree on the same rays,")
        L.append("1 thread and all threads. `identical`: packet and per-ray answers equal bit for bit (pass visibility and ray hits).")
        L.append("These rows alone are measured again by `python -m wsoft.bench.foundation_rays` (the other rows kept).")
        rounds = sorted({r.get("rounds") for r in thr if r.get("rounds")})
        if rounds:
            L.append(f"Timing: every figure of a row (Warp's and Embree's, 1 thread and all) timed once a round in {'/'.join(map(str, rounds))} "
                     "alternating rounds after a warm-up, the fastest round kept: for all threads its wall time, for 1 thread its CPU time "
                     "(on a shared machine the work itself, not the waits); Warp on its scalar CPU backend.")
        loads = [r["machine"]["load"] for r in thr if r.get("machine", {}).get("load") is not None]
        if loads:
            L.append(f"Load average of the 2-core machine as the rows finished: {', '.join(f'{x:.1f}' for x in loads)}.")
        L.append("")
        L.append("| scene | light | samples | threads | rays | traced | Warp ray Mrays/s | Warp packet Mrays/s | Embree Mrays/s | packet / Embree | "
                 "packet / ray | 1 thread: ray | packet | Embree | packet / Embree | identical |")
        L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        for r in thr:
            if "pass_packet_mrays_s" not in r:
                continue  # a row without the packet columns (rerun the sweep)
            for kind in ("rays", "pass"):
                e, e1 = r.get("embree_mrays_s"), r.get("embree_1t_mrays_s")
                emb = f"{e:.2f} ({r['embree_cpu_over_wall']:.2f})" if e else str(r.get("embree") or "-")
                ratio = f"{r[f'{kind}_packet_mrays_s'] / e:.2f}" if e else "-"
                ratio1 = f"{r[f'{kind}_packet_1t_mrays_s'] / e1:.2f}" if e1 and f"{kind}_packet_1t_mrays_s" in r else "-"
                L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['samples']} | {_cell(r['threads'], 'd')} | {r['rays']} | "
                         f"{'from arrays' if kind == 'rays' else 'pass (generates its rays)'} | "
                         f"{r[f'{kind}_ray_mrays_s']:.2f} ({r[f'{kind}_ray_cpu_over_wall']:.2f}) | "
                         f"{r[f'{kind}_packet_mrays_s']:.2f} ({r[f'{kind}_packet_cpu_over_wall']:.2f}) | {emb} | {ratio} | "
                         f"{r[f'{kind}_packet_mrays_s'] / r[f'{kind}_ray_mrays_s']:.2f} | "
                         f"{_cell(r.get(f'{kind}_ray_1t_mrays_s'))} | {_cell(r.get(f'{kind}_packet_1t_mrays_s'))} | "
                         f"{_cell(e1)} | {ratio1} | {r['packets_identical']} |")
        gen = [r for r in thr if "generation_1t_ns_per_ray" in r and r.get("embree_1t_mrays_s") and "pass_packet_1t_mrays_s" in r]
        if gen:
            L += ["", "What the pass spends generating its rays, on one thread (ns per ray; `bench/generation.py`; the rows' 1-thread time):",
                  "`generation`: the pass's kernel with its tracing left out (the stratified sample, the light point, the direction,",
                  "the plane and light-side tests); `random draws`: only its two random draws a sample (counter-based: each a hash",
                  "of the receiver's key, the sample and the dimension, none depending on another); `launch`: the chunked launch over",
                  "the receivers alone (each covered receiver's point read, one value written); `tracing in the pass`: the pass",
                  "less `generation`. For the pass to match Embree, generation must fit in `Embree` less `tracing in the pass`",
                  "(`room for generation`); `generation / Embree`: the share of Embree's whole time per ray that generating the rays",
                  "alone takes on Warp's scalar CPU backend.", "",
                  "| scene | light | samples | pass | generation | random draws | launch | tracing in the pass | Embree | room for generation | generation / Embree |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
            for r in gen:
                p1 = 1e3 / r["pass_packet_1t_mrays_s"]
                e1 = 1e3 / r["embree_1t_mrays_s"]
                g = r["generation_1t_ns_per_ray"]
                L.append(f"| {r['scene']} | {r['light'].split('/')[-1]} | {r['samples']} | {p1:.1f} | {g:.1f} | {r['random_draws_1t_ns_per_ray']:.1f} | "
                         f"{_cell(r.get('launch_1t_ns_per_ray'), '.1f')} | {p1 - g:.1f} | {e1:.1f} | {e1 - (p1 - g):.1f} | {g / e1:.2f} |")
        pk = list({r["scene"]: r for r in thr if "packed_bvh" in r}.values())
        if pk:
            L += ["", "The packets' BVH: Warp's, repacked once per scene (both children's boxes in one 64-byte record, depth first; the",
                  "triangles' corners in leaf order): " + "; ".join(
                      f"{r['scene']}: {r['packed_bvh']['inner_nodes']} inner nodes, {r['packed_bvh']['bytes'] / 2**20:.1f} MiB, "
                      f"{r['packed_bvh']['build_ms']:.0f} ms" for r in pk) + "."]
    rf = [r for r in rows if r["case"]["kind"] == "reference_frame"]
    if rf:
        c0 = rf[0]["case"]
        L += ["", f"## `reference samples={c0['samples']}` at {c0['width']}×{c0['height']}: per-ray against packet traversal", ""]
        L.append("The reference passes of a frame (every light of the stage), median of 3 after a warm-up, with `traversal=ray` (one")
        L.append("ray at a time) and `traversal=packet` (the CPU default); `identical`: every light's V and V_stderr equal bit for bit.")
        L.append("")
        L.append("| scene | lights | triangles | ray ms | packet ms | speed-up | identical |")
        L.append("|---|---|---|---|---|---|---|")
        for r in rf:
            if r.get("instanced"):
                L.append(f"| {r['scene']} | {r['lights']} | {r['triangles']:,} (instanced) | {r['ray_ms']:.0f} | — | — | — |")
                continue
            L.append(f"| {r['scene']} | {r['lights']} | {r['triangles']:,} | {r['ray_ms']:.0f} | {r['packet_ms']:.0f} | {r['packet_over_ray']:.2f}× | "
                     f"{r['identical']} |")
        if any(r.get("instanced") for r in rf):
            L += ["", "Instanced stages (kept instanced by `instancing=auto`: they would not fit flattened) are traced ray by ray: "
                      "packets walk the triangle soup only."]
        odd = [r for r in rf if r.get("identical") is False]
        if odd:
            L += ["", "Not identical: " + "; ".join(
                f"`{r['scene']}`, {r.get('differing_pixels', '?')} pixel(s), max |ΔV| {r.get('max_abs_dv', float('nan')):.4f}" for r in odd) + "."]
            found = {r["scene"] for r in odd}
            for scene_name, lines in PACKET_DIFFERENCES.items():
                if scene_name in found:
                    L += ["", *lines]
            L += ["", "In every difference found the packet agrees with the brute force. Differences appear where a packet decides",
                  "rays that the per-ray walk would decide: a packet that gives up hands its rays to the per-ray walk, so the budget",
                  "(`WORK_PER_RAY`) moves them."]
    return L


def rerun_throughput(out_dir: str = "reports", device: str | None = None) -> Path:
    """Measure the foundation sweep's ``ray_throughput`` rows again, alone: each replaces its row in
    ``<out_dir>/foundation.jsonl`` (the other rows kept as they are) and ``foundation.md`` is written
    again from the rows, as ``wsoft bench foundation`` writes it. The report's path."""
    import os

    from wsoft.bench import foundation, harness
    from wsoft.parallel import resolve_device

    out = Path(out_dir)
    jsonl = out / "foundation.jsonl"
    devices = [resolve_device(device)]
    cases = foundation.cases(quick=False, devices=devices)
    todo = [c for c in cases if c["kind"] == "ray_throughput"]
    part = out / "foundation-ray-throughput.part.jsonl"
    part.unlink(missing_ok=True)
    ctx = {"out_dir": out, "stem": "foundation", "quick": False}
    harness.run_in_process("foundation", foundation, todo, ctx, part)
    fresh = {r["key"]: r for r in harness.read_rows(part)}
    rows = [fresh.pop(r["key"], r) for r in harness.read_rows(jsonl)] + list(fresh.values())
    tmp = jsonl.with_suffix(".jsonl.tmp")
    tmp.write_text("".join(json.dumps(r, default=harness._jsonable) + "\n" for r in rows))
    os.replace(tmp, jsonl)
    part.unlink()
    keys = {harness.case_key(c) for c in cases}
    md = out / "foundation.md"
    foundation.report([r for r in harness.finished_rows(jsonl) if r["key"] in keys], md, ctx | {"command": "wsoft bench foundation"})
    return md


if __name__ == "__main__":
    import sys

    print(f"wrote {rerun_throughput(*sys.argv[1:2])}")
