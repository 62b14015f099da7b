"""Sweep ``usd-pipeline``: wsoft in a USD pipeline (render settings, shadowLink, bakes), every number made here.

1. **Render settings** (UsdRender): a stage (:func:`wsoft.stages.pipeline.render_settings_stage`) the
   sweep saves (``<out>/<stem>/render_settings.usda``) with two cameras and a ``RenderSettings`` prim, named by the stage metadata
   ``renderSettingsPrimPath``, that picks the *second* camera at a non-default resolution with wide
   pixels (``pixelAspectRatio`` 4/3), ``cropAperture`` and a data window, and a product whose
   ``visibility`` RenderVar receives ``V``. It is rendered as ``wsoft render STAGE`` does (no width,
   height or camera given) and, for contrast, with the first camera asked for; the framing each
   used is the frame's ``stats["framing"]``.
2. **shadowLink** (UsdLux): a light over two blockers (:func:`wsoft.stages.pipeline.shadow_link_stage`),
   saved with and without a ``collection:shadowLink`` that excludes blocker B; ``pcss`` and ``reference`` images of both, and
   the mean V on the ground in the umbra of each blocker.
3. **Bake**: ``wsoft.bake`` of the bundled ``lightmapped_bridge`` (``reference`` and ``pcss``) into a
   layer file, composed with the stage as a sublayer in usd-core, its
   ``primvars:wsoft:visibility:<light>`` read back on every mesh (interpolation, element count, value
   range) and drawn on the meshes seen from the stage's camera: with pyvista offscreen (the ``viz``
   extra) when it renders here, else with matplotlib's 3-D polygons (the report says which).
4. **Bake time**: the bake of ``lightmapped_bridge`` per frame (3 frames over its time range; 1 in
   ``--quick``) for ``reference`` and ``pcss``: wall and CPU time from the bake's ``stats["frames"]``,
   after a warm-up bake that compiles the kernels.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from wsoft.stages.pipeline import (
    CAM_APERTURE,
    CONFORM,
    DATA_WINDOW,
    LINK_BLOCKER_Z,
    LINK_BLOCKERS,
    LINK_HALF,
    LINK_LIGHT_Z,
    PIXEL_ASPECT,
    RS_PRIM,
    render_settings_stage,
    shadow_link_stage,
)

BRIDGE = "lightmapped_bridge"
UMBRA_HALF = 0.2  # ground pixels within this of a blocker's umbra centre (the umbra's half side is 0.35)

REPORT = "usd_pipeline"  # its files: reports/usd_pipeline.md and .jsonl, the images and stages in reports/usd_pipeline/


def _quality(technique: str, quick: bool) -> dict:
    if technique == "reference":
        return {"samples": 16 if quick else 256}
    return {"shadow_map_size": 512 if quick else 1024}


def cases(quick: bool, devices: list[str]) -> list[dict]:
    out = []
    for dev in devices:
        out.append({"kind": "render_settings", "device": dev, "technique": "pcss", "params": _quality("pcss", quick),
                    "resolution": [192, 108] if quick else [400, 225]})
        for tech in ("pcss", "reference"):
            out.append({"kind": "shadow_link", "device": dev, "technique": tech, "params": _quality(tech, quick),
                        "width": 160 if quick else 320, "height": 120 if quick else 240})
        for tech in ("reference", "pcss"):
            out.append({"kind": "bake", "device": dev, "scene": BRIDGE, "technique": tech, "params": _quality(tech, quick), "frame": 24,
                        "lights": ["Sun"] if quick else ["Sun", "Torch"], "picture": [280, 210] if quick else [560, 420]})
        for tech in ("reference", "pcss"):
            out.append({"kind": "bake_time", "device": dev, "scene": BRIDGE, "technique": tech, "params": _quality(tech, quick),
                        "frames": "1" if quick else "1:48:23"})
    return out


def run_case(case: dict, ctx: dict) -> dict:
    folder = Path(ctx["out_dir"]) / ctx["stem"]
    folder.mkdir(parents=True, exist_ok=True)
    run = {"render_settings": _render_settings, "shadow_link": _shadow_link, "bake": _bake, "bake_time": _bake_time}[case["kind"]]
    row = run(case, folder, ctx["stem"])
    row.update(kind=case["kind"], technique=case["technique"], params=case["params"], device=case["device"])
    return row


def _tag(case: dict) -> str:
    dev = case["device"].replace(":", "")
    return case["technique"] + ("" if dev == "cpu" else f"-{dev}")


# -- 1. render settings ----------------------------------------------------------------------------


def _fov(tan_half) -> list[float]:
    return [round(math.degrees(2 * math.atan(t)), 2) for t in tan_half]


def _render_settings(case: dict, folder: Path, stem: str) -> dict:
    import wsoft
    from PIL import Image

    from wsoft.pipeline import frame_setup

    stage = folder / "render_settings.usda"
    built = render_settings_stage(case["resolution"])  # held: the layer lives as long as its stage
    built.GetRootLayer().Export(str(stage))
    scene = wsoft.load_scene(str(stage))
    renders = []
    for label, camera in (("settings", None), ("first camera", "/World/Cam1")):
        fr = wsoft.render(str(stage), case["technique"], camera=camera, device=case["device"], **case["params"])  # width, height: from the settings
        fm = fr.stats["framing"]
        name = f"rs_{'settings' if camera is None else 'cam1'}_{_tag(case)}"
        fr.write_png(str(folder / f"{name}.png"))  # as `wsoft render --png` writes it: the data window's pixels, as they are
        h, w = fr.V.shape
        Image.open(folder / f"{name}.png").resize((round(w * fm["pixel_aspect"]), h), Image.LANCZOS).save(folder / f"{name}_display.png")
        own = next(c for c in scene.cameras if c.path == fm["camera"])
        conformed = frame_setup(scene, None, None, camera).camera
        renders.append({
            "label": label, "camera_flag": camera, "framing": fm, "image": f"{stem}/{name}.png", "display_image": f"{stem}/{name}_display.png",
            "written": [w, h], "exr_names": dict(fr.exr_names), "ms": fr.stats["timings_ms"]["total"],
            "fov_camera": _fov(own.tan_half), "fov_conformed": _fov(conformed.tan_half), "warnings": fr.stats["warnings"],
        })
    return {"scene": f"{stem}/render_settings.usda", "stage": f"{stem}/render_settings.usda", "renders": renders,
            "authored": {"resolution": case["resolution"], "pixel_aspect": PIXEL_ASPECT, "conform_policy": CONFORM,
                         "data_window": list(DATA_WINDOW), "camera": "/World/Cam2", "aperture_mm": list(CAM_APERTURE)}}


# -- 2. shadowLink -----------------------------------------------------------------------------------


def _shadow_link(case: dict, folder: Path, stem: str) -> dict:
    import wsoft
    from pxr import Usd, UsdLux

    from wsoft.pipeline import shadow_controls

    out = {"scene": f"{stem}/shadow_link.usda", "width": case["width"], "height": case["height"], "variants": []}
    for exclude in (False, True):
        stage = folder / ("shadow_link.usda" if exclude else "shadow_link_none.usda")
        built = shadow_link_stage(exclude)  # held: the layer lives as long as its stage
        built.GetRootLayer().Export(str(stage))
        usd = Usd.Stage.Open(str(stage))
        query = UsdLux.LightAPI(usd.GetPrimAtPath("/World/Light")).GetShadowLinkCollectionAPI().ComputeMembershipQuery()
        scene = wsoft.load_scene(str(stage))
        fr = wsoft.render(scene, case["technique"], width=case["width"], height=case["height"], device=case["device"], **case["params"])
        ground = (fr["A"] > 0) & (np.abs(fr["P.Z"]) < 1e-3)
        under = {}
        for name, x in LINK_BLOCKERS.items():
            c = x * LINK_LIGHT_Z / (LINK_LIGHT_Z - LINK_BLOCKER_Z)  # the umbra's centre on the ground
            sel = ground & (np.abs(fr["P.X"] - c) < UMBRA_HALF) & (np.abs(fr["P.Y"]) < UMBRA_HALF)
            under[name] = {"mean_V": float(fr.V[sel].mean()) if sel.any() else None, "pixels": int(sel.sum()), "umbra_x": c,
                           "usd_member": bool(query.IsPathIncluded(f"/World/Blocker{name}"))}
        name = f"link_{'excluded' if exclude else 'none'}_{_tag(case)}.png"
        _link_png(fr, folder / name)
        out["variants"].append({"exclude": ["/World/BlockerB"] if exclude else [], "stage": f"{stem}/{stage.name}", "image": f"{stem}/{name}",
                                "under": under, "link": shadow_controls(scene, scene.lights[0])["link"],
                                "ms": fr.stats["timings_ms"]["total"], "warnings": fr.stats["warnings"]})
    return out


def _link_png(fr, path: Path) -> None:
    """V as linear grey on the ground; the blockers (above the ground) tinted blue by their own V;
    no surface: dark grey."""
    from PIL import Image

    v = np.clip(fr.V, 0, 1)[..., None]
    rgb = np.repeat(v, 3, -1)
    blocker = (fr["A"] > 0) & (fr["P.Z"] > 0.5 * LINK_BLOCKER_Z)
    rgb[blocker] = np.array([0.3, 0.5, 0.95]) * (0.4 + 0.6 * v[blocker])
    rgb[fr["A"] <= 0] = 0.2
    Image.fromarray((rgb * 255 + 0.5).astype(np.uint8), "RGB").save(path)


# -- 3. bake, compose, read back, draw ---------------------------------------------------------------


def _bake(case: dict, folder: Path, stem: str) -> dict:
    import wsoft
    from pxr import Sdf, Usd, UsdGeom

    from wsoft.bench.harness import scene_file

    src = scene_file(case["scene"])
    t = float(case["frame"])
    tc = Usd.TimeCode(t)
    with tempfile.TemporaryDirectory() as tmp:
        layer_file = os.path.join(tmp, f"bridge_visibility_{case['technique']}.usda")
        stats: dict = {}
        t0 = time.perf_counter()
        wsoft.bake(src, case["technique"], frames=f"{case['frame']:g}", out=layer_file, device=case["device"], stats=stats, **case["params"])
        bake_s = time.perf_counter() - t0
        layer_bytes = os.path.getsize(layer_file)
        # compose: a root layer whose sublayers are the baked layer (stronger) and the stage
        root = Sdf.Layer.CreateAnonymous("composed.usda")
        root.subLayerPaths = [layer_file, src]
        stage = Usd.Stage.Open(root)
        lights = dict(stats["lights"])  # light path -> primvar identifier
        xf = UsdGeom.XformCache(tc)
        meshes, geometry = [], []
        for prim in stage.Traverse():
            if not prim.IsA(UsdGeom.Mesh):
                continue
            mesh = UsdGeom.Mesh(prim)
            pts = np.asarray(mesh.GetPointsAttr().Get(tc), dtype=np.float64)
            counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(tc), dtype=np.int64)
            idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(tc), dtype=np.int64)
            M = np.array(xf.GetLocalToWorldTransform(prim), dtype=np.float64)
            world = pts @ M[:3, :3] + M[3, :3]  # USD's row-vector convention
            entry = {"path": str(prim.GetPath()), "points": len(pts), "face_corners": len(idx), "primvars": {}}
            corner_values = {}
            for path, ident in lights.items():
                pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar(f"wsoft:visibility:{ident}")
                if not pv:
                    continue
                vals = np.asarray(pv.Get(tc), dtype=np.float64)
                interp = pv.GetInterpolation()
                entry["primvars"][ident] = {
                    "name": pv.GetPrimvarName(), "type": str(pv.GetTypeName()), "interpolation": interp, "elements": len(vals),
                    "time_samples": list(pv.GetAttr().GetTimeSamples()), "min": float(vals.min()), "mean": float(vals.mean()),
                    "max": float(vals.max()),
                    "layer": Path(pv.GetAttr().GetPropertyStack(tc)[0].layer.identifier).name,  # the strongest opinion's layer
                }
                if interp == "vertex" and len(vals) == len(pts):
                    corner_values[ident] = vals[idx]
                elif interp == "faceVarying" and len(vals) == len(idx):
                    corner_values[ident] = vals
            meshes.append(entry)
            keep = counts >= 3
            if corner_values and keep.all():
                geometry.append((world[idx], counts, corner_values))
    view = _look_at(PICTURE_EYE, PICTURE_TARGET, PICTURE_FOV)
    pictures = []
    for ident in case["lights"]:
        parts = [g for g in geometry if ident in g[2]]
        if not parts:
            continue
        P = np.concatenate([g[0] for g in parts])
        sizes = np.concatenate([g[1] for g in parts])
        values = np.concatenate([g[2][ident] for g in parts])
        name = f"bake_{_tag(case)}_{ident}.png"
        title = f"primvars:wsoft:visibility:{ident} ({case['technique']}, time {t:g})"
        renderer = _picture(P, sizes, values, view, folder / name, tuple(case["picture"]), title)
        pictures.append({"light": ident, "image": f"{stem}/{name}", "renderer": renderer})
    return {"scene": case["scene"], "frame": t, "lights": lights, "meshes": meshes, "pictures": pictures, "layer_bytes": layer_bytes,
            "bake_seconds": round(bake_s, 3), "bake_frames": stats["frames"], "warnings": stats["warnings"],
            "interpolations": {m: v["interpolation"] for m, v in stats["meshes"].items()}, "camera": view}


PICTURE_EYE, PICTURE_TARGET, PICTURE_FOV = (-9.0, -16.0, 12.0), (0.5, 0.0, 1.5), 38.0  # above the bridge's south-west end


def _look_at(eye, target, fov_vertical: float) -> dict:
    eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
    d = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(d, (0.0, 0.0, 1.0))
    up = np.cross(right / np.linalg.norm(right), d)
    return {"position": eye.tolist(), "direction": d.tolist(), "up": up.tolist(), "fov_vertical": fov_vertical}


_PYVISTA = r"""
import json, sys
import numpy as np
import pyvista as pv
pv.OFF_SCREEN = True
z = np.load(sys.argv[1])
P, sizes, values = z["points"], z["sizes"], z["values"]
spec = json.loads(str(z["spec"]))
starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
faces = np.concatenate([np.concatenate([[n], np.arange(s, s + n)]) for s, n in zip(starts, sizes)])
mesh = pv.PolyData(P, faces)
mesh.point_data["V"] = values
p = pv.Plotter(off_screen=True, window_size=spec["size"])
p.set_background("white")
p.add_mesh(mesh, scalars="V", cmap="inferno", clim=[0.0, 1.0], lighting=False,
           scalar_bar_args={"title": spec["bar"], "color": "black", "fmt": "%.1f", "vertical": True, "n_labels": 3,
                            "position_x": 0.88, "position_y": 0.2, "width": 0.05, "height": 0.6, "label_font_size": 12, "title_font_size": 12})
