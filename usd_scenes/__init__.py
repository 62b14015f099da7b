"""The bundled USD stages (installed as ``wsoft.usd_scenes``): :func:`path` finds one by name,
:func:`resolve` turns what a user gives as a scene (a file, or a bundled stage's name) into a file,
:data:`ABOUT` says in one line what each stage shows and :func:`catalog` gives their triangles,
lights and frames (``wsoft scenes`` prints both).

The stages are written by :mod:`wsoft.stages.bundled` (``python -m wsoft.stages.bundled``);
``catalog.json`` by :mod:`wsoft.scene.catalog` (``python -m wsoft.scene.catalog``: loading every
stage takes seconds, the catalog answers at once, and ``tests/test_first_hour.py`` checks it
against the stages). This package imports neither USD nor Warp.
"""

from __future__ import annotations

import json
import os
from importlib import resources
from pathlib import Path

from wsoft.errors import SceneError, suggestion

EXTENSIONS = (".usda", ".usdc", ".usdz", ".usd")
CATALOG = "catalog.json"

ABOUT = {
    "box_plane": "a square occluder under a parallel rect light: the exact visible fraction is known",
    "bridge_sun_sweep": "lightmapped_bridge with the sun turning 30 degrees while the character walks",
    "city": "a city of instanced buildings (about 1M triangles) under a sun and a rect light",
    "city_flyby": "the city seen from a camera flying a turn: shadow-map shimmer in motion",
    "contact": "a cube, a sphere and a plank touching the ground: contact shadows",
    "corridor_torch": "a small sphere light in a long closed corridor with pillars: receivers all around it",
    "cutout": "a fence quad perforated by an alpha texture (cutout) and an opaque box",
    "dinosaurs": "four instanced dinosaurs, feet on the ground (ESSM's Dinosaurs analog)",
    "dome_uniform": "a box and a small table under a constant DomeLight: the sky's own shadow",
    "dusk_street": "a street at dusk: a textured sky (DomeLight), the sun in it, a soft 30° spot and a 60° IES spot",
    "factory": "high-poly machinery and perforated grates under four sphere lights (Forest et al. Fig. 7b)",
    "fence_mesh": "fence_perforated's fence with its wires modelled as bars (Forest et al. Fig. 11b)",
    "fence_perforated": "a wire fence as two alpha-textured triangles (Forest et al. Fig. 11a)",
    "fig1_plant": "a potted plant under a large area light (Schwarz & Stamminger Fig. 1)",
    "fig8_tree": "a tree with instanced leaf clusters (Schwarz & Stamminger Fig. 8)",
    "forest": "10,195 trees placed by a PointInstancer (56M triangles): scale",
    "greece": "perforated leaf cards around a colonnade under three sphere lights (Forest et al. Fig. 7c)",
    "hl2_like": "foliage cards, a perforated fence and buildings under two suns (Forest et al. Fig. 7a)",
    "lightmapped_bridge": "baked light on a static bridge, a walking character and a torch (Salzman)",
    "multi_light": "one light of each kind (a dome among them) and an unshadowed one over n-gon occluders",
    "ogre": "one closed creature mesh, contact-sharp to wide penumbrae (ESSM's Ogre analog)",
    "open_world": "3 km of terrain (1M triangles) and 19,571 instanced trees, rocks and houses under a 0.53° sun",
    "open_world_flyby": "open_world from a camera flying 2 m above the ground, the sun still: shadow caching",
    "open_world_sunset": "open_world_flyby's flight with the sun sinking: every frame invalidates a shadow cache",
    "palm_dino": "a palm over a dinosaur (Schwarz & Stamminger Fig. 10)",
    "penumbra_ramp": "five plates at growing heights: every penumbra width known in closed form",
    "plants": "15 instanced plants of overlapping leaves (ESSM's Plants analog)",
    "ramp_slide": "penumbra_ramp under a sliding area light",
    "ramp_static": "penumbra_ramp with nothing moving: a technique's own flicker",
    "walker": "a UsdSkel figure stepping and waving under a rect light: skinned casters, a foot's contact shadow",
    "room_lamp": "a sphere light hanging in a furnished closed room: receivers on every side of it",
    "tower": "a thin lattice tower under a point light: sub-pixel hard shadows",
    "tunnel_fan": "a fan's shadows streaming along a tunnel: surfaces grazing eye and light",
    "wedge_overlap": "sheets and a perforated card whose penumbra wedges overlap (Forest et al. Fig. 4a)",
}
"""Bundled stage name -> what it shows, in one line (``usd_scenes/README.md`` has the details)."""


def folder() -> Path:
    """The folder holding the bundled stages (in a checkout or in site-packages)."""
    return Path(str(resources.files(__name__)))


def names() -> list[str]:
    """The bundled scenes' names (file names without extension)."""
    return sorted(p.stem for p in folder().iterdir() if p.suffix in EXTENSIONS)


def path(name: str) -> Path | None:
    """The file of the bundled scene ``name`` (with or without extension), or None."""
    d = folder()
    for cand in [d / name] + [d / (name + e) for e in EXTENSIONS]:
        if cand.is_file():
            return cand
    return None


def _is_name(s: str) -> bool:
    return bool(s) and os.sep not in s and not (os.altsep and os.altsep in s)


def resolve(scene) -> str:
    """The stage file ``scene`` names: the file itself when it exists; else, for a name without a
    folder (``multi_light``, ``multi_light.usda``), the bundled stage of that name. A name that is
    neither is a :class:`~wsoft.errors.SceneError` suggesting the closest bundled names; a path
    that does not exist is returned as it is (opening it says ``file not found``), unless its
    file name is a bundled stage's, which the error then names."""
    s = os.fspath(scene)
    if os.path.exists(s):
        return s
    stem = os.path.splitext(s)[0] if os.path.splitext(s)[1] in EXTENSIONS else s
    if _is_name(s):
        found = path(s)
        if found is not None:
            return str(found)
        raise SceneError("no such file, nor a bundled stage of that name" + suggestion(stem, names())
                         + "; `wsoft scenes` lists the bundled stages", file=s)
    base = os.path.basename(stem)
    if base in names():
        raise SceneError(f"file not found; {base!r} is a bundled stage: give its name alone", file=s)
    return s


def catalog() -> dict[str, dict]:
    """Name -> ``triangles`` (every instance's included), ``lights`` ([name, kind] of each
    shadow-casting light) and ``frames`` ([start, end] time codes, or None), as
    :func:`wsoft.scene.catalog.measure` read them; {} when the file is missing."""
    try:
        return json.loads((folder() / CATALOG).read_text())
    except FileNotFoundError:
        return {}
