"""``wsoft plan``: what a render of the stage would use (render settings, camera, lights, cutouts)
and the passes each technique would run; ``--json`` for the whole plan."""

from __future__ import annotations

import json

import wsoft.cli.args as a
from wsoft.cli.common import auto_args, auto_line, check_args


def add_parser(sub, one_of: str) -> None:
    p = sub.add_parser("plan", help="lights, cutouts and the passes each technique would run", formatter_class=a.Help)
    a.scene(p)
    p.add_argument("--technique", "-t", action="append", metavar="TECHNIQUE",
                   help="a technique whose passes to list (repeatable; default: all); " + one_of)
    a.light(p, "light path or name (default: every shadow-casting light)")
    a.camera(p)
    a.render_settings(p, "--camera overrides its camera")
    a.instancing(p)
    a.time(p)
    p.add_argument("--json", action="store_true", help="the plan as JSON")
    a.auto_options(p)
    a.subdiv(p)
    a.material_purpose(p)
    p.set_defaults(fn=run)


def run(args) -> int:
    techs = args.technique or None
    scene_file = check_args(args, techs or [])
    import wsoft
    from wsoft.pipeline import load_stage

    scene = load_stage(scene_file, time=args.time, render_settings=args.render_settings, instancing=args.instancing,
                       subdiv_level=args.subdiv_level,
                       material_purpose=args.material_purpose)
    auto = auto_args(args, "auto" if techs and "auto" in techs else None)
    p = wsoft.plan(scene, techs, light=args.light, camera=args.camera, auto=auto or None)
    if args.json:
        print(json.dumps(p, indent=2))
        return 0
    print(f"scene {p['scene']}: {p['triangles']} triangles, up {p['up_axis']}, {p['meters_per_unit']:g} m/unit"
          + (f", time code {p['time']:g}" if p["time"] is not None else ""))
    fr = p["framing"]
    print(f"render settings: {fr['render_settings']} (from {fr['render_settings_source']})" if fr["render_settings"] else
          "render settings: none (no --render-settings, no renderSettingsPrimPath metadata, none from GetStageRenderSettings)")
    print(f"camera: {fr['camera']} (from {fr['camera_source']}); {fr['resolution'][0]}x{fr['resolution'][1]} "
          f"(from {fr['resolution_source']}), pixel aspect {fr['pixel_aspect']:g}, {fr['conform_policy']}"
          + (f", data window {fr['data_window']}" if fr["data_window"] else ""))
    if fr["product"]:
        print(f"render product: {fr['product']}: V as {fr['visibility_var']!r}" + (f", default output {fr['product_name']}" if fr["product_name"] else ""))
    print(f"purposes loaded: {', '.join(p['purposes']) or '(none)'}")
    inst = p["instancing"]
    if inst["mode"] == "none":
        print("instancing: none (no instances kept: the stage has none, or it was flattened)")
    else:
        print(f"instancing: kept, {inst['instances']:,} instances of {inst['prototypes']} prototypes "
              f"({inst['prototype_triangles']:,} prototype triangles placed as {inst['instanced_triangles']:,}; "
              f"{inst['soup_triangles']:,} triangles not instanced)")
    for name, why in p.get("flattened_for", {}).items():
        print(f"{name}: renders the stage flattened ({why})")
    print("shadow-casting lights:" + ("" if p["lights"] else " (none)"))
    for l in p["lights"]:
        print(f"  {l['path']:<32} {l['kind']:<8} {l['size']}")
        em = l["emits"]
        toward = f"({', '.join(f'{c:.3g}' for c in em['direction'])})" if "direction" in em else ""
        if em["side"] == "shaped":
            print(f"      emits: in a cone of {em['cone']:g} degrees about {toward} (ShapingAPI: softness {em['softness']:g}, focus "
                  f"{em['focus']:g}, focusTint ({', '.join(f'{c:g}' for c in em['focus_tint'])})); receivers outside it are "
                  "masked out of its error metrics (reach.<light>)")
            if em.get("ies"):
                print(f"      IES profile: {em['ies']['file']} (angleScale {em['ies']['angle_scale']:g}, normalize "
                      f"{'on: over its mean intensity' if em['ies']['normalize'] else 'off: over its peak'}), times the cone")
        elif em["side"] == "front":
            print(f"      emits: from its front only, toward {toward}; {em['points_behind']} of {em['points']} mesh points lie behind "
                  f"its plane" + (" (they get none of its light: V = 0)" if em["points_behind"] else ""))
        else:
            print(f"      emits: {em['side']}" + (f" {toward}" if toward else ""))
        sh = l["shadow"]
        lk = sh["link"]
        print(f"      collection:shadowLink: {lk['excluded_prims']} of {lk['prims']} prims excluded"
              + (f" ({', '.join(lk['excluded'])}{', ...' if lk['excluded_prims'] > len(lk['excluded']) else ''}): {lk['applied']}" if lk["excluded_prims"] else ""))
        dist = "unlimited" if sh["distance"] is None else f"{sh['distance']:g} scene units: {sh['distance_applied']}"
        print(f"      shadow:distance: {dist}")
        print(f"      shadow:color: ({', '.join(f'{c:g}' for c in sh['color'])}): {sh['color_applied']}")
        print(f"      shadow:falloff: {sh['falloff']:g}, falloffGamma {sh['falloff_gamma']:g}: {sh['falloff_applied']}")
        if l["path"] in p.get("light_views", {}):
            print(f"      light views (shadow-map techniques, cube=auto): {p['light_views'][l['path']]}")
    print("lights skipped:" + ("" if p["skipped_lights"] else " (none)"))
    for l in p["skipped_lights"]:
        print(f"  {l['path']:<32} {l['kind']:<12} {l['reason']}")
    print("cutout (perforated) materials:" + ("" if p["cutout_materials"] else " (none)"))
    for m in p["cutout_materials"]:
        print(f"  {m['path']:<32} {m['triangles']} triangles")
    print(f"dynamic casters: {', '.join(p['dynamic_prims']) or '(none)'}")
    if p["skinned"]["meshes"]:
        print(f"skinned meshes (UsdSkel, posed at load: the stats' skin): {p['skinned']['meshes']}, {p['skinned']['skin_ms']:.1f} ms")
    print(f"triangles with baked light: {p['baked_light_triangles']}")
    for w in p["warnings"]:
        print(f"warning: {w}")
    for n in p["notes"]:
        print(f"note: {n}")
    for name, passes in p["techniques"].items():
        print(f"{name}: {' -> '.join(passes)}")
    for name, why in p["not_applicable"].items():
        for w in why:
            print(f"{name}: not applicable to {w['light']}: {w['reason']}")
    for name, models in p.get("cylinder_lights", {}).items():
        for m in models:
            print(f"{name}: cylinder light {m['light']}: {m['model']}")
    for light, choice in p.get("auto", {}).items():
        print_auto_plan(light, choice, len(p["auto"]))
    return 0