p.add_text(spec["title"], font_size=8, color="black")
c = spec["camera"]
pos = np.array(c["position"])
p.camera.position = tuple(pos)
p.camera.focal_point = tuple(pos + 10.0 * np.array(c["direction"]))
p.camera.up = tuple(c["up"])
p.camera.view_angle = c["fov_vertical"]
p.camera.clipping_range = (0.05, 200.0)
p.screenshot(spec["out"])
window = type(p.ren_win).__name__ if getattr(p, "ren_win", None) is not None else "?"
p.close()
import vtk
print(json.dumps({"pyvista": pv.__version__, "vtk": vtk.vtkVersion.GetVTKVersion(), "window": window}))
"""


def _picture(P, sizes, values, view, path: Path, size, title) -> dict:
    """The meshes coloured by the primvar (interpolated over each face from its corners): pyvista
    offscreen in a child process (a crash of the GL stack cannot take the sweep down), else
    matplotlib. Returns which drew it and why."""
    import importlib.util

    why = "pyvista is not installed (the `viz` extra)"
    if importlib.util.find_spec("pyvista") is not None:
        with tempfile.TemporaryDirectory() as tmp:
            npz = os.path.join(tmp, "mesh.npz")
            spec = {"size": list(size), "camera": view, "title": title, "bar": "V", "out": str(path)}
            np.savez(npz, points=P.astype(np.float32), sizes=sizes.astype(np.int64), values=values.astype(np.float32), spec=json.dumps(spec))
            try:
                p = subprocess.run([sys.executable, "-c", _PYVISTA, npz], capture_output=True, text=True, timeout=300)
                info = json.loads(p.stdout.strip().splitlines()[-1]) if p.returncode == 0 and p.stdout.strip() else None
            except (subprocess.TimeoutExpired, json.JSONDecodeError) as exc:
                p, info = None, None
                why = f"pyvista failed: {type(exc).__name__}"
            if info is not None and path.exists() and _not_blank(path):
                return {"renderer": "pyvista", **info}
            if p is not None:
                tail = " ".join((p.stderr or "").strip().splitlines()[-1:])[:200]
                why = f"pyvista could not render offscreen (exit {p.returncode}{': ' + tail if tail else ''})" if p.returncode else \
                    "pyvista rendered a blank picture"
    _matplotlib_picture(P, sizes, values, view, path, size, title)
    import matplotlib

    return {"renderer": "matplotlib", "matplotlib": matplotlib.__version__, "why": why}


def _not_blank(path: Path) -> bool:
    from PIL import Image

    a = np.asarray(Image.open(path).convert("L"), dtype=np.float64)
    return a.std() > 2.0


def _matplotlib_picture(P, sizes, values, view, path: Path, size, title) -> None:
    """The fallback: one flat colour per face (the mean of its corners), matplotlib's painter's
    sort, perspective, looking along the view's direction at the faces its frustum holds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    face_v = np.add.reduceat(values, starts) / sizes
    centroid = np.add.reduceat(P, starts, axis=0) / sizes[:, None]
    pos, d, up = (np.asarray(view[k], dtype=np.float64) for k in ("position", "direction", "up"))
    right = np.cross(d, up)
    rel = centroid - pos
    depth = rel @ d
    th = math.tan(math.radians(view["fov_vertical"]) / 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = (depth > 0) & (np.abs(rel @ up) < 1.05 * th * depth) & (np.abs(rel @ right) < 1.05 * th * size[0] / size[1] * depth)
    if not inside.any():
        inside[:] = True
    keep = np.nonzero(inside)[0]
    polys = [P[starts[i]:starts[i] + sizes[i]] for i in keep]
    cmap = plt.get_cmap("inferno")
    fig = plt.figure(figsize=(size[0] / 100, size[1] / 100), dpi=100)
    ax = fig.add_axes((0.0, 0.0, 0.82, 0.93), projection="3d", proj_type="persp", focal_length=1 / th)
    ax.add_collection3d(Poly3DCollection(polys, facecolors=cmap(np.clip(face_v[keep], 0, 1)), edgecolors="none"))
    ax.view_init(elev=math.degrees(math.asin(max(-1.0, min(1.0, -d[2])))), azim=math.degrees(math.atan2(-d[1], -d[0])))
    pts = np.concatenate(polys)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    ax.set_xlim(lo[0], hi[0]), ax.set_ylim(lo[1], hi[1]), ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-3 * (hi - lo).max()), zoom=1.4)
    ax.set_axis_off()
    cax = fig.add_axes((0.84, 0.2, 0.025, 0.6))
    fig.colorbar(plt.cm.ScalarMappable(cmap=cmap, norm=matplotlib.colors.Normalize(0, 1)), cax=cax, label="V")
    fig.text(0.01, 0.96, title, fontsize=7)
    with np.errstate(over="ignore"):  # mplot3d's margin arithmetic overflows harmlessly on its unset data limits
        fig.savefig(path, dpi=100)
    plt.close(fig)


