"""``wsoft.bake`` (:func:`bake`): a technique's visibility baked back into USD, as a layer of ``over``\\ s.

:func:`bake` (``wsoft bake`` on the command line) writes, on every mesh of a stage, a float primvar
``primvars:wsoft:visibility:<light>`` per shadow-casting light, time-sampled over the frames asked
for (or a default value), and optionally a texture per mesh and light over its ``st``. The layer is
meant to be added as a sublayer of the stage (``subLayerPaths``), stronger than it.

**How it reuses every technique unchanged.** A frame is rendered as usual, except that its
G-buffer (:func:`~wsoft.raster.gbuffer.bake_gbuffer`) holds *bake points* instead of camera-ray
hits: each mesh vertex (or face corner, or texel centre) moved off its surface along its normal,
with that normal and the triangle it lies on. The technique's passes, the light views fitted to
these receivers and the receiver's horizon (a point sees only the part of the light in front of
its tangent plane) run on it as on an eye view, so a bake covers what no camera sees. The bake
G-buffer has no camera and no pixel grid (no sample is another's neighbour): a technique that needs
either says why in :meth:`~wsoft.techniques.base.Technique.bake_support` and is refused (``izb``
with anti-aliasing, ``ssm`` with a per-pixel ``budget_map``); ``essm``'s anisotropic kernels see a
zero pixel footprint (a point has none) and ``ssm``'s level-of-quality smoothing no neighbour.

**Values.** The normal of each vertex or face corner follows the crease rule of
:mod:`wsoft.scene.mesh_points` (authored normals when present): a mesh whose vertices are all
smooth gets ``vertex`` interpolation (one value per point; points no face uses get 1), else
``faceVarying`` (one value per face corner, each with its face's normal: a cube's corner has three).
The interpolation of a mesh is decided at the first frame baked. Each bake point is moved off its
surface along its normal by :data:`BAKE_OFFSET` of the receivers' extent (the diagonal of the
bounds of every baked mesh's points), at least ``2e-6`` of its largest coordinate (the reference's
``ray_offset`` rule), and a face corner at a crease is also moved as far towards its face's
centroid, so that it does not lie on a neighbouring face of a concave crease. Visibility is the
renderer's: the unweighted fraction of the light that the point sees (hard techniques: 0 or 1).

**Textures** (``texture_size = N``): for each mesh with an ``st`` primvar, an ``N x N`` EXR per
light (channel ``V``; ``A`` is 1 on texels whose centre a triangle covers in uv space) whose texels
are baked at the 3-D point of their centre (barycentric on the triangle covering it in uv, the
normal interpolated from its corners') exactly like vertices. Where triangles overlap in uv the
first (in face order) wins; texels no triangle covers take the value of the nearest covered texel
(jump flooding), so bilinear filtering at uv seams reads no value from off the surface; a texture
no triangle covers is all 1. uv outside [0, 1] is not wrapped. Row 0 of the EXR is ``t = 1``
(``UsdUVTexture``'s convention). The layer gets, under each such mesh, a ``UsdShade.NodeGraph``
``<mesh>/wsoftVisibility`` with a ``UsdPrimvarReader_float2`` reading ``st``, a ``UsdUVTexture``
per light (``inputs:file``, time-sampled with the frames; raw colour space, clamped) and an output
``outputs:<light>`` (float): a hookup for the user to connect to a material input, bound to no
material.

The primvar's ``<light>`` is the light prim's name (its path where two lights share a name) made a
valid USD identifier (``Tf.MakeValidIdentifier``). Meshes instanced through ``instanceable``
prims or a ``PointInstancer`` cannot carry per-instance primvars and are skipped with a warning.
"""

from __future__ import annotations

import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
import warp as wp

import wsoft.usd_scenes as usd_scenes
from wsoft.errors import NonFiniteWarning, ParameterError, SceneError
from wsoft.graph import Pass
from wsoft.io import nonfinite_counts, write_exr
from wsoft.parallel import compile_time, resolve_device
from wsoft.raster.gbuffer import GBuffer, bake_gbuffer
from wsoft.pipeline.build import as_techniques, supported_lights, visibility_of
from wsoft.pipeline.context import GBUFFER, RenderContext
from wsoft.scene.mesh_points import CREASE_ANGLE, MeshSurface, read_mesh_surface
from wsoft.scene.types import Scene
from wsoft.scene.usd import diagnostic_lines, load_scene, open_stage, stage_file

BAKE_OFFSET = 2.0e-5
"""How far a bake point leaves its surface along its normal: this fraction of the receivers'
extent (the diagonal of the baked meshes' points), as the reference offsets its shadow rays."""

PRIMVAR = "wsoft:visibility:{light}"
"""The primvar written per light (``primvars:`` + this)."""

HOOKUP = "wsoftVisibility"
"""The name of the NodeGraph under a mesh that holds its texture hookups."""

