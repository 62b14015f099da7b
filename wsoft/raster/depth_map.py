"""Light-view depth maps: the rasterizer (:mod:`wsoft.raster.rasterizer`) with a depth fragment
(:func:`depth_min`, the nearest depth per texel; :func:`gated_depth_min`, Salzman's inverted depth
test behind a gate map), :func:`rasterize` for a scene (its soup, a list of its triangles, its
instances), alpha-tested, conservative or of inner coverage, of every face or only some."""

from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.view import DEPTH_CLEAR, LightView, boxes_in_view
from wsoft.parallel import ensure_loaded, launch_chunked
from wsoft.raster.rasterizer import InstanceBatch, InstanceRun, fragment, make_rasterizer
from wsoft.scene.device import DeviceScene, face_surfaces, view_surfaces
from wsoft.scene.surfaces import without_culling


@wp.struct
class DepthTarget:
    """A depth map, ``[H, W]`` float32 linear view depth; ``DEPTH_CLEAR`` where empty."""

    depth: wp.array2d[float]


@wp.struct
class GatedDepthTarget:
    """A depth map written only behind ``gate`` (same shape): surfaces behind the casters."""

    depth: wp.array2d[float]
    gate: wp.array2d[float]


@wp.kernel
def fill_depth(
    offset: int,
    value: float,
    # outputs
    dst: wp.array[float],
):
    dst[wp.tid() + offset] = value


@wp.kernel
def merge_min(
    offset: int,
    src: wp.array[float],
    # outputs
    dst: wp.array[float],
):
    """dst = min(dst, src), element-wise over flat maps."""
    i = wp.tid() + offset
    dst[i] = wp.min(dst[i], src[i])


def _private_depth(t, device):
    ensure_loaded(fill_depth, device)  # cleared inside the workers' tasks
    p = type(t)()
    p.depth = wp.empty(t.depth.shape, dtype=float, device=device)
    if hasattr(t, "gate"):
        p.gate = t.gate
    return p


def _clear_depth(t, device):
    """Clear a private depth target (runs inside its worker's task: one thread)."""
    ensure_loaded(fill_depth, device)
    wp.launch(fill_depth, dim=t.depth.size, inputs=[0, DEPTH_CLEAR], outputs=[t.depth.reshape(-1)], device=device)


def _merge_depth(privates, t, device):
    flat = t.depth.reshape(-1)
    for p in privates:
        launch_chunked(merge_min, flat.shape[0], inputs=[p.depth.reshape(-1)], outputs=[flat], device=device, min_chunk=1 << 16)


@fragment(DepthTarget, private=_private_depth, clear=_clear_depth, merge=_merge_depth, masked=True)
def depth_min(t: DepthTarget, x: int, y: int, z: float, bary: wp.vec3, tri: int):
    """Keep the nearest depth of the texel."""
    wp.atomic_min(t.depth, y, x, z)


@fragment(GatedDepthTarget, private=_private_depth, clear=_clear_depth, merge=_merge_depth, masked=True)
def gated_depth_min(t: GatedDepthTarget, x: int, y: int, z: float, bary: wp.vec3, tri: int):
    """Keep the nearest depth behind the gate (the inverted depth test; nothing where the gate is empty)."""
    if z > t.gate[y, x] * 1.0001:
        wp.atomic_min(t.depth, y, x, z)


@dataclass
class DepthMap:
    """Light-space linear depth, shape ``[height, width]`` float32; ``DEPTH_CLEAR`` where empty."""

    view: LightView
    depth: wp.array
    alpha_tested: bool
    conservative: bool
    inner: bool = False  # texels certainly blocked (inner coverage, farthest depth), else DEPTH_CLEAR
    private_maps: int = 0  # CPU worker maps merged into ``depth`` (temporaries, freed)
    big_triangles: int = 0  # CPU: triangles rasterized in the banded second pass
    instances_drawn: int = 0  # instanced scene: instances whose bounds reach the view (drawn)
    texels_read: int = 0  # > 0: only these texels were drawn, those the receivers read (wsoft.raster.raycast.raycast_read); DEPTH_CLEAR elsewhere

    def arrays(self) -> dict[str, wp.array]:
        return {"depth": self.depth}


