"""Sweep ``cube``: cube maps for local lights that surround their receivers (:mod:`wsoft.lightspace.cube`).

Three kinds of row, each against a ray-traced reference on the same pixels:

* ``frame``: each bundled stage of :data:`FRAME_SCENES`, each of its sphere, point or cylinder
  lights; every shadow-map technique (those with a ``cube`` parameter) at its defaults, once with
  ``cube=auto`` (a cube map where its receivers need one) and once with ``cube=never`` (one frustum
  of at most ±80°), in one frame graph: penumbra MAE, frame time, the fraction of receivers outside
  every map (from the frame's warnings), the faces and texels drawn, the *seam error* (MAE on the
  pixels within a filter width of a face edge beside the MAE elsewhere) and the depth passes' time.
* ``seam``: the ring of posts of :func:`~wsoft.stages.cube_cases.ring_stage`, whose penumbrae cross
  face edges, with each technique's guard band and with none
  (:data:`~wsoft.lightspace.cube.GUARD_OVERRIDE` = 0): error near edges against error elsewhere.
* ``seam_lookup``: the same ring, ``pcf`` with its kernel crossing face edges read two ways: faces
  drawn with a guard band of the kernel's width (``seams=guard``) or with the bilinear texel's and
  each tap read from the face its direction belongs to (``seams=lookup``,
  :mod:`wsoft.accel.cube_filter`), at two kernel widths.
* ``paraboloid``: the frames of ``frame`` again, for the techniques that take ``omni`` (``hard``,
  ``pcf``): the cube map against a dual-paraboloid map (:mod:`wsoft.lightspace.paraboloid`) at the
  same size per side and at about the cube's texel count: error, the error within a kernel's width
  of the paraboloids' equator beside elsewhere, the depth passes' and the frame's time.
* ``spread``: a sphere light over a field of posts seen out to a half-angle θ off its axis
  (:func:`~wsoft.stages.cube_cases.spread_stage`), one frustum against a cube map: where the cube
  starts to win, which sets :data:`~wsoft.lightspace.cube.CUBE_THRESHOLD_DEG`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from wsoft.bench.harness import cache_dir, ground_truth, load, measure, reference

FRAME_SCENES = ("room_lamp", "corridor_torch", "multi_light")
QUICK_FRAME_SCENES = ("multi_light",)
SEAM_TECHS = ("pcf", "pcss", "vsm", "essm", "msm_soft")
SPREAD_ANGLES = (30.0, 45.0, 55.0, 60.0, 65.0, 70.0, 79.0)
QUICK_SPREAD = (45.0, 70.0)
SPREAD_TECHS = ("hard", "pcf", "pcss", "vsm")
SIZE = (256, 192)
MAP = 512
GROUND_TRUTH = 256
EDGE_TEXELS = 4.0  # the seam error's band: pixels within this many texels (or the technique's guard band, if wider) of a face edge


def _cube_techniques() -> list[str]:
    """Every registered technique with light views (a ``cube`` parameter)."""
    import dataclasses

    from wsoft.techniques import TECHNIQUES

    return sorted(n for n, c in TECHNIQUES.items() if any(f.name == "cube" for f in dataclasses.fields(c.Params)))


def cases(quick: bool, devices: list[str]) -> list[dict]:
    from wsoft import usd_scenes
    from wsoft.lightspace.cube import CUBE_KINDS

    have = set(usd_scenes.names())
    w, h = (96, 72) if quick else SIZE
    common = {"width": w, "height": h, "map": 256 if quick else MAP, "ground_truth": 64 if quick else GROUND_TRUTH, "quick": quick}
    out = []
    for dev in devices:
        for name in [n for n in (QUICK_FRAME_SCENES if quick else FRAME_SCENES) if n in have]:
            for l in load(name).lights:
                if l.kind in CUBE_KINDS:
                    out.append({"kind": "frame", "scene": name, "file": name, "light": l.path, "device": dev, **common})
                    out.append({"kind": "paraboloid", "scene": name, "file": name, "light": l.path, "device": dev, **common})
        out.append({"kind": "seam", "scene": "cube_ring", "device": dev, **common, "width": 3 * h // 2, "height": 3 * h // 2})
        out.append({"kind": "seam_lookup", "scene": "cube_ring", "device": dev, **common, "width": 3 * h // 2, "height": 3 * h // 2})
        for a in QUICK_SPREAD if quick else SPREAD_ANGLES:
            out.append({"kind": "spread", "scene": f"cube_spread_{a:g}", "angle": a, "device": dev, **common, "width": h, "height": h})
    return out


def _stage_folder() -> str:
    d = cache_dir() / "cube_stages"
    d.mkdir(parents=True, exist_ok=True)
    return str(d)


_OUTSIDE = re.compile(r"(\d+) of (\d+) visible samples lie (outside its single-frustum view|in cube-map faces)")


def outside_fraction(warnings: list[str]) -> float:
    """The fraction of the visible samples a frame's warnings say were left outside every map."""
    n = 0
    total = 0
    for w in warnings:
        m = _OUTSIDE.search(w)
        if m:
            n += int(m.group(1))
            total = max(total, int(m.group(2)))
    return n / total if total else 0.0


