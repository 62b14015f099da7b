"""The comparison as one picture: ``wsoft.write_compare_grid`` on a real compare and on frames made
by hand (a NaN shows), ``wsoft compare``'s grid and short table, and the one palette."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import scene_path, wsoft_cli

from wsoft.metrics.figures import grid_size, short_params, write_compare_grid
from wsoft.palette import ORDER, style

W, H = 96, 72


def _palette_pixels(img: np.ndarray, technique: str) -> int:
    """Pixels of ``img`` (uint8 RGB) within 3 levels of ``technique``'s palette colour."""
    c = np.round(np.asarray(style(technique)["color"][:3]) * 255)
    return int((np.abs(img[..., :3].astype(int) - c).max(-1) <= 3).sum())


def _near(size, inches_dpi) -> bool:
    """A PNG's (width, height) against the figure's size in pixels (Agg drops the fraction)."""
    return all(abs(a - b) <= 1 for a, b in zip(size, inches_dpi))


def test_the_grid_of_a_compare_names_each_technique_its_time_and_error(tmp_path):
    from PIL import Image

    import wsoft

    fs = wsoft.compare(wsoft.load_scene(scene_path("box_plane.usda")), ["hard", ("pcss", {"shadow_map_size": 512})], samples=8,
                       width=W, height=H, device="cpu")
    path = tmp_path / "box_plane-compare.png"
    titles = write_compare_grid(str(path), fs)
    assert list(titles) == ["reference", "hard", "pcss"]  # the reference first
    assert titles["reference"].startswith("reference (8 samples)")
    for label in ("hard", "pcss"):
        e, ms = fs[label].stats["error"], fs[label].stats["timings_ms"]["total"]
        assert titles[label].startswith(label) and f"{ms:.1f} ms" in titles[label]
        assert f"penumbra MAE {e['mae_penumbra']:.4f}" in titles[label] and f"MAE {e['mae']:.4f}" in titles[label]
    assert "shadow_map_size=512" in titles["pcss"] and "(defaults)" in titles["hard"]
    assert e["mae_penumbra"] > 0.0  # a penumbra to see

    img = np.asarray(Image.open(path).convert("RGB"))
    fw, fh, ncol, nrow = grid_size(3, W, H, tiles=3)  # the shaded image, the ꟻLIP map, V against the reference's
    assert (ncol, nrow) == (3, 1) and _near(img.shape[1::-1], (fw * 110, fh * 110))
    assert img.shape[1] > 3 * W and img.shape[0] > 2 * H  # every tile at least the frame's own pixels
    for tech in ("hard", "pcss"):  # each technique's cell is framed in its palette colour
        assert _palette_pixels(img, tech) > 200, tech
    # the difference map: the hard shadow is darker than the reference outside, lighter inside, so both ends of RdBu_r show
    red = (img[..., 0] > 150) & (img[..., 1] < 80) & (img[..., 2] < 80)
    blue = (img[..., 2] > 120) & (img[..., 0] < 60)
    assert red.sum() > 20 and blue.sum() > 20


def _frame(v: np.ndarray, technique: str, params: dict, ms: float, error: dict | None):
    from wsoft.pipeline import Frame

    a = np.ones_like(v)
    a[:, :4] = 0.0  # background
    stats = {"technique": technique, "params": params, "light_labels": ["Key"], "timings_ms": {"total": ms},
             "scene": {"path": "/x/hand.usda"}, "width": v.shape[1], "height": v.shape[0], "device": "cpu"}
    if error is not None:
        stats["error"] = error
    return Frame(channels={"V": v, "V.Key": v, "A": a}, stats=stats)


def test_a_nan_in_v_is_drawn_and_counted_never_hidden(tmp_path):
    from PIL import Image

    from wsoft.pipeline import FrameSet

    y, x = np.mgrid[0:24, 0:32]
    ref = np.clip((x - 10) / 12.0, 0.0, 1.0).astype(np.float32)  # a penumbra ramp
    v = (x >= 16).astype(np.float32)
    v[5:8, 20:23] = np.nan
    err = {"mae": 0.2, "mae_penumbra": 0.3, "nan_pixels": 9}
    fs = FrameSet({"hard": _frame(v, "hard", {"shadow_map_size": 256, "bias": 0.001}, 3.0, err),
                   "reference": _frame(ref, "reference", {"samples": 64}, 40.0, None)}, {"reference": "reference"})
    path = tmp_path / "hand.png"
    titles = write_compare_grid(str(path), fs, title="by hand")
    assert titles["reference"] == "reference (64 samples)\n40.0 ms"
    assert "NaN 9 px" in titles["hard"] and "3.0 ms" in titles["hard"] and "40.0 ms" in titles["reference"]
    img = np.asarray(Image.open(path).convert("RGB")).astype(int)
    lime = (img[..., 0] > 120) & (img[..., 0] < 160) & (img[..., 1] > 240) & (img[..., 2] < 20)
    assert lime.sum() > 20  # 9 pixels of V, drawn magnified


def test_frames_compared_against_a_ground_truth_need_it(tmp_path):
    from wsoft.errors import ParameterError
    from wsoft.metrics import GroundTruth
    from wsoft.pipeline import FrameSet

    v = np.ones((12, 16), np.float32)
    fs = FrameSet({"hard": _frame(v, "hard", {}, 1.0, {"mae": 0.0, "mae_penumbra": 0.0})}, {"reference": None})
    with pytest.raises(ParameterError, match="pass that GroundTruth as reference="):
        write_compare_grid(str(tmp_path / "g.png"), fs)
    truth = GroundTruth({"Key": {"V": v, "V_stderr": 0 * v, "A": v}}, 32)
    titles = write_compare_grid(str(tmp_path / "g.png"), fs, truth, reference_ms=12.5)
    assert titles["reference"] == "reference (32 samples)\n12.5 ms" and (tmp_path / "g.png").is_file()


