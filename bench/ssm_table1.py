"""Sweep ``ssm-table1``: build time and memory of the pruning structures (HSM, MSSM, YSM with a
256^2 MSSM part) at 1024^2 and 2048^2, beside Schwarz & Stamminger's Table 1 (GeForce 8800 GTX),
plus the microrect textures' build (the paper: 1.89 ms at 1024^2).

The map is ``fig1_plant``'s light depth map at that size (the builds do not depend on the
content). Build time: median of 7 builds after a warm-up (kernels compiled), device synchronised.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

from wsoft.bench.harness import load

# Table 1 of the paper: (structure, size) -> (construction ms, memory MB)
PAPER = {
    ("hsm", 1024): (0.26, 10.67), ("mssm", 1024): (3.92, 88.00), ("ysm", 1024): (0.46, 14.67),
    ("hsm", 2048): (0.87, 42.67), ("mssm", 2048): (18.65, 384.00), ("ysm", 2048): (1.07, 46.67),
}
SCENE = "fig1_plant"
REPEATS = 7


def cases(quick: bool, devices: list[str]) -> list[dict]:
    sizes = [256, 512] if quick else [1024, 2048]
    out = []
    for dev in devices:
        for size in sizes:
            for structure in ("hsm", "mssm", "ysm", "microrects"):
                out.append({"kind": "build", "scene": SCENE, "structure": structure, "size": size, "ysm_size": 256 if not quick else 64, "device": dev})
    return out


def depth_map(scene_name: str, size: int, device: str):
    """The soft light view's depth map of the scene's first light (as ``ssm`` renders it)."""
    from wsoft.pipeline import build_graph
    from wsoft.techniques import create

    scene = load(scene_name)
    tech = create("hard", {"shadow_map_size": size})
    built = build_graph(scene, tech, width=320, height=240, device=device)
    key = built.ctx.light_depth(built.lights["hard"][0], size=size, soft=True)
    res, _ = built.ctx.graph.execute([key], device)
    return res[key].depth


def run_case(case: dict, ctx: dict) -> dict:
    import warp as wp

    from wsoft.accel.ssm_structures import build_microrects, build_structure

    dev = case["device"]
    with wp.ScopedDevice(dev):
        d = depth_map(case["scene"], case["size"], dev)
        if case["structure"] == "microrects":
            build = lambda: build_microrects(d, dev)
        else:
            build = lambda: build_structure(case["structure"], d, dev, ysm_size=case["ysm_size"])
        build()
        runs, wall = [], []
        for _ in range(REPEATS):
            t0 = time.perf_counter()
            s = build()
            wall.append(1e3 * (time.perf_counter() - t0))
            runs.append(s.build_ms)
            mem = sum(int(a.size) * wp.types.type_size_in_bytes(a.dtype) for a in s.arrays().values())
            del s
    paper = PAPER.get((case["structure"], case["size"]))
    return {
        "structure": case["structure"], "size": case["size"], "device": dev,
        "build_ms": statistics.median(runs), "build_ms_runs": runs, "memory_mb": mem / 2**20,
        "paper_build_ms": paper[0] if paper else None, "paper_memory_mb": paper[1] if paper else None,
    }


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    m = rows[0]["machine"] if rows else {}
    L = [f"# Sweep `ssm-table1`{' (quick)' if ctx['quick'] else ''}", ""]
    L.append(f"Produced by `{ctx['command']}` (rows: `{md.with_suffix('.jsonl').name}`; rerun resumes, `--fresh` starts over).")
    L.append(f"Machine: {m.get('cpu', '?')}, {m.get('threads', '?')} CPU threads for Warp launches, Python {m.get('python', '?')}.")
    L.append("")
    sizes = " or ".join(f"{n}²" for n in sorted({r["size"] for r in rows})) or "?"
    L.append(f"Pruning structures of `ssm` built from `{SCENE}`'s light depth map (a {sizes} float32 map);")
    L.append("ranges are vec2 of float32 (8 bytes a texel a level). HSM: min/max pyramid; MSSM: every texel's ranges of")
    m = rows[0]["case"]["ysm_size"] if rows else 256
    L.append(f"its 2^s neighbourhoods, s = 0..log2 N; YSM: the full HSM plus an MSSM (scales 1..{int(math.log2(m))}) over HSM level")
    L.append(f"log2(N/{m}). Build: median of 7 after a warm-up. Paper: GeForce 8800 GTX (2008), our CPU runs are ")
    L.append("Warp kernels on the threads below, so absolute times differ by the hardware; the ratios are the point.")
    L.append("")
    L.append("| structure | size | device | build ms | memory MB | paper build ms | paper memory MB |")
    L.append("|---|---|---|---|---|---|---|")
    order = {"hsm": 0, "mssm": 1, "ysm": 2, "microrects": 3}
    for r in sorted(rows, key=lambda r: (r["device"], r["size"], order[r["structure"]])):
        name = {"ysm": f"YSM {r['size']}²/{r['case']['ysm_size']}²", "microrects": "microrect textures"}.get(r["structure"], r["structure"].upper())
        pb = "" if r["paper_build_ms"] is None else f"{r['paper_build_ms']:.2f}"
        pm = "" if r["paper_memory_mb"] is None else f"{r['paper_memory_mb']:.2f}"
        if r["structure"] == "microrects" and r["size"] == 1024:
            pb = "1.89"
        L.append(f"| {name} | {r['size']}² | {r['device']} | {r['build_ms']:.2f} | {r['memory_mb']:.2f} | {pb} | {pm} |")
    L += ["", "## Targets", ""]
    by = {(r["device"], r["structure"], r["size"]): r for r in rows}
    for dev in sorted({r["device"] for r in rows}):
        big = max(r["size"] for r in rows if r["device"] == dev)
        m, y = by.get((dev, "mssm", big)), by.get((dev, "ysm", big))
        if m and y:
            tb, tm = m["build_ms"] / y["build_ms"], m["memory_mb"] / y["memory_mb"]
            ok = "met" if tb >= 4 and tm >= 4 else "NOT met"
            L.append(f"- YSM at least 4× cheaper to build and 4× smaller than the MSSM at {big}² ({dev}): build {m['build_ms']:.2f} / "
                     f"{y['build_ms']:.2f} ms = **{tb:.1f}×**, memory {m['memory_mb']:.2f} / {y['memory_mb']:.2f} MB = **{tm:.1f}×** — {ok}. "
                     f"(Paper: {18.65 / 1.07:.1f}× and {384 / 46.67:.1f}×.)")
    md.write_text("\n".join(L) + "\n")
