"""The bundled stages' catalog, ``catalog.json`` beside them (:func:`wsoft.usd_scenes.catalog`):
their triangles, shadow-casting lights and frames, which ``wsoft scenes`` prints without loading
a stage. ``python -m wsoft.scene.catalog`` reads every bundled stage and writes it again (after a
stage changed; ``tests/test_first_hour.py`` checks that it matches)."""

from __future__ import annotations

import json
from pathlib import Path

import wsoft.usd_scenes as usd_scenes
from wsoft.scene.usd import load_scene


def measure(name: str) -> dict:
    """The catalog entry of the bundled stage ``name``, read from the stage (loaded with its
    instances kept): ``triangles`` (every instance's), ``lights`` ([name, kind] per shadow-casting
    light), ``frames`` ([startTimeCode, endTimeCode] when the stage authors them, else None)."""
    from pxr import Usd

    file = str(usd_scenes.path(name))
    scene = load_scene(file, instancing=True)
    stage = Usd.Stage.Open(file)
    frames = [stage.GetStartTimeCode(), stage.GetEndTimeCode()] if stage.HasAuthoredTimeCodeRange() else None
    return {"triangles": int(scene.total_triangles), "lights": [[l.name, l.kind_name] for l in scene.lights], "frames": frames}


def write_catalog() -> Path:
    """Measure every bundled stage and write ``catalog.json`` beside them, one line a stage."""
    out = usd_scenes.folder() / usd_scenes.CATALOG
    entries = [f"  {json.dumps(n)}: {json.dumps(measure(n))}" for n in usd_scenes.names()]
    out.write_text("{\n" + ",\n".join(entries) + "\n}\n")
    return out


if __name__ == "__main__":
    print(f"wrote {write_catalog()}")