MAX_TEXTURE_SIZE = 8192


class BakeContext(RenderContext):
    """A :class:`~wsoft.pipeline.RenderContext` whose G-buffer is a given bake G-buffer (points on
    surfaces, no camera): every provider and technique pass built on ``ctx.gbuffer()`` runs on it."""

    def __init__(self, scene: Scene, gbuffer: GBuffer, device: str):
        super().__init__(scene, None, gbuffer.width, gbuffer.height, device)
        self.bake_points = gbuffer

    def probe_receivers(self) -> tuple[np.ndarray, str]:
        """Every bake point decides which lights get a cube map (there is no camera to probe with)."""
        if self._probe is None:
            gb = self.bake_points
            prim = gb.prim.numpy()
            self._probe = (gb.pos.numpy()[prim >= 0].astype(np.float64), f"{int(np.count_nonzero(prim >= 0))} bake points")
        return self._probe

    def gbuffer(self):
        gb = self.bake_points
        return self.add(Pass("bake_points", (), (GBUFFER,), lambda res: {GBUFFER: gb}, kind="gbuffer"))


@dataclass
class _MeshPoints:
    """One mesh's bake points in a frame and where their values go."""

    surface: MeshSurface
    interpolation: str
    first: int  # first bake point in the frame's G-buffer
    count: int
    element: np.ndarray  # per bake point: its primvar element (a point or a face corner)...
    elements: int  # ...of this many
    inverse: np.ndarray | None = None  # faceVarying: element (valid corner) -> its (deduplicated) bake point
    texels: dict = field(default_factory=dict)  # texture: first, count, texel index, coverage


def _triangle_of_faces(scene: Scene, j: int, nfaces: int, tri_of_prim: dict) -> np.ndarray:
    """Per face of prim ``j``: the index of a scene triangle of that face (its first), else of the
    prim's first triangle (a face whose triangles were all dropped, zero area)."""
    tris = tri_of_prim.get(j, np.zeros(0, np.int64))
    out = np.full(nfaces, tris[0] if len(tris) else 0, np.int64)
    faces = scene.tri_face[tris]
    out[faces[::-1]] = tris[::-1]  # the first triangle of each face wins
    return out


def _on_refined_surface(s: MeshSurface, scene: Scene, tris: np.ndarray, first: int, count: int) -> MeshSurface:
    """``s`` (a cage's faces through its vertices' refined positions) with the normals of the refined
    surface: per vertex the area-weighted normal of the scene's triangles ``tris`` of the refined
    mesh (points ``first .. first + count``) around it, every corner smooth (``vertex`` values)."""
    import dataclasses

    p = scene.points[first:first + count].astype(np.float64)
    t = scene.triangles[tris].astype(np.int64) - first
    area = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, t[:, k], area)
    n = n[:len(s.points)]
    ln = np.linalg.norm(n, axis=1)
    n = np.where(ln[:, None] > 0, n / np.where(ln > 0, ln, 1.0)[:, None], 0.0)
    corner = np.where(s.corner_valid[:, None], n[s.corner_vertex], 0.0)
    return dataclasses.replace(s, vertex_normal=n, corner_normal=corner, corner_crease=np.zeros_like(s.corner_crease),
                               interpolation="vertex", normals="refined surface")


def _offsets(points: np.ndarray, eps: float) -> np.ndarray:
    """Per point: ``eps``, at least 2e-6 of its largest coordinate (as the reference's ray_offset)."""
    return np.maximum(eps, 2.0e-6 * np.abs(points).max(axis=1))


def _vertex_points(s: MeshSurface, eps: float, face_tri: np.ndarray):
    """Bake points of a vertex-interpolated mesh: (pos, nrm, tri, st, element)."""
    valid = s.corner_valid
    used = np.zeros(len(s.points), bool)
    used[s.corner_vertex[valid]] = True
    v = np.nonzero(used)[0]
    first_corner = np.full(len(s.points), -1, np.int64)
    cidx = np.nonzero(valid)[0]
    first_corner[s.corner_vertex[cidx[::-1]]] = cidx[::-1]
    n = s.vertex_normal[v]
    p = s.points[v] + _offsets(s.points[v], eps)[:, None] * n
    c = first_corner[v]
    st = s.st[c] if s.st is not None else None
    return p, n, face_tri[s.corner_face[c]], st, v


