"""Warp's CPU atomics are plain read-modify-write: a kernel launched in chunks across the thread
pool must never let two chunks update the same element. Every function that writes through
atomics is run here with 1 and with 8 threads, through every scheduling strategy it can take,
and must give identical output."""

from __future__ import annotations

import ast
import pathlib

import numpy as np
import pytest
import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR, LightView
from wsoft.raster import depth_map as D
from wsoft.raster import rasterizer as R
from wsoft.scene.device import upload_scene
from wsoft.scene.types import Material, Scene

WSOFT = pathlib.Path(__file__).resolve().parents[1] / "wsoft"


def atomic_writers() -> set[str]:
    """Names of the functions (kernels or ``@wp.func``) in wsoft whose body calls ``wp.atomic_*``."""
    found = set()
    for path in WSOFT.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                for sub in ast.walk(node):
                    if isinstance(sub, ast.Attribute) and sub.attr.startswith("atomic_") and isinstance(sub.value, ast.Name) and sub.value.id == "wp":
                        found.add(node.name)
                        break
    return found


def soup(n_small: int = 70000, seed: int = 0) -> Scene:
    """Overlapping random triangles at many depths, a few large ones (the CPU's banded second pass)
    and some crossing a perspective view's near plane (clipped, also banded)."""
    rng = np.random.default_rng(seed)
    c = rng.uniform([-4, -4, 1], [4, 4, 9], (n_small, 1, 3))
    tri = c + rng.normal(0, 0.06, (n_small, 3, 3))
    big = np.array([[[-5, -5, 9.5], [5, -5, 9.5], [0, 5, 9.5]], [[-3, -3, 5.0], [3, -3, 6.0], [0, 3, 5.5]],
                    [[-1, -1, -0.5], [1, -1, 2.0], [0, 1, 2.0]], [[-2, 0, -1.0], [2, 0.5, 3.0], [0, 2, -1.0]]])
    pts = np.concatenate([tri, big]).reshape(-1, 3).astype(np.float32)
    t = len(pts) // 3
    return Scene(path="soup", points=pts, triangles=np.arange(3 * t, dtype=np.int32).reshape(-1, 3), tri_prim=np.zeros(t, np.int32),
                 tri_material=np.zeros(t, np.int32), tri_uv=np.zeros((t, 3, 2), np.float32), tri_double_sided=np.ones(t, bool),
                 prims=["/soup"], materials=[Material(path="(default)")])


def view(persp: bool, size: int = 384) -> LightView:
    axes = np.eye(3)
    if persp:  # from the origin looking along +z
        return LightView("/L", True, np.zeros(3), axes, (-1.0, 1.0, -1.0, 1.0), 0.1, 20.0, size, size)
    return LightView("/L", False, np.array([0.0, 0.0, -1.0]), axes, (-5.0, 5.0, -5.0, 5.0), 0.0, 20.0, size, size)


def run_depth(persp: bool, strategy: str, conservative: bool = False, gate: bool = False):
    ds = upload_scene(soup(), "cpu")
    v = view(persp)
    if gate:
        t = D.GatedDepthTarget()
        t.gate = D.rasterize(ds, v, False, triangles=np.arange(0, 35000, dtype=np.int32)).depth
        frag = D.gated_depth_min
    else:
        t = D.DepthTarget()
        frag = D.depth_min
    t.depth = wp.full((v.height, v.width), DEPTH_CLEAR, dtype=float, device="cpu")
    st = R.make_rasterizer(v, frag, conservative=conservative).run(ds.points, ds.indices, ds.cutouts, v, t, "cpu", strategy=strategy)
    return t.depth.numpy(), st


CASES = {
    "depth_min": [dict(persp=True, strategy="private"), dict(persp=False, strategy="private"), dict(persp=True, strategy="bands"),
                  dict(persp=True, strategy="private", conservative=True)],
    "gated_depth_min": [dict(persp=True, strategy="private", gate=True)],
    "izb_test": [],  # the irregular z-buffer's light pass: tests/test_izb.py::test_one_and_eight_threads_agree
}


def test_every_atomic_writer_is_covered():
    assert atomic_writers() == set(CASES), "a function writes through atomics: add it to CASES here"


@pytest.mark.parametrize("name,kw", [(n, kw) for n, kws in CASES.items() for kw in kws], ids=lambda x: x if isinstance(x, str) else "-".join(f"{k}={v}" for k, v in x.items()))
def test_one_and_eight_threads_agree(monkeypatch, name, kw):
    monkeypatch.setenv("WSOFT_THREADS", "1")
    one, st1 = run_depth(**kw)
    monkeypatch.setenv("WSOFT_THREADS", "8")
    eight, st8 = run_depth(**kw)
    assert np.array_equal(one, eight)
    covered = one < DEPTH_CLEAR
    assert covered.mean() > 0.3  # the map really holds geometry
    if kw["strategy"] == "private":
        assert st1.private_targets == 1 and st8.private_targets > 1  # the workers really had their own targets
        assert st8.big_triangles >= 2  # and the banded second pass ran
    else:
        assert st8.bands > st1.bands > 1
