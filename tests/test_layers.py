"""The code's shape: dependencies point one way, every module imports on its own, kernel
signatures put inputs first and outputs after a ``# outputs`` comment, launches name them."""

from __future__ import annotations

import ast
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
WSOFT = ROOT / "wsoft"
BENCH = ROOT / "bench"

# lowest first: a module may import its own layer or lower ones, never a higher one
LAYERS = [
    ("core", ("wsoft.errors", "wsoft.env", "wsoft.params", "wsoft.parallel", "wsoft.graph", "wsoft.io", "wsoft.palette", "wsoft.rgbe")),
    ("stages", ("wsoft.stages", "wsoft.usd_scenes")),
    ("scene", ("wsoft.scene",)),
    ("lightspace", ("wsoft.lightspace",)),
    ("raster", ("wsoft.raster", "wsoft.reference")),
    ("accel", ("wsoft.accel",)),
    ("techniques", ("wsoft.techniques",)),
    ("pipeline", ("wsoft.pipeline",)),
    ("auto", ("wsoft.auto",)),  # --technique auto: registers itself with the pipeline (wsoft.pipeline.build.CHOOSERS)
    ("metrics", ("wsoft.metrics",)),
    ("baking", ("wsoft.baking",)),
    ("cli/bench", ("wsoft.cli", "wsoft.__main__", "wsoft.bench", "wsoft")),
]


def module_name(path: pathlib.Path) -> str:
    if path.is_relative_to(BENCH):
        rel = path.relative_to(BENCH).with_suffix("")
        parts = ["wsoft", "bench", *rel.parts]
    else:
        rel = path.relative_to(ROOT).with_suffix("")
        parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(mod: str) -> int:
    best, best_len = None, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (mod == p or mod.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    if best is None:
        raise AssertionError(f"module {mod} has no layer: add it to LAYERS")
    return best


def sources() -> list[pathlib.Path]:
    return sorted(WSOFT.rglob("*.py")) + sorted(BENCH.glob("*.py"))


def imports_of(path: pathlib.Path) -> list[tuple[str, int]]:
    """Every wsoft module ``path`` imports (module level or inside functions), with the line."""
    tree = ast.parse(path.read_text())
    me = module_name(path)
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names if a.name.split(".")[0] in ("wsoft", "bench")]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = me.split(".")[: len(me.split(".")) - node.level + (1 if path.name == "__init__.py" else 0)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] in ("wsoft", "bench"):
                out.append((mod, node.lineno))
                # "from wsoft.x import y" may import the submodule wsoft.x.y
                out += [(f"{mod}.{a.name}", node.lineno) for a in node.names if (ROOT / (mod + "." + a.name).replace(".", "/")).with_suffix(".py").exists()]
    return out


def test_every_module_has_a_layer():
    for path in sources():
        layer_of(module_name(path))


def test_imports_point_down():
    """core -> stages -> scene -> light space -> raster -> accel -> techniques -> pipeline -> auto -> metrics -> baking -> cli/bench."""
    bad = []
    for path in sources():
        me = module_name(path)
        mine = layer_of(me)
        for mod, line in imports_of(path):
            assert not mod.startswith("bench"), f"{path}:{line} imports the top-level bench (use wsoft.bench)"
            theirs = layer_of(mod)
            if theirs > mine:
                bad.append(f"{path.relative_to(ROOT)}:{line}: {me} ({LAYERS[mine][0]}) imports {mod} ({LAYERS[theirs][0]})")
    assert not bad, "imports pointing up:\n" + "\n".join(bad)


def test_techniques_do_not_import_each_other():
    """A technique's module (or package) imports no other technique; what two share lives below
    them, or in a module of ``wsoft.techniques`` that holds no technique (``base``, ``_object_based``)."""
    from wsoft.techniques import bundled_names

    names = set(bundled_names())
    assert {"hard", "izb", "ssm"} <= names and "_object_based" not in names and "base" not in names
    bad = []
    for path in (WSOFT / "techniques").rglob("*.py"):
        me = module_name(path)
        if me in ("wsoft.techniques", "wsoft.techniques.base"):
            continue
        own = me.split(".")[2]
        for mod, line in imports_of(path):
            parts = mod.split(".")
            if parts[:2] == ["wsoft", "techniques"] and len(parts) > 2 and parts[2] in names and parts[2] != own:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {mod}")
    assert not bad, "\n".join(bad)


def test_the_check_itself_sees_an_upward_import(tmp_path):
    """The layer test would catch a lower module importing a higher one (a test that can fail)."""
    fake = WSOFT / "accel" / "_layer_probe.py"
    fake.write_text("from wsoft.techniques.hard import Hard\n")
    try:
        with pytest.raises(AssertionError, match="_layer_probe"):
            test_imports_point_down()
    finally:
        fake.unlink()