def _corner_points(s: MeshSurface, eps: float, face_tri: np.ndarray):
    """Bake points of a faceVarying mesh, one per distinct (point, normal) of its valid corners:
    (pos, nrm, tri, st, element = the corner of each bake point, inverse: valid corner -> bake point)."""
    c = np.nonzero(s.corner_valid)[0]
    n = s.corner_normal[c]
    base = s.points[s.corner_vertex[c]]
    off = _offsets(base, eps)[:, None]
    p = base + off * n
    crease = s.corner_crease[c]
    if crease.any():  # towards the face's centroid, in the tangent plane, so as to leave a concave neighbour's plane
        d = s.face_centroid[s.corner_face[c[crease]]] - base[crease]
        d -= np.einsum("ij,ij->i", d, n[crease])[:, None] * n[crease]
        ln = np.linalg.norm(d, axis=1)
        p[crease] += np.where(ln[:, None] > 0, d / np.where(ln > 0, ln, 1.0)[:, None], 0.0) * off[crease]
    key = np.concatenate([p, n], axis=1).astype(np.float32)
    _, first, inverse = np.unique(key.view(np.dtype((np.void, key.dtype.itemsize * 6))).ravel(), return_index=True, return_inverse=True)
    cc = c[first]
    st = s.st[cc] if s.st is not None else None
    return p[first], n[first], face_tri[s.corner_face[cc]], st, cc, inverse.ravel()


