"""The foundation sweep's rasterizer baselines (``BASELINES``: modules of earlier commits, read from
the git history) load against this checkout's package, whose modules hold some of the names they
import elsewhere: each such name comes from the module that defines it, and a name that no wsoft
module holds is an ImportError naming it."""

from __future__ import annotations

import ast

import pytest

import wsoft.bench.foundation_raster as fnd


def _imports(src: str) -> list[str]:
    tree = fnd._resolve_moved_imports(ast.parse(src), "test")
    return [ast.unparse(n) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]


@pytest.mark.parametrize("rev", sorted(fnd.BASELINES))
def test_every_baseline_loads(rev):
    mod = fnd._baseline_module(rev)
    if mod is None:
        pytest.skip(f"no git history with {rev} (not a checkout)")
    assert callable(mod.rasterize) and hasattr(mod, "LightView")


def test_a_name_its_module_does_not_hold_comes_from_the_module_that_defines_it():
    # surface_present and without_culling are defined in wsoft.scene.surfaces; wsoft.scene.device holds DeviceScene
    # and re-exports CULL_SKIP (kept where the source asks for it)
    src = "from wsoft.scene.device import CULL_SKIP, DeviceScene, surface_present, without_culling\n"
    assert _imports(src) == ["from wsoft.scene.device import CULL_SKIP, DeviceScene",
                             "from wsoft.scene.surfaces import surface_present, without_culling"]
    # inside a function too, and from a module that is not there at all (a constant: found by its assignment)
    src = "def f():\n    from wsoft.raster.no_such_module import DEPTH_CLEAR\n    return DEPTH_CLEAR\n"
    assert _imports(src) == ["from wsoft.lightspace.view import DEPTH_CLEAR"]
    assert _imports("from wsoft.scene import device\nfrom numpy import pi\n") == ["from wsoft.scene import device", "from numpy import pi"]


def test_a_name_no_wsoft_module_holds_is_an_import_error_naming_it():
    with pytest.raises(ImportError, match="no_such_name") as info:
        _imports("from wsoft.scene.device import DeviceScene, no_such_name\n")
    assert info.value.name == "no_such_name"
