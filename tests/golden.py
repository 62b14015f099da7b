"""The golden frames: every bundled technique on every light of every bundled stage it supports,
48 x 36 pixels, at its defaults (maps and grids of 512 texels or cells, the reference at 8
samples), each frame's V hashed (SHA-256 of its float32 bytes) and its mean kept
(``golden_frames.json``). ``tests/test_golden.py`` renders them again and compares: a change of
code that should not move a frame (a refactoring) must leave every hash as it is.

Write the file again (after a change that moves frames on purpose, saying why, or to add a
technique's frames) with ``python tests/golden.py --write``.
"""

from __future__ import annotations

import hashlib
import json
import sys
import warnings
from pathlib import Path

import numpy as np

FILE = Path(__file__).with_name("golden_frames.json")
WIDTH, HEIGHT = 48, 36


def golden_params(cls) -> dict:
    """The parameters a technique's golden frames are rendered with."""
    if cls.name == "reference":
        return {"samples": 8}
    return {cls.size_param: 512} if cls.size_param else {}


def frames():
    """(scene name, technique name, parameters) of every golden frame, in a fixed order."""
    from wsoft import usd_scenes
    from wsoft.pipeline import load_stage
    from wsoft.pipeline.build import refusal
    from wsoft.pipeline.loading import too_big_to_flatten
    from wsoft.techniques import TECHNIQUES, bundled_names, create

    for scene_name in usd_scenes.names():
        scene = load_stage(str(usd_scenes.path(scene_name)))
        for name in bundled_names():
            params = golden_params(TECHNIQUES[name])
            tech = create(name, params)
            if not any(refusal((name, params), scene, light, width=WIDTH, height=HEIGHT) is None for light in scene.lights):
                continue
            if scene.instanced and tech.instancing_why() and too_big_to_flatten(scene):
                continue
            yield scene, scene_name, name, params


def render_all() -> list[dict]:
    """Every golden frame rendered now: scene, technique, parameters, the lights it rendered, the
    hash of its V and the mean."""
    import wsoft

    out = []
    for scene, scene_name, name, params in frames():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a stage's own warnings (a light beyond one frustum) are not the point here
            f = wsoft.render(scene, name, width=WIDTH, height=HEIGHT, device="cpu", **params)
        v = np.ascontiguousarray(f.V, dtype=np.float32)
        out.append({"scene": scene_name, "technique": name, "params": params, "lights": f.stats["lights"],
                    "v_sha256": hashlib.sha256(v.tobytes()).hexdigest(), "mean_v": float(v.mean())})
    return out


def main(argv: list[str]) -> int:
    if argv != ["--write"]:
        print(__doc__)
        return 2
    rows = render_all()
    FILE.write_text("[\n" + ",\n".join(json.dumps(r) for r in rows) + "\n]\n")  # one frame per line
    print(f"wrote {len(rows)} golden frames to {FILE}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