def test_short_params_keep_what_differs_from_the_defaults():
    assert short_params("pcss", {"shadow_map_size": 1024}) == "defaults"
    assert short_params("pcss", {"shadow_map_size": 512, "bias": 0.002}).startswith("shadow_map_size=512")
    assert short_params("no_such_plugin", {"k": 1.5}) == "k=1.5"


def test_the_cli_writes_the_grid_and_a_short_table_first(tmp_path):
    from PIL import Image

    out = tmp_path / "cmp"
    p = wsoft_cli("compare", "box_plane", "-t", "hard", "-t", "pcss", "--samples", "4", "--width", "48", "--height", "36", "--device", "cpu",
                  "--out-dir", str(out))
    assert p.returncode == 0, p.stderr
    png = out / "box_plane-compare.png"
    assert _near(Image.open(png).size, [s * 110 for s in grid_size(3, 48, 36, tiles=3)[:2]])  # shaded, ꟻLIP, V
    md = (out / "box_plane-compare.md").read_text()
    short = md.index("| technique | frame ms | MAE | penumbra MAE |")
    assert short < md.index("![each technique beside the reference](box_plane-compare.png)") < md.index("## Time (ms)")
    rows = md[short:].splitlines()[2:5]
    assert [r.split("|")[1].strip() for r in rows] == ["reference", "hard", "pcss"] and rows[0].endswith("| - | - |")
    assert str(png) in p.stdout


def test_every_bundled_technique_has_its_own_colour_and_the_reference_is_black():
    from wsoft.techniques import bundled_names

    names = [n for n in bundled_names() if n != "reference"]
    assert set(names) <= set(ORDER)
    styles = [(tuple(style(n)["color"]), style(n)["marker"]) for n in ORDER]
    assert len({c for c, _ in styles}) == len(ORDER)  # a colour each
    assert style("reference") == {"color": "black", "marker": "."}
    plugin = tuple(style("my_plugin_technique")["color"])
    assert plugin not in {c for c, _ in styles}  # a plugin takes a colour no bundled technique has


@pytest.mark.parametrize("columns,cells,shape", [(4, 3, (3, 1)), (4, 4, (4, 1)), (4, 5, (3, 2)), (4, 9, (3, 3)), (2, 5, (2, 3))])
def test_grid_size_wraps_cells_into_rows(columns, cells, shape):
    assert grid_size(cells, 640, 480, columns)[2:] == shape


def test_a_side_by_side_label_wraps_inside_its_panel(tmp_path):
    from PIL import Image, ImageDraw, ImageFont

    from wsoft.bench.common import LABEL_PX, params_label, side_by_side, wrap_label

    label = params_label("salzman", {"radius": 16, "shadow_map_size": 512, "far_bound": "off"})
    assert label == "salzman: radius=16, shadow_map_size=512, far_bound=off"
    font = ImageFont.load_default(size=LABEL_PX)
    draw = ImageDraw.Draw(Image.new("L", (1, 1)))
    lines = wrap_label(draw, label, font, 96 - 8)
    assert len(lines) >= 3 and all(draw.textlength(l, font=font) <= 88 for l in lines)
    assert "shadow_map_size=512," not in lines and "".join(lines).replace(" ", "") == label.replace(" ", "")  # a long word broken within
    v = np.zeros((40, 96), np.float32)
    case = {"scene": "s", "light": None, "technique": "salzman", "device": "cpu", "ref_samples": 1, "ref_casters": "dynamic"}
    rel = side_by_side(case, label, v, v, np.ones_like(v), {"stem": "t", "out_dir": tmp_path})
    img = np.asarray(Image.open(tmp_path / rel))
    top = img.shape[0] - 40
    assert img.shape[1] == 3 * 96 and top >= 3 * (LABEL_PX + 3)  # the header grew to the longest label's lines
    assert (img[:top, 96 - 3:96 + 3] == 255).all() and (img[:top, 2 * 96 - 3:2 * 96 + 3] == 255).all()  # no text across a panel's edge


def test_error_vs_time_colours_each_technique_from_the_palette(tmp_path):
    from PIL import Image

    from wsoft.bench.common import error_vs_time

    def row(scene, tech, ms, mae, group=None):
        return {"scene": scene, "technique": group or tech, "case": {"technique": tech}, "light": "/World/Light", "device": "cpu",
                "width": 64, "timings_ms": {"total": ms}, "error": {"mae": mae}}

    rows = [row(s, t, ms, e) for s in ("a", "b") for t, ms, e in (("pcss", 10, 0.01), ("pcss", 20, 0.005), ("vsm", 12, 0.02),
                                                                     ("vsm", 24, 0.015), ("reference", 30, 0.002), ("reference", 60, 0.001))]
    lines = error_vs_time(rows, tmp_path / "r.md", {"stem": "t"}, "test")
    img = np.asarray(Image.open(tmp_path / "images" / "t" / "error_vs_time.png").convert("RGB"))
    assert lines[-1] == "![error vs time](images/t/error_vs_time.png)"
    for tech in ("pcss", "vsm"):
        assert _palette_pixels(img, tech) > 30, tech
    assert _palette_pixels(img, "hard") == 0  # no colour that is not a technique's in the plot
