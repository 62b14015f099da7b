"""Times of ``ssm`` at 1 and 4 samples a pixel (Fig. 9's setups), for ``bench.ssm``.

Run as ``python -m wsoft.bench.ssm_msaa SCENE WIDTH HEIGHT DEVICE``: prints one JSON line. ``bench.ssm``
runs it in a child process with ``OPENBLAS_NUM_THREADS=1`` beside its in-process measurement:
NumPy's OpenBLAS threads keep spinning for a while after a large matrix product, and on a 2-core
machine they take the cores from the Warp launches that follow. The light view's fit over 4x the
receivers projects without BLAS (``lightview.to_frame``); the child process is a control.
"""

from __future__ import annotations

import json
import sys

BASE = {"shadow_map_size": 1024, "structure": "ysm", "occluder": "micropatch", "visibility": "bitmask", "budget": 10.0}
SETUPS = [("1 sample a pixel", {}, 1), ("4 samples, one visibility, no interpolation", {"msaa": "single"}, 4),
          ("4 samples, one visibility, interpolation", {"msaa": "interpolate"}, 4), ("4 samples, per-sample visibility", {"msaa": "per_sample"}, 4)]


def measure(scene: str, width: int, height: int, device: str) -> dict:
    """Per setup: the median frame's total ms, technique ms (passes named ssm*) and G-buffer ms, and the frame."""
    from wsoft.bench.harness import measure_render

    out = {}
    for label, p, spp in SETUPS:
        fr = measure_render(scene, "ssm", BASE | p | {"pixel_samples": spp}, device=device, width=width, height=height, light=None)
        t = fr.stats["timings_ms"]
        kinds = fr.stats["timings_by_kind_ms"]
        out[label] = {"frame_ms": t["total"], "ssm_ms": kinds.get("technique", 0.0), "gbuffer_ms": kinds.get("gbuffer", 0.0),
                      "timings_ms_runs": fr.stats["timings_ms_runs"], "frame": fr}
    return out


if __name__ == "__main__":
    name, w, h, dev = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    res = measure(name, w, h, dev)
    print(json.dumps({k: {kk: vv for kk, vv in v.items() if kk != "frame"} for k, v in res.items()}))