def rasterize(
    ds: DeviceScene,
    view: LightView,
    alpha_tested: bool,
    conservative: bool = False,
    triangles: np.ndarray | None = None,
    behind: wp.array | None = None,
    inner: bool = False,
    faces: str = "all",
) -> DepthMap:
    """Rasterize the scene (or only ``triangles``, an index array) into a depth map for ``view``.

    ``behind``: a depth map of the same size; only surfaces behind it are written (the
    inverted depth test, :func:`gated_depth_min`; texels where it is empty receive nothing).
    ``inner``: per texel the nearest of the farthest depths of the triangles that cover it whole
    (cutouts never do), far faces included (each adds coverage): a depth every ray through the
    texel is certainly blocked at; ``DEPTH_CLEAR`` where no triangle covers the texel whole.
    ``faces``: ``all``, or only ``back`` / ``open`` faces (:func:`~wsoft.scene.device.face_surfaces`)."""
    dev = ds.device
    shape = (view.height, view.width)
    alpha = bool((alpha_tested or inner) and ds.has_cutouts)
    subset = None if triangles is None else wp.array(np.asarray(triangles, np.int32), dtype=wp.int32, device=dev)
    if behind is None:
        target = DepthTarget()
        frag = depth_min
    else:
        target = GatedDepthTarget()
        target.gate = behind
        frag = gated_depth_min
    target.depth = wp.empty(shape, dtype=float, device=dev)
    r = make_rasterizer(view, frag, conservative=conservative or inner, alpha=alpha, inner=inner)
    if faces != "all":
        surfaces = face_surfaces(ds, view.origin if view.persp else None, faces)
    elif inner:
        surfaces = without_culling(ds.cutouts, ds.tri_total, dev)
    else:
        surfaces = view_surfaces(ds, view.origin if view.persp else None)  # no far-face skipping around a light inside a closed mesh
    runs, placed = [], 0
    if ds.instances is not None:
        if inner or faces != "all" or triangles is not None:
            raise ValueError("an instanced scene's maps draw every face of every caster (no inner coverage, face subsets or triangle lists)")
        runs, placed = instance_runs(ds, view)
    st = r.run(ds.points, ds.indices, surfaces, view, target, dev, triangles=subset, initialized=False, batches=runs)
    return DepthMap(view=view, depth=target.depth, alpha_tested=alpha, conservative=conservative or inner, inner=inner,
                    private_maps=st.private_targets, big_triangles=st.big_triangles, instances_drawn=placed)


def instance_runs(ds: DeviceScene, view: LightView) -> tuple[list[InstanceRun], int]:
    """An instanced scene's instances to draw into ``view`` (for :meth:`Rasterizer.run`): per
    prototype one :class:`InstanceRun` of the instances whose world bounds can reach the view
    (:func:`~wsoft.lightspace.view.boxes_in_view`), split where its work items would pass 2^30
    (they are int32). Returns (runs, instances drawn)."""
    di = ds.instances
    dev = ds.device
    seen, origin_inside = boxes_in_view(view, di.lo, di.hi)
    runs, drawn = [], 0
    for p in range(len(di.proto_ntri)):
        sel = np.flatnonzero(seen & (di.proto == p))
        if len(sel) == 0 or di.proto_ntri[p] == 0:
            continue
        per_run = max(1, (1 << 30) // int(di.proto_ntri[p]))
        for a in range(0, len(sel), per_run):
            part = sel[a: a + per_run]
            b = InstanceBatch()
            b.to_world = wp.array(di.to_world[part].astype(np.float32), dtype=wp.mat44, device=dev)
            b.cull_off = wp.array(origin_inside[part].astype(np.int32), dtype=wp.int32, device=dev)
            b.mirrored = wp.array(di.mirrored[part].astype(np.int32), dtype=wp.int32, device=dev)
            b.ntri = int(di.proto_ntri[p])
            b.first = int(di.proto_first[p])
            b.tri0 = int(di.tri_base + di.proto_first[p])
            runs.append(InstanceRun(b, len(part), di.proto_points, di.proto_indices))
        drawn += len(sel)
    return runs, drawn