def import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (module level or inside functions; ``bench`` as
    ``wsoft.bench``). An import names the module it reaches: ``from a.b import c`` is ``a.b.c``
    where that is a module, else ``a.b``; the packages above a module (whose ``__init__`` runs
    first) are not edges of their own."""
    mods = {module_name(p): p for p in sources()}
    graph = {m: set() for m in mods}
    for me, path in mods.items():
        for mod, _ in imports_of(path):
            if mod == "bench" or mod.startswith("bench."):
                mod = "wsoft." + mod
            while mod and mod not in mods:
                mod = mod.rpartition(".")[0]
            if mod and mod != me:
                graph[me].add(mod)
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, circles = {}, {}, set(), [], []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            v, edges = work[-1]
            w = next(edges, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on_stack:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    circles.append(sorted(comp))
    return circles


def test_no_import_circles():
    """No module reaches itself through the package's imports (function-level imports count)."""
    graph = import_graph()
    assert len(graph) > 80 and sum(map(len, graph.values())) > 300  # the walk really found the imports
    circles = import_circles(graph)
    assert not circles, "import circles:\n" + "\n".join(" <-> ".join(c) for c in circles)


def test_the_check_itself_sees_an_import_circle():
    """The circle test would catch two modules importing each other, one of them inside a function."""
    a, b = WSOFT / "accel" / "_circle_probe_a.py", WSOFT / "accel" / "_circle_probe_b.py"
    a.write_text("from wsoft.accel import _circle_probe_b\n")
    b.write_text("def f():\n    from wsoft.accel._circle_probe_a import f\n")
    try:
        with pytest.raises(AssertionError, match="wsoft.accel._circle_probe_a <-> wsoft.accel._circle_probe_b"):
            test_no_import_circles()
    finally:
        a.unlink()
        b.unlink()
    assert import_circles({"x": {"y"}, "y": {"z"}, "z": {"x"}, "w": {"x"}}) == [["x", "y", "z"]]


@pytest.mark.parametrize("mod", ["wsoft.techniques.ssm.kernels", "wsoft.accel.sat", "wsoft.accel.ssm_structures", "wsoft.lightspace.samples",
                                 "wsoft.raster.rasterizer", "wsoft.techniques.essm", "wsoft.metrics", "wsoft.baking",
                                 "wsoft.scene.mesh_points", "wsoft.bench.pareto", "wsoft.stages.bundled", "wsoft.stages.adversarial",
                                 "wsoft.scene.usd", "wsoft.scene.rays", "wsoft.raster.shadow_rays", "wsoft.reference.packets"])
def test_module_imports_on_its_own(mod):
    p = subprocess.run([sys.executable, "-c", f"import {mod}"], capture_output=True, text=True, timeout=300, cwd=str(ROOT))
    assert p.returncode == 0, p.stderr


def kernels() -> list[tuple[pathlib.Path, ast.FunctionDef]]:
    out = []
    for path in sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef):
                for d in node.decorator_list:
                    src = ast.unparse(d)
                    if src in ("wp.kernel", "wp.kernel()") or src.startswith("wp.kernel("):
                        out.append((path, node))
    return out


def test_kernel_signatures_put_outputs_last():
    """Every ``@wp.kernel`` lists its inputs, then a ``# outputs`` comment, then what it writes."""
    bad = []
    for path, node in kernels():
        lines = path.read_text().splitlines()
        body_start = node.body[0].lineno - 1
        if isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant):
            body_start = node.body[0].lineno - 1
        sig = "\n".join(lines[node.lineno - 1: body_start])
        if "# outputs" not in sig:
            bad.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name}")
    assert not bad, "kernels without '# outputs' in their signature:\n" + "\n".join(bad)
    assert len(kernels()) > 40  # the scan really found the kernels


def test_launches_name_inputs_and_outputs():
    """``wp.launch`` / ``launch_chunked`` calls spell out ``inputs=`` and ``outputs=``."""
    bad = []
    for path in sources():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call):
                f = ast.unparse(node.func)
                if f in ("wp.launch", "launch_chunked"):
                    kw = {k.arg for k in node.keywords}
                    if not {"inputs", "outputs"} <= kw:
                        bad.append(f"{path.relative_to(ROOT)}:{node.lineno} {f}")
    assert not bad, "launches without inputs=/outputs=:\n" + "\n".join(bad)


MAX_LINES = 700


def test_no_module_is_over_700_lines():
    """Every module of wsoft/ and bench/ holds at most 700 lines: a longer one is split by subject."""
    long = [f"{p.relative_to(ROOT)}: {n} lines" for p in sources() if (n := len(p.read_text().splitlines())) > MAX_LINES]
    assert not long, f"modules over {MAX_LINES} lines:\n" + "\n".join(long)


def test_every_package_is_installed():
    """pyproject.toml lists every package (a plain ``pip install .`` installs only those): each folder
    of wsoft/ with an ``__init__.py``, and bench/ and usd_scenes/ as wsoft.bench and wsoft.usd_scenes."""
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in WSOFT.rglob("__init__.py")} | {"wsoft.bench", "wsoft.usd_scenes"}
    assert listed == found
