"""``wsoft bench usd-pipeline --quick`` (render settings, shadow linking and baking, end to end): its
four sections, the images and stages it links, and that its rows say what the pipeline must do."""

from __future__ import annotations

import re

import numpy as np

from wsoft.bench import harness


def test_quick_report_has_its_sections_images_and_numbers(tmp_path):
    from pxr import Usd

    out = tmp_path / "reports"
    assert harness.run_sweep("usd-pipeline", quick=True, device=["cpu"], out_dir=str(out)) == 0
    md = (out / "usd_pipeline-quick.md").read_text()
    assert "Produced by `wsoft bench usd-pipeline --quick" in md and "Machine:" in md
    for head in ("## 1. Render settings", "## 2. `collection:shadowLink`", "## 3. Bake into USD", "## 4. Bake time per frame"):
        assert head in md, head
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(images) >= 10 and all(p.endswith(".png") and (out / p).is_file() for p in images), images
    assert all(p.startswith("usd_pipeline-quick/") for p in images)  # quick images apart from the full report's
    stages = re.findall(r"\[`[^`]+`\]\(([^)]+\.usda)\)", md)
    assert len(stages) == 3 and all((out / p).is_file() for p in stages)

    rows = {}
    for r in harness.read_rows(out / "usd_pipeline-quick.jsonl"):
        rows.setdefault(r["kind"], []).append(r)
    assert sorted(rows) == ["bake", "bake_time", "render_settings", "shadow_link"]

    # 1: the stage's own settings chose the second camera, the size, the policy and the window
    (rs,) = rows["render_settings"]
    stage = Usd.Stage.Open(str(out / rs["stage"]))
    assert stage.GetMetadata("renderSettingsPrimPath") == "/Render/Settings"
    own, flag = rs["renders"]
    f = own["framing"]
    assert (f["render_settings"], f["render_settings_source"], f["camera"], f["camera_source"]) == (
        "/Render/Settings", "metadata", "/World/Cam2", "render settings")
    assert f["resolution"] == rs["authored"]["resolution"] and f["resolution_source"] == "render settings"
    assert f["conform_policy"] == "cropAperture" and abs(f["pixel_aspect"] - 4 / 3) < 1e-6 and f["data_window"] is not None
    x0, y0, x1, y1 = f["data_window"]
    assert own["written"] == [x1 - x0, y1 - y0] and own["exr_names"]["V"] == "shadowVis"
    assert own["fov_conformed"][1] < own["fov_camera"][1]  # cropAperture narrowed the 16:9 window to the wider image
    assert flag["framing"]["camera"] == "/World/Cam1" and flag["framing"]["camera_source"] == "flag"

    # 2: the excluded blocker casts no shadow of the light; the other still does
    assert {r["technique"] for r in rows["shadow_link"]} == {"pcss", "reference"}
    for r in rows["shadow_link"]:
        none, excl = sorted(r["variants"], key=lambda v: len(v["exclude"]))
        assert none["under"]["A"]["mean_V"] < 0.05 and none["under"]["B"]["mean_V"] < 0.05, r["technique"]
        assert excl["under"]["A"]["mean_V"] < 0.05 and excl["under"]["B"]["mean_V"] > 0.95, r["technique"]
        assert not excl["under"]["B"]["usd_member"] and excl["under"]["A"]["usd_member"]

    # 3: every mesh's primvar read back through the composed stage, with the element count its interpolation asks
    for r in rows["bake"]:
        assert r["pictures"] and r["layer_bytes"] > 0
        baked = [m for m in r["meshes"] if m["primvars"]]
        assert len(baked) == len(r["interpolations"]) > 5
        for m in baked:
            for pv in m["primvars"].values():
                assert pv["elements"] == (m["points"] if pv["interpolation"] == "vertex" else m["face_corners"])
                assert 0.0 <= pv["min"] <= pv["mean"] <= pv["max"] <= 1.0 and pv["time_samples"] == [24.0]
                assert pv["interpolation"] == r["interpolations"][m["path"]]

    # 4: wall and CPU time per frame
    for r in rows["bake_time"]:
        assert len(r["frames"]) == 1 and all(fr["total_ms"] > 0 and fr["cpu_ms"] > 0 for fr in r["frames"])
        assert np.isfinite([fr["technique_cpu_ms"] for fr in r["frames"]]).all()
