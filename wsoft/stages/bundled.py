"""The bundled stages (``wsoft.usd_scenes``) and the command that regenerates them.

Usage::

    python -m wsoft.stages.bundled [--out DIR] [NAME ...]

NAME is a scene of :data:`SCENES` (a file name with its extension is accepted too); without one,
every scene is written. The default folder is the one ``wsoft.usd_scenes`` reads. Every run with
the same arguments writes byte-identical files: all randomness uses fixed seeds and nothing
time-dependent is written. Only pxr (usd-core), numpy and Pillow are used.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence

from wsoft.stages.scenes import animated, basics, bridge, character, city, forest, interiors, lights, open_world, organic, stsv, tower, tunnel_fan
from wsoft.usd_scenes import folder as bundled_folder

# name -> generator(out_dir) -> {"file": path, "triangles": n, ...}
SCENES: dict[str, Callable[[str], dict[str, object]]] = {
    "box_plane": basics.scene_box_plane,
    "contact": basics.scene_contact,
    "multi_light": basics.scene_multi_light,
    "cutout": basics.scene_cutout,
    "city": city.scene_city,
    "penumbra_ramp": basics.scene_penumbra_ramp,
    "lightmapped_bridge": bridge.scene_lightmapped_bridge,
    "tower": tower.scene_tower,
    "tunnel_fan": tunnel_fan.scene_tunnel_fan,
    "room_lamp": interiors.scene_room_lamp,
    "corridor_torch": interiors.scene_corridor_torch,
    "forest": forest.scene_forest,
    "ogre": organic.scene_ogre,
    "plants": organic.scene_plants,
    "dinosaurs": organic.scene_dinosaurs,
    "fig1_plant": organic.scene_fig1_plant,
    "fig8_tree": organic.scene_fig8_tree,
    "palm_dino": organic.scene_palm_dino,
    "fence_perforated": stsv.scene_fence_perforated,
    "fence_mesh": stsv.scene_fence_mesh,
    "hl2_like": stsv.scene_hl2_like,
    "factory": stsv.scene_factory,
    "greece": stsv.scene_greece,
    "wedge_overlap": stsv.scene_wedge_overlap,
    "city_flyby": animated.scene_city_flyby,
    "bridge_sun_sweep": animated.scene_bridge_sun_sweep,
    "ramp_slide": animated.scene_ramp_slide,
    "ramp_static": animated.scene_ramp_static,
    "walker": character.scene_walker,
    "open_world": open_world.scene_open_world,
    "open_world_flyby": open_world.scene_open_world_flyby,
    "open_world_sunset": open_world.scene_open_world_sunset,
    "dome_uniform": lights.scene_dome_uniform,
    "dusk_street": lights.scene_dusk_street,
}


def main(argv: Sequence[str] | None = None) -> int:
    """The command line: regenerate the bundled stages, one line per scene written."""
    ap = argparse.ArgumentParser(prog="python -m wsoft.stages.bundled", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(bundled_folder()), help="output folder (default: the bundled stages' folder)")
    ap.add_argument("names", nargs="*", metavar="NAME", help="scenes to write (default: all): " + ", ".join(SCENES))
    args = ap.parse_args(argv)

    names = list(SCENES)
    if args.names:
        names = []
        for n in args.names:
            key = os.path.splitext(os.path.basename(n))[0]
            if key not in SCENES:
                ap.error("unknown scene %r (choose from %s)" % (n, ", ".join(SCENES)))
            if key not in names:
                names.append(key)
    out_dir = os.path.abspath(args.out)
    os.makedirs(out_dir, exist_ok=True)

    for name in names:
        info = SCENES[name](out_dir)
        extra = ""
        if "instances" in info:
            extra = "  (%d instances of %d prototypes)" % (
                info["instances"], len(info["prototype_triangles"]))
        print("%-18s %-40s %9d triangles%s" % (name, info["file"], info["triangles"], extra))
        if name == "city":
            print("city total triangle count: %d" % info["triangles"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