def texel_coverage(st_tri: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which triangle covers each texel centre of a ``size x size`` texture in uv space.

    ``st_tri``: [T, 3, 2] st of each triangle's corners. Returns (texel index ``row * size + col``
    of each covered texel, its triangle, its barycentric weights [K, 3]); row 0 is ``t = 1``.
    Where triangles overlap, the first wins; degenerate (zero uv area) triangles cover nothing."""
    x = st_tri[..., 0].astype(np.float64) * size - 0.5  # texel (row, col)'s centre is at (x, y) = (col, row)
    y = (1.0 - st_tri[..., 1].astype(np.float64)) * size - 0.5
    c0 = np.clip(np.ceil(x.min(axis=1)), 0, size).astype(np.int64)
    c1 = np.clip(np.floor(x.max(axis=1)), -1, size - 1).astype(np.int64)
    r0 = np.clip(np.ceil(y.min(axis=1)), 0, size).astype(np.int64)
    r1 = np.clip(np.floor(y.max(axis=1)), -1, size - 1).astype(np.int64)
    w = np.maximum(c1 - c0 + 1, 0)
    h = np.maximum(r1 - r0 + 1, 0)
    det = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    cand = np.where(np.abs(det) > 1e-12, w * h, 0)
    texel, tri, bary = [], [], []
    budget = 1 << 22  # candidate texels per chunk
    t = 0
    T = len(st_tri)
    while t < T:
        csum = np.cumsum(cand[t:])
        stop = t + max(1, int(np.searchsorted(csum, budget, side="right")))
        ids = np.arange(t, stop)
        k = cand[ids]
        ids = ids[k > 0]
        k = k[k > 0]
        t = stop
        if not len(ids):
            continue
        rep = np.repeat(ids, k)
        local = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
        cx = c0[rep] + local % w[rep]
        cy = r0[rep] + local // w[rep]
        d = det[rep]
        b1 = ((cx - x[rep, 0]) * (y[rep, 2] - y[rep, 0]) - (x[rep, 2] - x[rep, 0]) * (cy - y[rep, 0])) / d
        b2 = ((x[rep, 1] - x[rep, 0]) * (cy - y[rep, 0]) - (cx - x[rep, 0]) * (y[rep, 1] - y[rep, 0])) / d
        b0 = 1.0 - b1 - b2
        tol = -1e-9
        inside = (b0 >= tol) & (b1 >= tol) & (b2 >= tol)
        texel.append((cy * size + cx)[inside])
        tri.append(rep[inside])
        bary.append(np.stack([b0, b1, b2], axis=1)[inside])
    if not texel:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3))
    texel, tri, bary = np.concatenate(texel), np.concatenate(tri), np.concatenate(bary)
    order = np.lexsort((tri, texel))  # per texel, the first triangle first
    texel, tri, bary = texel[order], tri[order], bary[order]
    keep = np.concatenate([[True], texel[1:] != texel[:-1]])
    return texel[keep], tri[keep], np.clip(bary[keep], 0.0, 1.0)


def _texel_points(s: MeshSurface, size: int, eps: float, face_tri: np.ndarray):
    """Bake points at the texel centres a triangle of ``s`` covers in uv: (pos, nrm, tri, st, texel)."""
    st_tri = s.st[s.tri_corners]
    texel, t, b = texel_coverage(st_tri, size)
    corners = s.tri_corners[t]
    P = s.points[s.corner_vertex[corners]]  # [K, 3, 3]
    N = s.corner_normal[corners] if s.interpolation == "faceVarying" else s.vertex_normal[s.corner_vertex[corners]]
    p = np.einsum("kj,kjc->kc", b, P)
    n = np.einsum("kj,kjc->kc", b, N)
    ln = np.linalg.norm(n, axis=1)
    n = np.where(ln[:, None] > 1e-12, n / np.where(ln > 1e-12, ln, 1.0)[:, None], s.corner_normal[corners[:, 0]])
    p = p + _offsets(p, eps)[:, None] * n
    uv = np.einsum("kj,kjc->kc", b, st_tri[t].astype(np.float64))
    return p, n, face_tri[s.tri_face[t]], uv, texel


def fill_from_nearest(values: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """``values`` [H, W] with every texel outside ``covered`` set to the value of the nearest covered
    texel (jump flooding: log2 passes of 9 taps, then one more at step 1; exact but for rare ties
    between far seeds); all 1 when nothing is covered."""
    H, W = values.shape
    if not covered.any():
        return np.ones_like(values)
    if covered.all():
        return values
    yy, xx = np.mgrid[0:H, 0:W]
    sy = np.where(covered, yy, -1)
    sx = np.where(covered, xx, -1)
    big = float(H * H + W * W + 1)
    d2 = np.where(covered, 0.0, big)
    steps = []
    k = 1 << int(math.ceil(math.log2(max(H, W))))
    while k >= 1:
        k //= 2
        if k >= 1:
            steps.append(k)
    steps.append(1)
    for k in steps:
        for dy in (-k, 0, k):
            for dx in (-k, 0, k):
                if dy == 0 and dx == 0:
                    continue
                # the seed the texel (y + dy, x + dx) has found, looked at from (y, x)
                ny = np.full((H, W), -1)
                nx = np.full((H, W), -1)
                ys, ye = max(0, -dy), min(H, H - dy)
                xs, xe = max(0, -dx), min(W, W - dx)
                if ys >= ye or xs >= xe:
                    continue
                ny[ys:ye, xs:xe] = sy[ys + dy:ye + dy, xs + dx:xe + dx]
                nx[ys:ye, xs:xe] = sx[ys + dy:ye + dy, xs + dx:xe + dx]
                ok = ny >= 0
                cand = np.where(ok, (ny - yy) ** 2 + (nx - xx) ** 2, big)
                better = cand < d2
                sy = np.where(better, ny, sy)
                sx = np.where(better, nx, sx)
                d2 = np.where(better, cand, d2)
    return values[sy, sx]


def _frames(stage, frames, file: str) -> list[float] | None:
    """The time codes to bake (None: the loader's default time, written as a default value)."""
    from wsoft.pipeline.sequence import stage_time_codes

    return None if frames is None else stage_time_codes(stage, frames, file)


def _frame_token(t: float) -> str:
    return f"{int(t):04d}" if float(t).is_integer() and t >= 0 else f"{t:g}".replace("-", "m")


def _sanitise(path: str) -> str:
    from pxr import Tf

    return Tf.MakeValidIdentifier(path.strip("/").replace("/", "_")) or "mesh"


def bake(scene, technique, *, light: str | None = None, frames=None, out: str | None = None, texture_size: int | None = None,
         texture_dir: str | None = None, device: str | None = None, crease_angle: float = CREASE_ANGLE, stats: dict | None = None,
         progress=None, subdiv_level: int | None = None, material_purpose: str | None = None, **params):
    """Bake ``technique``'s visibility of the stage ``scene`` into a new ``Sdf.Layer`` of ``over``\\ s
    (see the module's documentation) and return it.

    ``scene``: a USD file (or a bundled stage's name), an open ``Usd.Stage`` or a :class:`~wsoft.scene.types.Scene` (whose
    stage is read again: the open stage it was loaded from, with its load rules and population
    mask, else its file). ``technique``: a name with its parameters as keywords (``samples=1024``), a
    ``(name, params)`` pair or a Technique. ``light``: one light's path or name (default: every
    shadow-casting light the technique supports). ``frames``: ``"a:b"``, ``"a:b:step"`` or a
    sequence of time codes, within the stage's time range, written as time samples; None: the time a
    render uses (the stage's start time code when it authors a range, else its earliest time
    sample, else the default time), written as default values. ``out``: the layer's file (``.usda``, ``.usdc`` or ``.usd``; saved);
    None: an anonymous layer. ``texture_size``: also bake ``N x N`` textures over each mesh's
    ``st`` into ``texture_dir`` (default: the layer's folder; required without ``out``), named
    ``<mesh path>_<light>.exr`` (``..._<light>.<frame>.exr`` per frame). ``crease_angle``: degrees
    (:mod:`wsoft.scene.mesh_points`). ``stats``: a dict filled with what was done (per frame
    wall and CPU times, points, meshes and their interpolation, skipped meshes, textures, warnings,
    the load's notes). ``progress``: called as ``progress(done, total, time_code)`` after each frame.

    ``subdiv_level`` (None: a :class:`~wsoft.scene.types.Scene`'s own, else 0): subdivision
    surfaces are refined that many times (:func:`~wsoft.scene.usd.load_scene`) and cast the
    refined shadows; their primvars stay the cage's, one value per cage point (``vertex``), baked
    at each cage vertex's refined position (a vertex of the refined surface) with the refined
    surface's normal there (area-weighted over its refined triangles). A texture bake
    (``texture_size``) needs the cage itself (its texels lie on the cage's faces): with
    ``subdiv_level > 0`` it is an error. ``material_purpose``: the purpose material bindings resolve
    for, ``full`` or ``preview`` (None: a :class:`~wsoft.scene.types.Scene`'s own, else ``full``)."""
    from pxr import Sdf, Tf, Usd, UsdGeom, UsdUtils, Vt

    version = sys.modules["wsoft"].__version__  # the package (loaded before any of its modules), not an upward import

    report = stats if stats is not None else {}
    report.update(frames=[], warnings=[], notes=[], meshes={}, skipped_meshes={}, textures=[], lights={})
    warn_list: list[str] = report["warnings"]
    # the technique first: a refusal costs nothing
    (tech,) = as_techniques(technique, params)
    why = tech.bake_support()
    if why is not None:
        raise ParameterError(f"{tech.name} cannot bake: {why}")
    if not (0.0 <= float(crease_angle) <= 180.0):
        raise ParameterError(f"crease angle {crease_angle:g} out of range [0, 180] degrees")
    if texture_size is not None and not 1 <= int(texture_size) <= MAX_TEXTURE_SIZE:
        raise ParameterError(f"texture size {texture_size} out of range [1, {MAX_TEXTURE_SIZE}]")
    if subdiv_level is None:
        subdiv_level = scene.subdiv_level if isinstance(scene, Scene) else 0
    if material_purpose is None:  # a Scene's loads keep its material purpose
        material_purpose = scene.material_purpose if isinstance(scene, Scene) else "full"
    if texture_size is not None and subdiv_level:
        raise ParameterError(f"a texture bake reads the control cage's faces: texture_size {texture_size} needs subdiv_level 0, "
                             f"not {subdiv_level}")
    if out is not None:
        out = os.fspath(out)
        if not out.endswith((".usda", ".usdc", ".usd")):
            raise ParameterError(f"{out}: the layer must be a .usda, .usdc or .usd file")
        if os.path.isdir(out):
            raise ParameterError(f"{out}: is a directory, not a file")
    if texture_size is not None and texture_dir is None:
        if out is None:
            raise ParameterError("texture_size needs texture_dir (or out, whose folder is the default)")
        texture_dir = os.path.dirname(os.path.abspath(out))
    dev = resolve_device(device)

    # the stage
    loaded_from, load_time = scene.__dict__.get("_loaded_from", (None, None)) if isinstance(scene, Scene) else (None, None)
    if isinstance(scene, Usd.Stage):
        stage, file = scene, stage_file(scene)
    elif isinstance(loaded_from, Usd.Stage):  # a Scene of an open stage: that stage (its load rules and population mask)
        stage, file = loaded_from, scene.path
    elif isinstance(scene, Scene) and not os.path.isfile(scene.path):  # loaded from a stage in memory
        found = Sdf.Layer.Find(scene.path)
        if not found:
            raise ParameterError("this Scene has no file to open again; pass its Usd.Stage", file=scene.path)
        stage, file = Usd.Stage.Open(found), scene.path
    else:
        file = scene.path if isinstance(scene, Scene) else usd_scenes.resolve(scene)
        delegate = UsdUtils.CoalescingDiagnosticDelegate()
        stage = open_stage(file)
        warn_list += diagnostic_lines(delegate.TakeUncoalescedDiagnostics(), file)
    times = _frames(stage, frames, file)
    if times is None and isinstance(scene, Scene):
        times_load = [load_time if loaded_from is not None else scene.time]  # the Scene's own load
    else:
        times_load = times if times is not None else [None]

    layer = Sdf.Layer.CreateAnonymous(".usda")
    ostage = Usd.Stage.Open(layer)
    interp_of: dict[str, str] = {}
    hooked: set[tuple[str, str]] = set()
    noted: set[str] = set()
    lights_of: dict[str, str] = {}  # light path -> primvar identifier

    repeats: dict[str, list] = {}  # a pass's warning, once per bake: [its index in warn_list, frames it came in]

    def note(msg: str, key: str | None = None) -> None:
        if key is not None:
            if key in repeats:
                repeats[key][1] += 1
                return
            repeats[key] = [len(warn_list), 1]
        if msg not in noted:
            noted.add(msg)
            warn_list.append(msg)

    from wsoft.techniques import TECHNIQUES  # noqa: F401  (the technique modules load before the clock starts)

    for fi, t in enumerate(times_load):
        f0, c0 = time.perf_counter(), time.process_time()
        sc = load_scene(stage, time=t, subdiv_level=subdiv_level, material_purpose=material_purpose)
        for w in sc.warnings:
            note(w)
        report["notes"] += [n for n in sc.notes if n not in report["notes"]]
        tc = Usd.TimeCode.Default() if sc.time is None else Usd.TimeCode(sc.time)
        f1 = time.perf_counter()
        if not sc.lights:
            raise SceneError("no shadow-casting light", file=file)
        lights = [sc.find_light(str(light))] if light else list(sc.lights)
        mine, skipped = supported_lights(tech, sc, lights)
        for l, why in skipped:
            note(f"{tech.name}: light {l.path} skipped: {why}")
        if not mine:
            raise ParameterError(f"{tech.name}: " + "; ".join(f"{l.path}: {why}" for l, why in skipped), file=file)
        for l in mine:
            if l.path not in lights_of:
                ident = Tf.MakeValidIdentifier(sc.light_label(l))
                if ident in lights_of.values():
                    ident = Tf.MakeValidIdentifier(l.path)
                lights_of[l.path] = ident

        # the meshes and their bake points
        xf = UsdGeom.XformCache(tc)
        tri_order = np.argsort(sc.tri_prim, kind="stable")
        bounds = np.searchsorted(sc.tri_prim[tri_order], np.arange(len(sc.prims) + 1))
        tri_of_prim = {j: tri_order[bounds[j]:bounds[j + 1]] for j in range(len(sc.prims))}
        surfaces: list[tuple[int, MeshSurface]] = []
        for j, name in enumerate(sc.prims):
            if "@" in name:
                inst = name.split("@", 1)[1].split("[", 1)[0]
                report["skipped_meshes"][name.split("@", 1)[0] + "@" + inst] = "placed by a PointInstancer"
                note(f"{file}: {inst}: a PointInstancer's prototypes cannot carry per-instance primvars; its meshes are not baked")
                continue
            prim = stage.GetPrimAtPath(name)
            if not prim or prim.IsInstanceProxy():
                report["skipped_meshes"][name] = "an instance proxy"
                note(f"{file}: {name}: inside an instanceable prim, which cannot carry per-instance primvars; not baked "
                     f"(make its instance not instanceable to bake it)")
                continue
            if not prim.IsA(UsdGeom.Mesh):
                report["skipped_meshes"][name] = f"a {prim.GetTypeName()} (one of UsdGeom's shapes): no authored points or faces"
                note(f"{file}: {name}: a {prim.GetTypeName()} has no authored points or faces to carry primvars; not baked "
                     "(make it a mesh to bake it)")
                continue
            off, cnt = sc.prim_points[j]
            ncage = cnt
            if sc.subdiv_level:  # a refined mesh's first points are its cage's vertices, refined
                cage = UsdGeom.Mesh(prim).GetPointsAttr().Get(tc)
                ncage = min(int(cnt), len(cage) if cage is not None else 0)
            M = np.array(xf.GetLocalToWorldTransform(prim), dtype=np.float64).T
            s = read_mesh_surface(prim, tc, sc.points[off:off + ncage], M, crease_angle)
            if s is None:
                continue
            if ncage < cnt:
                s = _on_refined_surface(s, sc, tri_of_prim.get(j, np.zeros(0, np.int64)), off, cnt)
            for w in s.warnings:
                note(w)
            surfaces.append((j, s))
        if not surfaces:
            raise SceneError("no mesh to bake (instanced meshes cannot carry per-instance primvars)", file=file)
        allp = np.concatenate([s.points for _, s in surfaces])
        extent = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0))) if len(allp) else 1.0
        eps = BAKE_OFFSET * (extent if math.isfinite(extent) and extent > 0 else 1.0)

        parts_p, parts_n, parts_t, parts_uv, no_st = [], [], [], [], []
        meshes: list[_MeshPoints] = []
        cursor = 0
        for j, s in surfaces:
            face_tri = _triangle_of_faces(sc, j, len(s.face_centroid), tri_of_prim)
            interp = interp_of.setdefault(s.path, s.interpolation)
            if interp == "vertex" and s.interpolation == "faceVarying":
                note(f"{file}: {s.path}: has creases at time {sc.time} but was baked with vertex interpolation from the first frame; "
                     f"its values there use the mean normal of each vertex")
            if interp == "vertex":
                p, n, tr, st, elem = _vertex_points(s, eps, face_tri)
                mp = _MeshPoints(s, interp, cursor, len(p), elem, len(s.points))
            else:
                p, n, tr, st, elem, inverse = _corner_points(s, eps, face_tri)
                mp = _MeshPoints(s, interp, cursor, len(p), elem, len(s.corner_vertex), inverse)
            parts_p.append(p), parts_n.append(n), parts_t.append(tr)
            parts_uv.append(st if st is not None else np.zeros((len(p), 2)))
            cursor += len(p)
            if texture_size:
                if s.st is None:
                    report["skipped_meshes"].setdefault(s.path + " (texture)", "no st primvar")
                    no_st.append(s.path)
                else:
                    tp, tn, tt, tuv, texel = _texel_points(s, int(texture_size), eps, face_tri)
                    mp.texels = {"first": cursor, "count": len(tp), "texel": texel}
                    parts_p.append(tp), parts_n.append(tn), parts_t.append(tt), parts_uv.append(tuv)
                    cursor += len(tp)
            meshes.append(mp)
            report["meshes"][s.path] = {"interpolation": interp, "normals": s.normals, "elements": mp.elements}
        if no_st:
            note(f"{file}: {no_st[0]}" + (f" and {len(no_st) - 1} other mesh(es)" if len(no_st) > 1 else "")
                 + ": no usable st primvar: no texture baked (the primvar is)", key="no st")
        gb = bake_gbuffer(np.concatenate(parts_p), np.concatenate(parts_n), np.concatenate(parts_t), np.concatenate(parts_uv), dev)
        f2 = time.perf_counter()

        # the technique's passes on the bake points
        ctx = BakeContext(sc, gb, dev)
        tctx = ctx.technique(tech, tech.name)
        keys = [visibility_of(ctx, tctx, l) for l in mine]
        with wp.ScopedDevice(dev):
            res, records = ctx.graph.execute(keys, dev)
        f3 = time.perf_counter()
        for r in records:
            for w in ctx.warnings.get(r["name"], []):
                w = w.replace("visible samples", "bake points")  # the render context's words for its receivers
                note(f"{r['name']}: {w}", key=f"{r['name']}: {w.split(':', 1)[0]}")
        vis = {}
        for l, k in zip(mine, keys):
            v = res[k].vis.numpy()[:cursor].astype(np.float32)
            bad = nonfinite_counts({"V": v})
            if bad:
                msg = f"{tech.name}: light {l.path}: {bad['V']} non-finite visibilities (NaN/inf) at time {sc.time}, written as 0"
                warn_list.append(msg)
                warnings.warn(msg, NonFiniteWarning, stacklevel=2)
                v = np.nan_to_num(v, nan=0.0, posinf=0.0, neginf=0.0)
            vis[l.path] = v

        # into the layer
        when = Usd.TimeCode.Default() if times is None else Usd.TimeCode(float(sc.time))
        for mp in meshes:
            s = mp.surface
            prim = ostage.OverridePrim(s.path)
            pva = UsdGeom.PrimvarsAPI(prim)
            for l in mine:
                ident = lights_of[l.path]
                v = vis[l.path][mp.first:mp.first + mp.count]
                vals = np.ones(mp.elements, np.float32)
                if mp.interpolation == "vertex":
                    vals[mp.element] = v
                else:
                    vals[np.nonzero(s.corner_valid)[0]] = v[mp.inverse]
                pv = pva.CreatePrimvar(PRIMVAR.format(light=ident), Sdf.ValueTypeNames.FloatArray,
                                       UsdGeom.Tokens.vertex if mp.interpolation == "vertex" else UsdGeom.Tokens.faceVarying)
                pv.Set(Vt.FloatArray.FromNumpy(vals), when)
                if mp.texels:
                    _write_texture(ostage, s, mp, ident, vis[l.path], int(texture_size), texture_dir, out, times, sc.time, hooked,
                                   report)
        f4, c4 = time.perf_counter(), time.process_time()
        comp, comp_cpu = compile_time(f0, f4)
        report["frames"].append({
            "time": sc.time, "points": int(cursor), "meshes": len(meshes),
            "load_ms": round(1e3 * (f1 - f0), 3), "points_ms": round(1e3 * (f2 - f1), 3),
            "passes_ms": {r["name"]: round(r["ms"], 3) for r in records}, "technique_ms": round(sum(r["ms"] for r in records), 3),
            "technique_cpu_ms": round(sum(r["cpu_ms"] for r in records), 3),
            "write_ms": round(1e3 * (f4 - f3), 3), "compile_ms": round(1e3 * comp, 3), "total_ms": round(1e3 * (f4 - f0 - comp), 3),
            "cpu_ms": round(1e3 * max(c4 - c0 - comp_cpu, 0.0), 3),  # the process's CPU time over the frame (every thread), compiling apart
        })
        if progress is not None:
            progress(fi + 1, len(times_load), sc.time)
    report["lights"] = dict(lights_of)
    for i, n in repeats.values():
        if n > 1:
            warn_list[i] += f" (at the first frame; {n - 1} later frame(s) warned alike)"

    # what produced it
    doc = (f"Visibility baked by wsoft {version} (wsoft bake) from {file}: technique {tech.name} "
           f"({', '.join(f'{k}={v}' for k, v in _plain(tech.params).items())}) on {dev}, lights "
           f"{', '.join(f'{p} as primvars:{PRIMVAR.format(light=i)}' for p, i in lights_of.items())}, "
           + (f"time samples at {', '.join(f'{t:g}' for t in times)}" if times is not None else
              (f"default values (the stage at time {times_load[0]:g})" if times_load[0] is not None else "default values (the default time)"))
           + ". Add this layer as a sublayer of the stage (stronger). Visibility is the fraction of the light a point sees; "
           f"normals by the crease rule at {float(crease_angle):g} degrees; points moved {BAKE_OFFSET:g} of the receivers' extent "
           f"along their normal." + (f" Textures ({texture_size}x{texture_size}) are hooked up under <mesh>/{HOOKUP} (a NodeGraph "
                                     f"with an output per light), bound to no material." if texture_size else ""))
    layer.documentation = doc
    layer.customLayerData = {"wsoft": {
        "version": version, "command": "bake", "source": file, "technique": tech.name, "params": _plain(tech.params),
        "device": dev, "lights": dict(lights_of), "frames": Vt.DoubleArray([float(t) for t in times]) if times is not None else "default",
        "crease_angle": float(crease_angle), "offset_fraction": BAKE_OFFSET, "texture_size": int(texture_size or 0),
    }}
    if times is not None:
        if stage.HasAuthoredTimeCodeRange():
            layer.startTimeCode, layer.endTimeCode = stage.GetStartTimeCode(), stage.GetEndTimeCode()
        else:
            layer.startTimeCode, layer.endTimeCode = min(times), max(times)
        layer.timeCodesPerSecond = stage.GetTimeCodesPerSecond()
        layer.framesPerSecond = stage.GetFramesPerSecond()
    if out is None:
        return layer
    try:
        target = Sdf.Layer.Find(out) or Sdf.Layer.CreateNew(out)
        target.TransferContent(layer)
        if not target.Save():
            raise OSError("Save() failed")
    except Exception as exc:  # Tf.ErrorException: permission, a folder...
        raise ParameterError(f"cannot write the layer: {' '.join(str(exc).split())[:300]}", file=out) from None
    return target


