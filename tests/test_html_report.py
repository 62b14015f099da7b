"""`wsoft report SWEEP`'s page (wsoft.bench.html_report): its groups and points from any sweep's rows,
the table-only page, the baseline page, and the page in a real headless Chromium (Selenium): no
console error, one data point per entry, a click on a point showing its images.

``python tests/test_html_report.py PAGE PNG`` opens PAGE in the same browser, clicks its first point
and saves a screenshot as PNG."""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import pytest

CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--window-size=1500,1100")


def _entry(tech: str, label: str, ms: float, err: float, **extra) -> dict:
    return {"technique": tech, "label": label, "params": {}, "frame_ms": ms,
            "error": {"mae_penumbra": err, "mae": err / 4, "penumbra_pixels": 100, "flip": err / 2}, "warnings": []} | extra


def _png(path: Path, shade: int) -> str:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("L", (48, 36), shade).save(path)
    return path.as_posix()


def pareto_rows(out: Path) -> list[dict]:
    """Two scenes' rows of pareto's shape: box_plane's pcss entry names its three images, its hard
    entry one side-by-side image; contact's entries none; the sweep's own plot of box_plane."""
    img = out / "images" / "fx"
    for n, name in enumerate(("frame", "difference", "flip")):
        _png(img / f"box_plane-Light-pcss-{name}.png", 60 * n + 40)
    _png(img / "box_plane-Light-hard-cpu.png", 200)
    _png(img / "box_plane-Light-cpu.png", 120)
    rel = "images/fx/box_plane-Light-pcss-"
    rows = []
    for scene in ("box_plane", "contact"):
        entries = [_entry("hard", "hard(shadow_map_size=512)", 10.0, 0.09), _entry("hard", "hard(shadow_map_size=1024)", 14.0, 0.07),
                   _entry("pcss", "pcss(shadow_map_size=512)", 20.0, 0.04), _entry("pcss", "pcss(shadow_map_size=1024)", 30.0, 0.03),
                   _entry("reference", "reference(samples=1)", 50.0, 0.08), _entry("reference", "reference(samples=16)", 200.0, 0.01)]
        if scene == "box_plane":
            entries[2]["images"] = {k: f"{rel}{k}.png" for k in ("frame", "difference", "flip")}
            entries[0]["image"] = "images/fx/box_plane-Light-hard-cpu.png"
        rows.append({"scene": scene, "light": "/World/Light", "light_kind": "rect", "device": "cpu", "width": 160, "height": 120,
                     "entries": entries, "key": scene})
    return rows


def test_groups_hold_every_entry_with_its_images(tmp_path):
    from wsoft.bench.html_rows import choice, groups

    gs = groups(pareto_rows(tmp_path), tmp_path, "fx")
    assert [g["title"] for g in gs] == ["box_plane / Light (rect), 160x120, cpu", "contact / Light (rect), 160x120, cpu"]
    assert [g["plotted"] for g in gs] == [6, 6] and gs[0]["metric"] == "mae_penumbra"
    pcss = gs[0]["points"][2]
    assert [i["slot"] for i in pcss["images"]] == ["frame", "difference", "flip"]
    assert [i["slot"] for i in gs[0]["points"][0]["images"]] == ["side_by_side"]
    assert gs[1]["points"][2]["images"] == [] and gs[0]["row_images"][0]["src"] == "images/fx/box_plane-Light-cpu.png"
    fastest = choice(gs[0])  # pareto's 'Which technique': fastest to 0.05, to 0.02, fastest but the reference to 0.05
    assert [c and c["setting"] for c in fastest] == ["pcss(shadow_map_size=512)", "reference(samples=16)", "pcss(shadow_map_size=512)"]