def edge_texels(light, pos: np.ndarray, size: int, guard_tan: float) -> np.ndarray:
    """Per point, its distance in texels (of a face ``size`` texels across a window of half-size
    ``1 + guard_tan``) from the nearest edge of its own cube face."""
    from wsoft.lightspace.cube import cube_frame

    q = (pos.reshape(-1, 3) - np.asarray(light.position, np.float64)) @ cube_frame(light)
    a = np.sort(np.abs(q), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        m = np.where(a[:, 2] > 0, a[:, 1] / a[:, 2], 0.0)  # the second-largest tangent in the owner face
    return ((1.0 - m) * size / (2.0 * (1.0 + guard_tan))).reshape(pos.shape[:-1])


def _seam(v: np.ndarray, truth: np.ndarray, near: np.ndarray, pen: np.ndarray) -> dict:
    e = np.abs(v - truth)
    a, b = pen & near, pen & ~near
    return {"edge_pixels": int(a.sum()), "mae_edge": float(e[a].mean()) if a.any() else math.nan,
            "mae_elsewhere": float(e[b].mean()) if b.any() else math.nan}


def _turned_seam(fr, fr30, truth: np.ndarray, near: np.ndarray, pen: np.ndarray) -> dict:
    """:func:`_seam` of frame ``fr`` and how much V changes in ``fr30`` (the light's frame turned
    30°, which moves the face edges, not the shadows) near the edges and elsewhere, and its frame ms."""
    s = _seam(fr.V, truth, near, pen)
    d = np.abs(fr.V - fr30.V)
    s.update(turned_edge=float(d[pen & near].mean()), turned_elsewhere=float(d[pen & ~near].mean()),
             frame_ms=fr.stats["timings_ms"]["total"])
    return s


def _face_ms(stats: dict, light_label: str) -> float:
    """The time of the passes run once per cube face (their names carry ``[Light/+x]``)."""
    return float(sum(v for k, v in stats["timings_ms"].items() if f"{light_label}/" in k))


def _positions(fs) -> np.ndarray:
    """The covered pixels' world positions [H, W, 3] (the G-buffer's, shared by every frame of a graph)."""
    f = next(iter(fs.values()))
    return np.stack([f["P.X"], f["P.Y"], f["P.Z"]], -1).astype(np.float64)


def _depth_ms(stats: dict, light_label: str) -> float:
    t = stats["timings_ms"]
    return float(sum(v for k, v in t.items() if k.startswith("light_depth") and (f"[{light_label}]" in k or f"[{light_label}/" in k)))


def run_case(case: dict, ctx: dict) -> dict:
    return {"frame": _frame, "seam": _seam_row, "seam_lookup": _seam_lookup, "spread": _spread,
            "paraboloid": _paraboloid}[case["kind"]](case)


def _entries(case: dict, file: str, light_path: str, techs: list[tuple[str, dict]], extra=None):
    ref = reference(file, width=case["width"], height=case["height"], light=light_path, samples=case["ground_truth"], device=case["device"])
    truth = ground_truth(file, ref, light_path)
    fs = measure(file, techs, device=case["device"], width=case["width"], height=case["height"], light=light_path, truth=truth)
    return ref, fs


def _measured(case: dict, light_path: str, techs: list[tuple[str, dict]]):
    """A frame's graph measured against its reference: (reference, frames, penumbra pixels, covered pixels' positions)."""
    ref, fs = _entries(case, case["file"], light_path, techs)
    pen = (ref["A"] > 0) & (ref["V"] > 0.02) & (ref["V"] < 0.98)
    return ref, fs, pen, _positions(fs)


def _frame(case: dict) -> dict:
    from wsoft.techniques import TECHNIQUES, create

    scene = load(case["file"])
    L = scene.find_light(case["light"])
    label = scene.light_label(L)
    techs = []
    for t in _cube_techniques():
        cls = TECHNIQUES[t]
        if create(t).supports(scene, L) is not None:
            continue
        for mode in ("auto", "never"):
            techs.append((t, {cls.size_param: case["map"], "cube": mode}))
    ref, fs, pen, P = _measured(case, L.path, techs)
    entries = []
    for (t, params), (lab, fr) in zip(techs, fs.items()):
        st = fr.stats
        c = st["counters"]["techniques"].get(lab, {}).get(label, {})
        guard = next((v.get("guard", 0.0) for k, v in st["counters"]["passes"].items() if k.startswith(f"fit_cube[{label}]")), 0.0)
        band = max(EDGE_TEXELS, create(t, params).cube_guard_texels())
        near = edge_texels(L, P, case["map"], guard) <= band
        entries.append({"technique": t, "params": params, "frame_ms": st["timings_ms"]["total"], "frame_ms_runs": st["timings_ms_runs"],
                        "error": st["error"], "outside": outside_fraction(st["warnings"]), "cube_faces": c.get("cube_faces", []),
                        "cube_texels": c.get("cube_texels", 0), "depth_ms": _depth_ms(st, label),
                        "face_ms": _face_ms(st, label),
                        "seam": _seam(fr.V, ref["V"], near, pen) if c.get("cube_faces") else None,
                        "warnings": [w for w in st["warnings"] if w not in scene.warnings]})
    decision = next(iter(fs.values())).stats["counters"]["passes"]
    return {"scene": case["scene"], "light": L.path, "light_kind": L.kind_name, "device": case["device"], "width": case["width"],
            "height": case["height"], "ground_truth_samples": case["ground_truth"], "map": case["map"], "entries": entries,
            "penumbra_pixels": int(pen.sum()), "fit_cube": {k: v for k, v in decision.items() if k.startswith("fit_cube")}}


PARABOLOID_TECHS = ("hard", "pcf")


def equator_texels(light, pos: np.ndarray, size: int, radius: float) -> np.ndarray:
    """Per pixel, how many texels of a dual-paraboloid map of ``size`` (window half-width
    ``radius``) its direction from the light's centre lies from the equator (inf on background)."""
    from wsoft.lightspace.cube import cube_frame
    from wsoft.lightspace.view import to_frame

    q = to_frame(pos.reshape(-1, 3), np.asarray(light.position, np.float64), cube_frame(light))
    n = np.linalg.norm(q, axis=1)
    q = q / np.maximum(n, 1e-300)[:, None]
    r = np.hypot(q[:, 0], q[:, 1]) / (1.0 + np.abs(q[:, 2]))
    out = np.abs(1.0 - r) * size / (2.0 * radius)
    out[n == 0.0] = np.inf
    return out.reshape(pos.shape[:-1])


def paraboloid_sizes(size: int) -> tuple[int, int]:
    """The dual-paraboloid maps measured beside a cube map of ``size``: the same size per side, and
    about six faces' texel count in two hemispheres (``size √3``, on a multiple of 64)."""
    return size, int(64 * round(size * math.sqrt(3.0) / 64))


def _paraboloid(case: dict) -> dict:
    from wsoft.lightspace.cube import guard_window
    from wsoft.lightspace.paraboloid import guard_texels_for
    from wsoft.techniques import create

    scene = load(case["file"])
    L = scene.find_light(case["light"])
    label = scene.light_label(L)
    techs = []
    for t in PARABOLOID_TECHS:
        techs.append((t, {"shadow_map_size": case["map"], "cube": "auto", "omni": "cube"}))
        for size in paraboloid_sizes(case["map"]):
            techs.append((t, {"shadow_map_size": size, "cube": "auto", "omni": "paraboloid"}))
    ref, fs, pen, P = _measured(case, L.path, techs)
    entries = []
    for (t, params), (lab, fr) in zip(techs, fs.items()):
        st = fr.stats
        c = st["counters"]["techniques"].get(lab, {}).get(label, {})
        dp = params["omni"] == "paraboloid" and bool(c.get("paraboloid_hemispheres"))
        seam = None
        if dp:
            g = guard_texels_for(create(t, params).params.radius if t == "pcf" else 0.0)
            near = equator_texels(L, P, params["shadow_map_size"], guard_window(g, params["shadow_map_size"])) <= max(EDGE_TEXELS, g)
            seam = _seam(fr.V, ref["V"], near, pen)
        t_ms = st["timings_ms"]
        depth_ms = (sum(v for k, v in t_ms.items() if k.startswith(f"paraboloid[{label}]")) if dp else _depth_ms(st, label))
        entries.append({"technique": t, "params": params, "frame_ms": t_ms["total"], "frame_ms_runs": st["timings_ms_runs"],
                        "error": st["error"], "outside": outside_fraction(st["warnings"]),
                        "views": (f"dual-paraboloid, {len(c['paraboloid_hemispheres'])} hemispheres" if dp
                                  else f"cube map, {len(c['cube_faces'])} faces" if c.get("cube_faces") else "one frustum"),
                        "texels": c.get("paraboloid_texels") or c.get("cube_texels") or params["shadow_map_size"] ** 2,
                        "depth_ms": float(depth_ms), "seam": seam, "warnings": [w for w in st["warnings"] if w not in scene.warnings]})
    return {"scene": case["scene"], "light": L.path, "light_kind": L.kind_name, "device": case["device"], "width": case["width"],
            "height": case["height"], "ground_truth_samples": case["ground_truth"], "map": case["map"], "entries": entries,
            "penumbra_pixels": int(pen.sum())}


def _seam_row(case: dict) -> dict:
    import wsoft.lightspace.cube as cube
    from wsoft.stages.cube_cases import ring_stage

    folder = _stage_folder()
    files = {turn: ring_stage(folder, turn) for turn in (0.0, 30.0)}
    light = load(files[0.0]).lights[0]
    techs = [(t, {"shadow_map_size": case["map"], "cube": "always"}) for t in SEAM_TECHS]
    out = {}
    for guard in ("technique", "none"):
        cube.GUARD_OVERRIDE = 0.0 if guard == "none" else None
        try:
            vs = {}
            for turn, f in files.items():
                ref, fs = _entries(case, f, light.path, techs)
                vs[turn] = (ref, fs)
        finally:
            cube.GUARD_OVERRIDE = None
        ref0, fs0 = vs[0.0]
        _, fs30 = vs[30.0]
        cov = ref0["A"] > 0
        pen = cov & (ref0["V"] > 0.02) & (ref0["V"] < 0.98)
        P = _positions(fs0)
        res = []
        for (t, _), (lab, fr), (_, fr30) in zip(techs, fs0.items(), fs30.items()):
            near = edge_texels(light, P, case["map"], 0.0) <= max(EDGE_TEXELS, 8.0)
            res.append({"technique": t, **_turned_seam(fr, fr30, ref0["V"], near, pen)})
        out[guard] = res
    return {"scene": case["scene"], "device": case["device"], "width": case["width"], "height": case["height"], "map": case["map"],
            "ground_truth_samples": case["ground_truth"], "guards": out}


LOOKUP_RADII = (2.0, 8.0)  # pcf kernel half-widths (texels) of the seam_lookup rows


def _seam_lookup(case: dict) -> dict:
    """``pcf`` on the ring with ``seams=guard`` and ``seams=lookup`` at :data:`LOOKUP_RADII`: the
    seam error (pixels within the kernel's width, at least :data:`EDGE_TEXELS`, of a face edge), the
    change when the light's frame turns 30°, the depth passes' and the frame's time."""
    from wsoft.stages.cube_cases import ring_stage

    folder = _stage_folder()
    files = {turn: ring_stage(folder, turn) for turn in (0.0, 30.0)}
    light = load(files[0.0]).lights[0]
    label = light.path.rsplit("/", 1)[-1]
    techs = [("pcf", {"shadow_map_size": case["map"], "cube": "always", "radius": r, "seams": s}) for r in LOOKUP_RADII
             for s in ("guard", "lookup")]
    (ref0, fs0), (_, fs30) = (_entries(case, files[t], light.path, techs) for t in (0.0, 30.0))
    cov = ref0["A"] > 0
    pen = cov & (ref0["V"] > 0.02) & (ref0["V"] < 0.98)
    P = _positions(fs0)
    res = []
    for (t, params), fr, fr30 in zip(techs, fs0.values(), fs30.values()):
        near = edge_texels(light, P, case["map"], 0.0) <= max(EDGE_TEXELS, params["radius"] + 2.0)
        guard = next((v.get("guard", 0.0) for k, v in fr.stats["counters"]["passes"].items() if k.startswith("fit_cube[")), 0.0)
        res.append({**_turned_seam(fr, fr30, ref0["V"], near, pen), "technique": t, "radius": params["radius"], "seams": params["seams"],
                    "guard": float(guard), "depth_ms": _depth_ms(fr.stats, label)})
    return {"scene": case["scene"], "device": case["device"], "width": case["width"], "height": case["height"], "map": case["map"],
            "ground_truth_samples": case["ground_truth"], "settings": res}


def _spread(case: dict) -> dict:
    from wsoft.stages.cube_cases import spread_stage

    f = spread_stage(_stage_folder(), case["angle"])
    light = load(f).lights[0]
    techs = [(t, {"shadow_map_size": case["map"], "cube": mode}) for t in SPREAD_TECHS for mode in ("never", "always")]
    ref, fs = _entries(case, f, light.path, techs)
    entries = [{"technique": t, "cube": p["cube"], "frame_ms": fr.stats["timings_ms"]["total"], "error": fr.stats["error"],
                "outside": outside_fraction(fr.stats["warnings"])} for (t, p), (lab, fr) in zip(techs, fs.items())]
    return {"scene": case["scene"], "angle": case["angle"], "device": case["device"], "width": case["width"], "height": case["height"],
            "map": case["map"], "ground_truth_samples": case["ground_truth"], "entries": entries}


# -- report -------------------------------------------------------------------------------------------


def _plot_spread(rows: list[dict], md: Path, ctx: dict) -> str | None:
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wsoft.palette import style

    fig, ax = plt.subplots(figsize=(6.4, 3.6), constrained_layout=True)
    rows = sorted(rows, key=lambda r: r["angle"])
    for t in SPREAD_TECHS:
        for mode, line in (("never", "--"), ("always", "-")):
            xs = [r["angle"] for r in rows]
            ys = [next(e["error"]["mae_penumbra"] for e in r["entries"] if e["technique"] == t and e["cube"] == mode) for r in rows]
            ax.plot(xs, ys, line, marker=style(t)["marker"], color=style(t)["color"], mfc="none" if mode == "never" else None,
                    label=f"{t}, {'cube map' if mode == 'always' else 'one frustum'}")
    from wsoft.lightspace.cube import CUBE_THRESHOLD_DEG

    ax.axvline(CUBE_THRESHOLD_DEG, color="0.5", lw=0.8)
    ax.set_xlabel("receivers' half-angle off the light's axis (degrees)")
    ax.set_ylabel("penumbra MAE")
    ax.set_yscale("log")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title(f"one frustum or a cube map, {rows[0]['map']}² maps", fontsize=9)
    rel = Path("images") / ctx["stem"] / "spread.png"
    out = Path(ctx["out_dir"]) / rel
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return rel.as_posix()


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header
    from wsoft.lightspace.cube import CUBE_THRESHOLD_DEG, GUARD_MAX

    L = report_header("cube", rows, md, ctx)
    frames = [r for r in rows if r["case"]["kind"] == "frame"]
    seams = [r for r in rows if r["case"]["kind"] == "seam"]
    spreads = [r for r in rows if r["case"]["kind"] == "spread"]
    L += ["Cube maps (`wsoft.lightspace.cube`): six 90° faces around a sphere, point or cylinder light, each drawn with a guard band "
          "(the technique's widest kernel in texels; a soft view's caster growth, at most "
          f"{GUARD_MAX:g} in tangents), each receiver's visibility from the face of the dominant axis of its direction from the light. "
          f"`cube=auto` draws one where the receivers lie more than {CUBE_THRESHOLD_DEG:g}° off one axis (a low-resolution probe decides); "
          "`cube=never` is one frustum of at most ±80°, which leaves the receivers beyond it lit and warns. Errors against a "
          "reference on the same pixels; frame ms: the passes a technique needs (median of 3 after a warm-up).", ""]
    for r in frames:
        n = r["entries"]
        L += [f"## {r['scene']} / {r['light'].split('/')[-1]} ({r['light_kind']}), {r['width']}x{r['height']}, {r['map']}² maps, "
              f"reference {r['ground_truth_samples']} spp", ""]
        fc = next(iter(r["fit_cube"].values()), None)
        if fc:
            L.append(f"Cube map: faces {', '.join(fc['cube_faces'])}; receivers per face {fc['receivers_per_face']}.")
            L.append("")
        L += ["| technique | views | penumbra MAE | MAE | outside every map | faces | texels | depth ms | frame ms | seam: MAE near edges / elsewhere |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---|"]
        for e in sorted(n, key=lambda e: (e["technique"], e["params"]["cube"])):
            s = e["seam"]
            seam = "" if not s else f"{s['mae_edge']:.4f} / {s['mae_elsewhere']:.4f} ({s['edge_pixels']} px)"
            views = "cube map" if e["cube_faces"] else "one frustum"
            L.append(f"| {e['technique']} | {views} (cube={e['params']['cube']}) | {e['error']['mae_penumbra']:.4f} | {e['error']['mae']:.4f} | "
                     f"{100 * e['outside']:.1f}% | {len(e['cube_faces']) or 1} | {e['cube_texels'] or r['map'] ** 2:,} | {e['depth_ms']:.1f} | "
                     f"{e['frame_ms']:.1f} | {seam} |")
        L.append("")
    paras = [r for r in rows if r["case"]["kind"] == "paraboloid"]
    if paras:
        L += ["## Dual-paraboloid maps against the cube", "",
              "`omni=paraboloid` (`hard`, `pcf`; `wsoft.lightspace.paraboloid`): where the cube map is called for, two hemispherical "
              "parabolic maps of distances from the light's centre, drawn by one BVH ray per texel (a paraboloid bends triangles' edges, "
              "which a rasterizer draws straight), with a guard band past the equator of the kernel's width. Measured at the cube's size "
              "per side and at about the cube's texel count (size √3). Equator: penumbra MAE on pixels within the kernel's width (at "
              f"least {EDGE_TEXELS:g} texels) of the paraboloids' equator, and elsewhere. Depth ms: the cube's depth passes or the "
              "paraboloid's traced map.", "",
              "| frame | technique | views | size | texels | penumbra MAE | MAE | equator: MAE near / elsewhere | depth ms | frame ms |",
              "|---|---|---|---:|---:|---:|---:|---|---:|---:|"]
        for r in paras:
            for e in r["entries"]:
                s_ = e["seam"]
                eq = "" if not s_ else f"{s_['mae_edge']:.4f} / {s_['mae_elsewhere']:.4f} ({s_['edge_pixels']} px)"
                L.append(f"| {r['scene']}/{r['light'].split('/')[-1]} | {e['technique']} | {e['views']} | {e['params']['shadow_map_size']} | "
                         f"{e['texels']:,} | {e['error']['mae_penumbra']:.4f} | {e['error']['mae']:.4f} | {eq} | {e['depth_ms']:.1f} | "
                         f"{e['frame_ms']:.1f} |")
        L.append("")
        ratios = []
        for r in paras:
            for t in PARABOLOID_TECHS:
                cube_e = next((e for e in r["entries"] if e["technique"] == t and e["params"]["omni"] == "cube"), None)
                dp_e = next((e for e in r["entries"] if e["technique"] == t and e["params"]["omni"] == "paraboloid"
                             and e["params"]["shadow_map_size"] == r["map"]), None)
                if cube_e and dp_e and cube_e["views"].startswith("cube") and dp_e["views"].startswith("dual"):
                    ratios.append((f"{r['scene']}/{r['light'].split('/')[-1]} {t}", dp_e["depth_ms"] / cube_e["depth_ms"],
                                   dp_e["frame_ms"] / cube_e["frame_ms"],
                                   dp_e["error"]["mae_penumbra"] - cube_e["error"]["mae_penumbra"]))
        if ratios:
            L += ["At the cube's size per side, the dual-paraboloid map over the cube map (depth passes' time, frame time; penumbra MAE "
                  "difference): " + "; ".join(f"{k} {a:.1f}x, {b:.2f}x, {d:+.4f}" for k, a, b, d in ratios) + "." + (" Here the traced "
                  "hemispheres cost more than rasterizing the cube's faces on every frame, although they hold at most a third of its texels."
                  if all(a > 1.0 for _, a, _, _ in ratios) else ""), ""]
    if seams:
        r = seams[0]
        L += ["## Seams: guard bands against none", "",
              f"The ring of posts (`wsoft.stages.cube_cases.ring_stage`, {r['width']}x{r['height']}, {r['map']}² maps, cube=always), "
              "whose penumbrae cross face edges: penumbra MAE on pixels within 8 texels of a face edge and elsewhere, and how much V "
              "changes when the light's frame turns 30° (which moves the edges, not the shadows), near the edges and elsewhere.", "",
              "| technique | guard band | MAE near edges | MAE elsewhere | ΔV turned, near edges | ΔV turned, elsewhere | frame ms |",
              "|---|---|---:|---:|---:|---:|---:|"]
        for t in SEAM_TECHS:
            for g in ("technique", "none"):
                e = next((x for x in r["guards"][g] if x["technique"] == t), None)
                if e:
                    L.append(f"| {t} | {'its own' if g == 'technique' else 'none'} | {e['mae_edge']:.4f} | {e['mae_elsewhere']:.4f} | "
                             f"{e['turned_edge']:.4f} | {e['turned_elsewhere']:.4f} | {e['frame_ms']:.1f} |")
        L.append("")
    lookups = [r for r in rows if r["case"]["kind"] == "seam_lookup"]
    if lookups:
        r = lookups[0]
        L += ["## Seams: guard bands against a direction lookup", "",
              f"`pcf` on the same ring ({r['width']}x{r['height']}, {r['map']}² maps, cube=always): faces drawn with a guard band of the "
              "kernel's width, each tap read from its receiver's own face (`seams=guard`, the default), against faces drawn with the "
              "bilinear texel's band and each tap past a face's edge read from the face its direction belongs to, as a GPU's cube-map "
              "sampler does (`seams=lookup`, `wsoft.accel.cube_filter`). Near edges: penumbra pixels within the kernel's width (at "
              f"least {EDGE_TEXELS:g} texels) of a face edge. Guard: the band past each face's 90°, in tangents.", "",
              "| radius (texels) | seams | guard | MAE near edges | MAE elsewhere | ΔV turned, near edges | ΔV turned, elsewhere | "
              "depth ms | frame ms |",
              "|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
        for e in r["settings"]:
            L.append(f"| {e['radius']:g} | {e['seams']} | {e['guard']:.4f} | {e['mae_edge']:.4f} | {e['mae_elsewhere']:.4f} | "
                     f"{e['turned_edge']:.4f} | {e['turned_elsewhere']:.4f} | {e['depth_ms']:.1f} | {e['frame_ms']:.1f} |")
        by = {(e["radius"], e["seams"]): e for e in r["settings"]}
        said = []
        for rad in sorted({e["radius"] for e in r["settings"]}):
            g, k = by.get((rad, "guard")), by.get((rad, "lookup"))
            if g and k:
                said.append(f"radius {rad:g}: near-edge MAE {k['mae_edge']:.4f} against {g['mae_edge']:.4f}, frame time "
                            f"{k['frame_ms'] / g['frame_ms']:.2f}x the guard band's")
        if said:
            L += ["", "Direction lookup against guard bands: " + "; ".join(said) + ". The guard band keeps the filter on one map per "
                  "receiver; the lookup projects each tap's direction and reads the neighbouring face, and keeps every face's window "
                  "at the bilinear texel's band whatever the kernel."]
        L.append("")
    if spreads:
        L += ["## Where one frustum stops sufficing", "",
              "A sphere light over a field of posts, receivers seen out to θ off its axis (`wsoft.stages.cube_cases.spread_stage`): "
              "penumbra MAE and frame ms with one frustum (cube=never) and with a cube map (cube=always). `cube=auto` draws a cube map "
              f"beyond {CUBE_THRESHOLD_DEG:g}° (the grey line): short of the ±80° cap of one frustum's window, past the spread where "
              "one frustum stops being as accurate as the cube for every technique here.", ""]
        head = " | ".join(f"{t} frustum | {t} cube" for t in SPREAD_TECHS)
        L += [f"| θ | {head} |", "|---:|" + "---:|" * (2 * len(SPREAD_TECHS))]
        for r in sorted(spreads, key=lambda r: r["angle"]):
            cells = []
            for t in SPREAD_TECHS:
                for mode in ("never", "always"):
                    e = next(e for e in r["entries"] if e["technique"] == t and e["cube"] == mode)
                    cells.append(f"{e['error']['mae_penumbra']:.4f}, {e['frame_ms']:.0f} ms" + (f", {100 * e['outside']:.0f}% out" if e["outside"] else ""))
            L.append(f"| {r['angle']:g}° | " + " | ".join(cells) + " |")
        pic = _plot_spread(spreads, md, ctx)
        if pic:
            L += ["", f"![penumbra MAE against the receivers' spread]({pic})"]
        L.append("")
    md.write_text("\n".join(L) + "\n")
