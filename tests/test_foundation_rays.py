"""The foundation sweep's ray_throughput timing and report section, on made-up functions and rows
(no render): alternating rounds, the 1-thread figures from CPU time, the generation bound's columns."""

from __future__ import annotations

import os

from wsoft.bench import foundation_rays
from wsoft.bench.foundation_rays import alternating_rounds, rays_sections


def test_rounds_alternate_and_keep_each_functions_fastest_wall_and_cpu():
    calls = []

    def make(key):
        def fn():
            calls.append((key, os.environ.get("WSOFT_THREADS")))
        return fn

    plan = [("a", None, make("a")), ("b", 1, make("b"))]
    before = os.environ.get("WSOFT_THREADS")
    best = alternating_rounds(plan, 2)
    # one warm-up each, then a, b, a, b: every round calls every function once, in turn
    assert [k for k, _ in calls] == ["a", "b", "a", "b", "a", "b"]
    assert all(t == "1" for k, t in calls if k == "b")  # its thread count set for its calls only
    assert os.environ.get("WSOFT_THREADS") == before
    assert set(best) == {"a", "b"} and all(w >= 0.0 and c >= 0.0 for w, c in best.values())


def _row(**over):
    r = {"case": {"kind": "ray_throughput"}, "scene": "contact", "light": "/World/Light", "samples": 16, "threads": 2, "rays": 1000,
         "rounds": 5, "machine": {"load": 2.5}, "packets_identical": True, "embree_mrays_s": 10.0, "embree_cpu_over_wall": 1.7,
         "embree_1t_mrays_s": 20.0, "generation_1t_ns_per_ray": 30.0, "random_draws_1t_ns_per_ray": 5.0, "launch_1t_ns_per_ray": 0.5}
    for kind in ("rays", "pass"):
        for mode in ("ray", "packet"):
            r |= {f"{kind}_{mode}_mrays_s": 8.0, f"{kind}_{mode}_cpu_over_wall": 1.9, f"{kind}_{mode}_1t_mrays_s": 16.0}
    return r | over


def test_the_section_names_its_timing_the_load_and_the_generation_bound():
    text = "\n".join(rays_sections([_row()]))
    assert "5 alternating rounds" in text and "for 1 thread its CPU time" in text
    assert "python -m wsoft.bench.foundation_rays" in text
    assert "Load average of the 2-core machine as the rows finished: 2.5" in text
    # pass 62.5 ns a ray at 1 thread, generation 30, Embree 50: generation / Embree 0.60, room 50 - 32.5
    line = [ln for ln in text.splitlines() if ln.startswith("| contact | Light | 16 | 62.5 |")][0]
    assert "| 30.0 | 5.0 | 0.5 | 32.5 | 50.0 | 17.5 | 0.60 |" in line


def test_a_row_without_the_launch_column_shows_a_dash():
    r = _row()
    del r["launch_1t_ns_per_ray"]
    text = "\n".join(rays_sections([r]))
    assert "| 30.0 | 5.0 | - | 32.5 |" in text
    assert foundation_rays.ROUNDS >= 3