def test_single_setting_and_temporal_rows_group_by_scene_and_light(tmp_path):
    from wsoft.bench.html_rows import groups

    flat = [{"scene": "box_plane", "light": "/World/Light", "device": "cpu", "width": 64, "height": 48, "technique": t, "label": t,
             "params": {"shadow_map_size": 512}, "case": {"params": {"taps": n}}, "timings_ms": {"total": 5.0 * n},
             "error": {"mae_penumbra": 0.1 / n, "mae": 0.01, "penumbra_pixels": 10}, "image": "images/fx/missing.png"} for n, t in ((1, "pcf"), (2, "pcf"))]
    temporal = {"scene": "ramp_slide", "light": "/World/Light", "device": "cpu", "width": 64, "height": 48, "entries": [
        {"technique": "hard", "label": "hard", "params": {}, "frame_ms": 3.0, "flip": 0.2, "temporal": {"flicker": 0.01, "mae_penumbra": 0.3, "mae": 0.1}}]}
    gs = groups(flat + [temporal], tmp_path, "fx")
    assert [len(g["points"]) for g in gs] == [2, 1]
    assert [q["setting"] for q in gs[0]["points"]] == ["pcf(taps=1)", "pcf(taps=2)"]
    assert gs[0]["points"][0]["missing"] == {"side_by_side": "images/fx/missing.png is not in the report's folder"}
    q = gs[1]["points"][0]
    assert (q["err"], q["flicker"], q["flip"]) == (0.3, 0.01, 0.2) and "mean over the frames" in gs[1]["metric_text"]


def test_rows_without_time_and_error_make_a_table_only(tmp_path):
    from wsoft.bench.html_report import write_html

    rows = [{"structure": "grid", "build_ms": 3.5, "size": 512, "case": {}, "key": "a"}, {"structure": "tree", "build_ms": 7.25, "key": "b"}]
    text = write_html("tables", rows, tmp_path).read_text()
    assert "<th>structure</th>" in text and "<td>tree</td>" in text and "<h2>Rows</h2>" in text
    assert len(text) < 50_000  # no BokehJS inlined without a plot


def test_baseline_page_gives_ratios_and_changes(tmp_path):
    from wsoft.bench.html_baseline import compare
    from wsoft.bench.html_report import write_html

    new = pareto_rows(tmp_path)
    old = json.loads(json.dumps(new))
    for e in old[0]["entries"]:
        e["frame_ms"] *= 2
        e["error"]["mae_penumbra"] += 0.01
    old[1]["entries"].pop()
    c = compare(new, old, tmp_path, "fx")
    first = c["pairs"][0]
    assert first["ratio"] == pytest.approx(0.5) and first["d_err"] == pytest.approx(-0.01)
    assert c["only_new"] == [("contact / Light (rect), 160x120, cpu", "reference(samples=16)")] and c["only_old"] == []
    page = write_html("fx", new, tmp_path, baseline_rows=old)
    assert 'href="fx-baseline.html"' in page.read_text()
    assert "0.500" in (tmp_path / "fx-baseline.html").read_text()


def test_main_writes_the_page_of_a_rows_file(tmp_path, capsys):
    from wsoft.bench.html_report import main

    (tmp_path / "pareto-quick.jsonl").write_text("".join(json.dumps(r) + "\n" for r in pareto_rows(tmp_path)))
    assert main(["pareto", "--quick", "--out-dir", str(tmp_path)]) == 0
    assert (tmp_path / "pareto-quick.html").is_file()
    assert main(["temporal", "--out-dir", str(tmp_path)]) == 2 and "no rows file" in capsys.readouterr().err


# -- in a browser -------------------------------------------------------------------------------------


def browser():
    """A headless Chromium driven by Selenium, logging the console; skips where there is none."""
    if not (Path(CHROMIUM).is_file() and Path(CHROMEDRIVER).exists()):
        pytest.skip(f"no chromium: {CHROMIUM} and {CHROMEDRIVER} are needed (apt-get install chromium chromium-driver)")
    pytest.importorskip("bokeh", reason="no bokeh: the page has no plots (pip install bokeh)")
    webdriver = pytest.importorskip("selenium.webdriver", reason="no selenium (pip install selenium)")
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="wsoft-chromium-")
    for f in FLAGS + (f"--user-data-dir={profile}",):
        opts.add_argument(f)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.wsoft_profile = profile
    return driver


def close(driver) -> None:
    driver.quit()
    shutil.rmtree(driver.wsoft_profile, ignore_errors=True)


def open_page(driver, page: Path, timeout: float = 30.0) -> None:
    """Load ``page`` and wait for Bokeh to draw its plots (their views hold screen coordinates)."""
    driver.get(page.resolve().as_uri())
    end = time.time() + timeout
    while time.time() < end:
        if driver.execute_script("return !!(window.Bokeh && window.wsoftPoints && window.wsoftPoints() > 0 && "
                                 "Bokeh.documents.every(d => d.is_idle))"):
            return
        time.sleep(0.1)
    raise AssertionError(f"{page}: the plots did not draw within {timeout} s")


