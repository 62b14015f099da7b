"""The adversarial corpus (``wsoft.stages.adversarial``): every hard or hostile input x every
technique, through the command line as a user runs it. Exit code, one-line errors naming the
prim, the warnings, no NaN, and the answer where it is known."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import wsoft
from wsoft.bench.adversarial import Corpus
from wsoft.errors import SceneError
from wsoft.stages.adversarial import CASES, KNOWN, b_missing_sublayer
from wsoft.techniques import TECHNIQUES


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    return Corpus(str(tmp_path_factory.mktemp("adversarial")))


@pytest.mark.parametrize("technique", sorted(TECHNIQUES))
@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_case(corpus, case, technique):
    res, problems = corpus.run(case, technique)
    if res is None:
        pytest.skip(f"{technique} does not support this stage's light")
    known = KNOWN.get((case.name, technique))
    if known:
        assert problems, f"the known defect no longer shows ({known}): remove it from KNOWN"
        pytest.xfail(known)
    assert not problems, "; ".join(problems)


def test_every_known_defect_is_a_case():
    names = {c.name for c in CASES}
    assert all(c in names and t in TECHNIQUES for c, t in KNOWN)


def test_usd_diagnostics_are_one_line_warnings(tmp_path):
    """A missing sublayer: USD's multi-line 'Warning: in _ReportErrors ...' never reaches stderr;
    one 'warning:' line names the layer (checked in a child process: USD prints from C++)."""
    stage = b_missing_sublayer(str(tmp_path))
    r = subprocess.run([sys.executable, "-m", "wsoft", "plan", stage], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = r.stdout + r.stderr
    assert "Warning: in" not in out and "_ReportErrors" not in out
    lines = [ln for ln in out.splitlines() if "not_there.usda" in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and stage in lines[0]


def test_light_inside_closed_mesh_is_shadowed_by_the_reference_everywhere(corpus):
    for name in ("lamp_rect", "lamp_sphere"):
        res = corpus.result(name, "reference")
        assert res.rc == 0 and res.channels["V"][res.channels["A"] > 0].max() == 0.0


def test_huge_triangle_leaves_biases_and_views_alone(corpus):
    """The frame's extent (receivers and light), not the scene's bounds, scales every default."""
    base = corpus.result("base", "hard").stats
    huge = corpus.result("huge_far_triangle", "hard").stats
    assert huge["scene"]["triangles"] == base["scene"]["triangles"] + 1
    for name in (base, huge):
        assert name["counters"]["passes"]["fit_light_view[Light]@256"]["receivers_outside"] == 0
    scene = wsoft.load_scene(corpus.stage("huge_far_triangle"))
    assert scene.diagonal > 1e7


# --------------------------------------------------------------------------- the mesh loader, fuzzed


def _mesh_stage(points, counts, indices):
    from pxr import UsdGeom

    from wsoft.stages import add_rect_light, make_stage

    stage = make_stage()
    m = UsdGeom.Mesh.Define(stage, "/World/M")
    m.CreatePointsAttr(points)
    m.CreateFaceVertexCountsAttr(counts)
    m.CreateFaceVertexIndicesAttr(indices)
    add_rect_light(stage, "/World/L", (0, 0, 5), 1, 1)
    return stage


coords = st.one_of(st.floats(-1e4, 1e4), st.sampled_from([0.0, 1e30, -1e30, 3e38, float("nan"), float("inf"), float("-inf")]))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    points=st.lists(st.tuples(coords, coords, coords), min_size=0, max_size=8),
    counts=st.lists(st.integers(-3, 6), min_size=0, max_size=5),
    indices=st.lists(st.integers(-2, 9), min_size=0, max_size=20),
)
def test_mesh_loader_loads_or_says_one_line(points, counts, indices):
    """Random counts, indices and points either load (finite float32 triangles with in-range
    indices) or give one SceneError naming the prim; never another exception."""
    try:
        scene = wsoft.load_scene(_mesh_stage(points, counts, indices))
    except SceneError as exc:
        line = exc.line()
        assert "\n" not in line and "/World/M" in line
        return
    assert np.isfinite(scene.points).all()
    if scene.triangle_count:
        assert scene.triangles.min() >= 0 and scene.triangles.max() < len(scene.points)
        p = scene.points[scene.triangles].astype(np.float64)
        assert (np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) > 0).all()