def print_auto_plan(light: str, a: dict, lights: int = 1) -> None:
    """``wsoft plan --technique auto``: a light's features, every candidate's predictions, the choice and the runner-up."""
    print(auto_line(light, a, lights))
    m = a["model"]
    print(f"  model: {m['path']} ({m.get('predicts', 'frame model')}; {m['device_kind']}; "
          + ", ".join(f"{q} by {v}" for q, v in m["method"].items())
          + (f"; times x {m['scale']:.3g}" if m["scale"] != 1.0 else "") + ")" + (f"; {m['note']}" if m["note"] else ""))
    print("  features: " + ", ".join(f"{k} {v:.4g}" for k, v in a["features"].items()))
    if a["warning"]:
        print(f"  warning: {a['warning']}")
    for t, why in a.get("not_candidates", {}).items():
        print(f"  {t}: {why}")
    num = lambda v, w: f"{v:>{w}.4f}" if v is not None else f"{'-':>{w}}"  # noqa: E731
    print(f"  {'candidate':<52} {'pred. ms':>9} {'ms bound':>9} {'pred. error':>11} {'error bound':>11} {'pred. ꟻLIP':>10} {'ꟻLIP bound':>10} "
          f"{'pred. flicker':>13} {'flicker bound':>13}")
    for c in a["candidates"]:
        mark = " <- choice" if c["setting"] == a["choice"]["setting"] else " <- runner-up" if a["runner_up"] and c["setting"] == a["runner_up"]["setting"] else ""
        print(f"  {c['setting']:<52} {c['predicted_ms']:>9.1f} {c['ms_bound']:>9.1f} {num(c.get('predicted_error'), 11)} {num(c.get('error_bound'), 11)} "
              f"{num(c.get('predicted_flip'), 10)} {num(c.get('flip_bound'), 10)} {num(c.get('predicted_flicker'), 13)} {num(c.get('flicker_bound'), 13)}{mark}")