# -- 4. bake time ----------------------------------------------------------------------------------------


FRAME_KEYS = ("time", "points", "total_ms", "cpu_ms", "technique_ms", "technique_cpu_ms", "load_ms", "points_ms", "write_ms", "compile_ms")


def _bake_time(case: dict, folder: Path, stem: str) -> dict:
    import wsoft

    from wsoft.bench.harness import scene_file

    src = scene_file(case["scene"])
    first = case["frames"].split(":")[0]
    warm: dict = {}
    wsoft.bake(src, case["technique"], frames=first, device=case["device"], stats=warm, **case["params"])  # compiles the kernels
    stats: dict = {}
    load = os.getloadavg()
    t0 = time.perf_counter()
    wsoft.bake(src, case["technique"], frames=case["frames"], device=case["device"], stats=stats, **case["params"])
    return {"scene": case["scene"], "frames_arg": case["frames"], "frames": [{k: f[k] for k in FRAME_KEYS} for f in stats["frames"]],
            "bake_seconds": round(time.perf_counter() - t0, 3), "warmup_compile_ms": warm["frames"][0]["compile_ms"],
            "loadavg": [round(x, 2) for x in load], "warnings": stats["warnings"]}


# -- the report ------------------------------------------------------------------------------------------


def _ptxt(p: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in p.items())