def click_point(driver, group: str, point: int) -> None:
    """A real mouse click at the point's pixel (read from its Bokeh glyph view)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.action_builder import ActionBuilder

    driver.execute_script(f"document.getElementById('{group}').scrollIntoView({{block: 'start'}});")
    x, y = driver.execute_script("""
        const [gid, k] = arguments; const g = wsoftData.groups.find(g => g.id === gid); const p = g.points[k];
        const models = Bokeh.documents.flatMap(d => [...d.all_models]);
        const r = models.find(m => m.name === 'pts' + p.src.slice(3)); const fig = models.find(m => m.name === 'fig:' + gid);
        const gv = Bokeh.index.get_one(r).glyph; const box = Bokeh.index.get_one(fig).el.getBoundingClientRect();
        return [box.left + gv.sx[p.idx], box.top + gv.sy[p.idx]];""", group, point)
    action = ActionBuilder(driver)
    action.pointer_action.move_to_location(round(x), round(y)).click()
    action.perform()
    ActionChains(driver).pause(0.2).perform()


def test_page_in_a_browser(tmp_path):
    from wsoft.bench.html_report import write_html

    rows = pareto_rows(tmp_path)
    page = write_html("fx", rows, tmp_path)
    driver = browser()
    try:
        open_page(driver, page)
        assert driver.execute_script("return window.wsoftPoints()") == sum(len(r["entries"]) for r in rows)
        pcss = driver.execute_script("return wsoftData.groups[0].points.findIndex(p => p.setting === 'pcss(shadow_map_size=512)')")
        click_point(driver, "g0", pcss)
        assert driver.execute_script("return window.wsoftSelected") == {"group": "g0", "point": pcss, "setting": "pcss(shadow_map_size=512)"}
        srcs = driver.execute_script("return [...document.querySelectorAll('#detail-g0 img')].map(i => [i.getAttribute('src'), i.naturalWidth])")
        assert srcs == [[f"images/fx/box_plane-Light-pcss-{k}.png", 48] for k in ("frame", "difference", "flip")]
        # a point without images says so, per image; the table's cell selects its point in its plot
        driver.execute_script("document.querySelector('a.pt[data-group=\"g1\"]').click()")
        sel = driver.execute_script("return window.wsoftSelected")
        assert sel["group"] == "g1" and sel["setting"] == "pcss(shadow_map_size=512)"
        assert driver.execute_script(f"return Bokeh.documents[0].get_model_by_name(wsoftData.groups[1].points[{sel['point']}].src).selected.indices.length") == 1
        none = driver.execute_script("return [...document.querySelectorAll('#detail-g1 figure.none')].map(f => f.textContent)")
        assert len(none) == 3 and all("the sweep stores none for this setting" in t for t in none)
        # a family's checkbox hides it in every plot
        driver.execute_script("document.querySelector('input[data-family=\"hard\"]').click()")
        assert driver.execute_script("return Bokeh.documents[0].get_model_by_name('pts:g1:hard').visible") is False
        severe = [m for m in driver.get_log("browser") if m["level"] == "SEVERE"]
        assert severe == []
    finally:
        close(driver)


def screenshot(page: Path, png: Path) -> None:
    """Open ``page``, click the first point of its first plot with images (else its first point), save a screenshot."""
    driver = browser()
    try:
        open_page(driver, page, timeout=120.0)
        gid, k = driver.execute_script("""
            const gs = wsoftData.groups.filter(g => g.points.some(p => p.src));
            for (const g of gs) { const k = g.points.findIndex(p => p.src && p.images.length); if (k >= 0) return [g.id, k]; }
            return [gs[0].id, gs[0].points.findIndex(p => p.src)];""")
        click_point(driver, gid, k)
        driver.execute_script(f"document.getElementById('{gid}').scrollIntoView({{block: 'start'}});")
        png.parent.mkdir(parents=True, exist_ok=True)
        driver.save_screenshot(str(png))
        print(f"{page}: {driver.execute_script('return wsoftPoints()')} points; clicked {gid}/{k}; "
              f"console errors: {[m['message'] for m in driver.get_log('browser') if m['level'] == 'SEVERE']}")
    finally:
        close(driver)


if __name__ == "__main__":
    screenshot(Path(sys.argv[1]), Path(sys.argv[2]))