def _plain(params) -> dict:
    """A technique's parameters as plain values for a layer's metadata (non-finite floats as text)."""
    import dataclasses

    out = {}
    for k, v in dataclasses.asdict(params).items():
        out[k] = str(v) if isinstance(v, float) and not math.isfinite(v) else v
    return out


def _write_texture(ostage, s: MeshSurface, mp: _MeshPoints, ident: str, v: np.ndarray, size: int, texture_dir: str, out: str | None,
                   times, t, hooked: set, report: dict) -> None:
    """One mesh's texture of one light at one frame, and (once) its hookup in the layer."""
    from pxr import Sdf, Usd, UsdShade

    tx = mp.texels
    img = np.zeros(size * size, np.float32)
    cov = np.zeros(size * size, bool)
    img[tx["texel"]] = v[tx["first"]:tx["first"] + tx["count"]]
    cov[tx["texel"]] = True
    img = fill_from_nearest(img.reshape(size, size), cov.reshape(size, size))
    name = f"{_sanitise(s.path)}_{ident}" + (f".{_frame_token(t)}" if times is not None else "") + ".exr"
    path = os.path.join(texture_dir, name)
    write_exr(path, {"V": img, "A": cov.reshape(size, size).astype(np.float32)})
    report["textures"].append(path)
    if out is not None:
        rel = os.path.relpath(os.path.abspath(path), os.path.dirname(os.path.abspath(out))).replace(os.sep, "/")
        asset = rel if rel.startswith("..") else "./" + rel
    else:
        asset = os.path.abspath(path)
    base = f"{s.path}/{HOOKUP}"
    tex_path = f"{base}/{ident}"
    if (s.path, ident) not in hooked:
        hooked.add((s.path, ident))
        ng = UsdShade.NodeGraph.Define(ostage, base)
        reader = UsdShade.Shader.Get(ostage, f"{base}/stReader")
        if not reader:
            reader = UsdShade.Shader.Define(ostage, f"{base}/stReader")
            reader.CreateIdAttr("UsdPrimvarReader_float2")
            reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
            reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        tex = UsdShade.Shader.Define(ostage, tex_path)
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset)
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.GetOutput("result"))
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
        tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("clamp")
        tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("clamp")
        r = tex.CreateOutput("r", Sdf.ValueTypeNames.Float)
        ng.CreateOutput(ident, Sdf.ValueTypeNames.Float).ConnectToSource(r)
    tex = UsdShade.Shader.Get(ostage, tex_path)
    when = Usd.TimeCode.Default() if times is None else Usd.TimeCode(float(t))
    tex.GetInput("file").Set(Sdf.AssetPath(asset), when)


__all__ = ["BAKE_OFFSET", "BakeContext", "bake", "fill_from_nearest", "texel_coverage"]