def _img(rel: str, alt: str) -> str:
    return f"![{alt}]({rel})"


def _section_settings(rows: list[dict]) -> list[str]:
    L = ["## 1. Render settings (UsdRender)", ""]
    for r in rows:
        a = r["authored"]
        L += [f"Stage: [`{r['stage']}`]({r['stage']}) (built by the sweep; open it in usdview or `wsoft plan {r['stage']}`). It has two "
              f"cameras (`/World/Cam1`, `/World/Cam2`, apertures {a['aperture_mm'][0]:g} x {a['aperture_mm'][1]:g} mm) and `{RS_PRIM}`, "
              f"named by the stage metadata `renderSettingsPrimPath`, authoring: camera `{a['camera']}`, resolution "
              f"{a['resolution'][0]} x {a['resolution'][1]}, `pixelAspectRatio` {a['pixel_aspect']:.4g}, `aspectRatioConformPolicy` "
              f"`{a['conform_policy']}`, `dataWindowNDC` ({', '.join(f'{x:g}' for x in a['data_window'])}), and a product "
              "`/Render/Products/shadowPass` (`productName` `shadow_pass.exr`) whose RenderVar `shadowVis` has `sourceName = \"visibility\"`.",
              "",
              f"Rendered with `{r['technique']}` ({_ptxt(r['params'])}) on {r['device']} through the Python API as `wsoft render STAGE` "
              "does: `wsoft.render(STAGE, technique)` with no width, height or camera (row `settings`); and with the first camera asked for, "
              "`camera=\"/World/Cam1\"` (`--camera /World/Cam1`, row `first camera`). Every column is the frame's `stats[\"framing\"]`, "
              "except the written size (the frame's `V`), the field of view (the camera's own, then conformed to the image by "
              "`frame_setup`, the function the render calls) and the EXR channel `V` is written as (`frame.exr_names`).", "",
              "| render | settings prim (source) | camera (source) | resolution (source) | pixel aspect | conform policy | data window (px) | "
              "written image | FOV h x v, camera's → conformed (°) | product / `V` written as | frame ms |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
        for x in r["renders"]:
            f = x["framing"]
            dw = f"{f['data_window']}" if f["data_window"] else "whole"
            L.append(f"| {x['label']} | `{f['render_settings']}` ({f['render_settings_source']}) | `{f['camera']}` ({f['camera_source']}) | "
                     f"{f['resolution'][0]} x {f['resolution'][1]} ({f['resolution_source']}) | {f['pixel_aspect']:.4g} | `{f['conform_policy']}` | "
                     f"{dw} | {x['written'][0]} x {x['written'][1]} | {x['fov_camera'][0]:g} x {x['fov_camera'][1]:g} → "
                     f"{x['fov_conformed'][0]:g} x {x['fov_conformed'][1]:g} | `{f['product']}` / `{x['exr_names'].get('V', 'V')}` | {x['ms']:.0f} |")
        L += ["", "Images: the PNG as `wsoft render --png` writes it (the data window's pixels, one per pixel), and the same stretched "
              "by the pixel aspect for viewing on a square-pixel screen.", "",
              "| render | PNG as written | shown with its pixel aspect |", "|---|---|---|"]
        for x in r["renders"]:
            L.append(f"| {x['label']} (`{x['framing']['camera']}`) | {_img(x['image'], x['label'])} | {_img(x['display_image'], x['label'])} |")
        warns = sorted({w for x in r["renders"] for w in x["warnings"]})
        if warns:
            L += ["", "Warnings: " + "; ".join(warns)]
        L.append("")
    return L


def _section_link(rows: list[dict]) -> list[str]:
    L = ["## 2. `collection:shadowLink` (UsdLux)", ""]
    if not rows:
        return L
    v0 = rows[0]
    stages = ", ".join(f"[`{v['stage']}`]({v['stage']})" for v in v0["variants"])
    L += [f"Stages: {stages} (built by the sweep): a ground, blocker A at x = {LINK_BLOCKERS['A']:g} and blocker B at "
          f"x = {LINK_BLOCKERS['B']:g} (squares of side {2 * LINK_HALF:g} at height {LINK_BLOCKER_Z:g}) under a 1 x 1 RectLight at height "
          f"{LINK_LIGHT_Z:g}; the second stage's light authors `collection:shadowLink` excluding `/World/BlockerB`. "
          f"`mean V under X`: the mean V of the ground pixels within {UMBRA_HALF:g} (x and y) of the centre of X's umbra on the ground "
          "(exact umbra: V = 0 there); `USD member`: `ComputeMembershipQuery().IsPathIncluded` of the light's shadowLink collection; "
          "`casting triangles`: what wsoft's loader keeps as the light's casters. Images: V, linear grey on the ground, the blockers tinted blue (A on the left), "
          f"{v0['width']} x {v0['height']}.", "",
          "| technique | shadowLink excludes | USD member A / B | casting triangles | mean V under A (pixels) | mean V under B (pixels) | frame ms |",
          "|---|---|---|---|---|---|---|"]
    for r in rows:
        for v in r["variants"]:
            a, b = v["under"]["A"], v["under"]["B"]

            def mv(x):
                return "n/a" if x["mean_V"] is None else f"{x['mean_V']:.4f} ({x['pixels']})"

            L.append(f"| {r['technique']} ({_ptxt(r['params'])}) | {', '.join(f'`{p}`' for p in v['exclude']) or 'nothing'} | "
                     f"{'yes' if a['usd_member'] else 'no'} / {'yes' if b['usd_member'] else 'no'} | {v['link']['casting_triangles']} | "
                     f"{mv(a)} | {mv(b)} | {v['ms']:.0f} |")
    L += ["", "| technique | without the exclusion | with `/World/BlockerB` excluded |", "|---|---|---|"]
    for r in rows:
        imgs = {bool(v["exclude"]): v["image"] for v in r["variants"]}
        L.append(f"| {r['technique']} | {_img(imgs[False], 'no exclusion')} | {_img(imgs[True], 'B excluded')} |")
    warns = sorted({w for r in rows for v in r["variants"] for w in v["warnings"]})
    if warns:
        L += ["", "Warnings: " + "; ".join(warns)]
    L.append("")
    return L


def _section_bake(rows: list[dict]) -> list[str]:
    L = ["## 3. Bake into USD, compose, read back", ""]
    if not rows:
        return L
    r0 = rows[0]
    lights = ", ".join(f"`{p}` → `primvars:wsoft:visibility:{i}`" for p, i in r0["lights"].items())
    L += [f"`wsoft.bake(\"{r0['scene']}\", technique, frames=\"{r0['frame']:g}\", out=LAYER)` wrote a layer of `over`s (to a temporary "
          "file, not kept: `wsoft bake lightmapped_bridge -t reference --frames 24 --out vis.usda` makes it again); the sweep then "
          "composed it in usd-core as a sublayer, stronger than the stage (an anonymous root layer with `subLayerPaths = [LAYER, "
          f"lightmapped_bridge.usda]`), and read every mesh's primvars back with `UsdGeom.PrimvarsAPI` at time {r0['frame']:g}. "
          f"Lights: {lights}.", ""]
    L += ["| technique | params | layer size | bake s (1 frame, compiling included) | primvars read back | warnings |", "|---|---|---|---|---|---|"]
    for r in rows:
        n = sum(len(m["primvars"]) for m in r["meshes"])
        layers = sorted({pv["layer"] for m in r["meshes"] for pv in m["primvars"].values()})
        L.append(f"| {r['technique']} | {_ptxt(r['params'])} | {r['layer_bytes'] / 1024:.0f} KiB | {r['bake_seconds']:.2f} | "
                 f"{n} on {sum(1 for m in r['meshes'] if m['primvars'])} meshes (opinion from {', '.join(f'`{x}`' for x in layers)}) | "
                 f"{len(r['warnings'])} |")
    # per mesh: interpolation, elements and value range, each technique and light
    idents = list(r0["lights"].values())
    head = "| mesh | interpolation | elements (points / face corners) | " + " | ".join(
        f"{r['technique']} {i} min / mean / max" for r in rows for i in idents) + " |"
    types = sorted({pv["type"] for r in rows for m in r["meshes"] for pv in m["primvars"].values()})
    samples = sorted({len(pv["time_samples"]) for r in rows for m in r["meshes"] for pv in m["primvars"].values()})
    L += ["", f"Read back at time {r0['frame']:g} (type {', '.join(f'`{t}`' for t in types)}; time samples per primvar: "
          f"{', '.join(str(n) for n in samples)}):", "", head, "|---|---|---|" + "---|" * (len(rows) * len(idents))]
    for i, m in enumerate(r0["meshes"]):
        pvs = m["primvars"]
        if not pvs:
            L.append(f"| `{m['path']}` | not baked | {m['points']} / {m['face_corners']} |" + " |" * (len(rows) * len(idents)))
            continue
        first = next(iter(pvs.values()))
        cells = []
        for r in rows:
            mm = next((x for x in r["meshes"] if x["path"] == m["path"]), {"primvars": {}})
            for ident in idents:
                pv = mm["primvars"].get(ident)
                cells.append("" if pv is None else f"{pv['min']:.3f} / {pv['mean']:.3f} / {pv['max']:.3f}")
        L.append(f"| `{m['path']}` | {first['interpolation']} | {first['elements']} ({m['points']} / {m['face_corners']}) | " + " | ".join(cells) + " |")
    errs = [f"{r['technique']} {m['path']} {i}" for r in rows for m in r["meshes"] for i, pv in m["primvars"].items()
            if pv["elements"] != (m["points"] if pv["interpolation"] == "vertex" else m["face_corners"])]
    L += ["", "Element count against the interpolation (vertex: one per point, faceVarying: one per face corner): "
          + ("all match." if not errs else "mismatch on " + ", ".join(errs) + ".")]
    pics = [(r, p) for r in rows for p in r["pictures"]]
    if pics:
        used = sorted({p["renderer"]["renderer"] for _, p in pics})
        L += ["", "### Pictures", ""]
        if "pyvista" in used:
            info = next(p["renderer"] for _, p in pics if p["renderer"]["renderer"] == "pyvista")
            L.append(f"Drawn offscreen with pyvista {info['pyvista']} (VTK {info['vtk']}, render window `{info['window']}`), the `viz` "
                     "extra: every mesh at the baked time, each face coloured from its corners' primvar values (faceVarying as they are, "
                     "vertex through the face-vertex indices), no lighting, seen from "
                     f"({', '.join(f'{x:g}' for x in PICTURE_EYE)}) towards ({', '.join(f'{x:g}' for x in PICTURE_TARGET)}).")
        if "matplotlib" in used:
            info = next(p["renderer"] for _, p in pics if p["renderer"]["renderer"] == "matplotlib")
            L.append(f"Drawn with matplotlib {info['matplotlib']}'s 3-D polygons, a fallback: {info['why']}. The report uses pyvista "
                     "offscreen (`pip install '.[viz]'`) when it is installed and renders here; matplotlib colours each face flat with "
                     "the mean of its corners' values, seen from the same point.")
        L += ["", "| technique | " + " | ".join(idents) + " |", "|---|" + "---|" * len(idents)]
        for r in rows:
            by = {p["light"]: p["image"] for p in r["pictures"]}
            L.append(f"| {r['technique']} | " + " | ".join(_img(by[i], f"{r['technique']} {i}") if i in by else "" for i in idents) + " |")
    warns = sorted({f"{r['technique']}: {w}" for r in rows for w in r["warnings"]})
    if warns:
        L += ["", "Bake warnings:", ""] + [f"* {w}" for w in warns]
    L.append("")
    return L


def _section_time(rows: list[dict], machine: dict) -> list[str]:
    L = ["## 4. Bake time per frame", ""]
    if not rows:
        return L
    L += [f"`wsoft.bake(\"{rows[0]['scene']}\", technique, frames=\"{rows[0]['frames_arg']}\")` into an anonymous layer (no file written), "
          "after a warm-up bake of the first frame that compiles the kernels; per frame from the bake's `stats[\"frames\"]`: `wall ms` "
          "(`total_ms`: loading the stage at that time, building the bake points, the technique's passes, writing the primvars; kernel "
          "compilation apart), `CPU ms` (`cpu_ms`: the process's CPU time over the frame, every thread), and the technique's passes alone "
          f"(`technique_ms` / `technique_cpu_ms`). Machine: {machine.get('cpu', '?')}, {machine.get('threads', '?')} CPU threads for Warp "
          f"launches ({machine.get('cores', '?')} cores), Python {machine.get('python', '?')}; one run per frame, on a machine others may "
          "load (`load avg` at the start: 1, 5, 15 min).", "",
          "| technique | params | device | time code | bake points | wall ms | CPU ms | CPU / wall | passes ms | passes CPU ms | load ms | points ms | write ms | load avg |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        for f in r["frames"]:
            L.append(f"| {r['technique']} | {_ptxt(r['params'])} | {r['device']} | {f['time']:g} | {f['points']} | {f['total_ms']:.1f} | "
                     f"{f['cpu_ms']:.1f} | {f['cpu_ms'] / max(f['total_ms'], 1e-9):.2f} | {f['technique_ms']:.1f} | {f['technique_cpu_ms']:.1f} | "
                     f"{f['load_ms']:.1f} | {f['points_ms']:.1f} | {f['write_ms']:.1f} | {', '.join(f'{x:g}' for x in r['loadavg'])} |")
    L += ["", "| technique | frames | mean wall ms / frame | mean CPU ms / frame | warm-up compile ms |", "|---|---|---|---|---|"]
    for r in rows:
        fr = r["frames"]
        L.append(f"| {r['technique']} | {len(fr)} | {np.mean([f['total_ms'] for f in fr]):.1f} | {np.mean([f['cpu_ms'] for f in fr]):.1f} | "
                 f"{r['warmup_compile_ms']:.0f} |")
    L.append("")
    return L


def report(rows: list[dict], md: Path, ctx: dict) -> None:
    from wsoft.bench.common import report_header

    L = [line for line in report_header("usd-pipeline", rows, md, ctx)
         if not line.startswith(("Error is against", "penumbra =", "Times:", "Rows:"))]
    L.append(f"Rows: {len(rows)}; every number below is read from them. Images, stages and the rows' files lie beside this report "
             f"(`{ctx['stem']}/`).")
    L += ["", "The USD pipeline, end to end: a stage's own render settings choose the camera and framing; a light's shadowLink "
          "decides who casts its shadow; `wsoft bake` writes visibility back into USD as primvars that usd-core composes and reads; "
          "and what a bake costs per frame.", ""]
    machine = rows[0]["machine"] if rows else {}
    by = lambda k: [r for r in rows if r.get("kind") == k]  # noqa: E731
    L += _section_settings(by("render_settings"))
    L += _section_link(by("shadow_link"))
    L += _section_bake(by("bake"))
    L += _section_time(by("bake_time"), machine)
    md.write_text("\n".join(L) + "\n")
