"""Host-side scene: flat triangle soup in world space, materials, lights and cameras.

Everything here is plain numpy so a scene can be built without USD (tests do) and
handed to any device. Arrays are float32/int32, world space, right-handed winding.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from wsoft.scene.dome import LIGHT_DOME, Dome
from wsoft.scene.render_settings import RenderSettings
from wsoft.scene.shaping import Shaping
from wsoft.scene.stmap import StMap  # noqa: F401  (read from here by the loaders)

# light kinds (the integers are what kernels see)
LIGHT_RECT = 0
LIGHT_DISK = 1
LIGHT_SPHERE = 2
LIGHT_DISTANT = 3
LIGHT_POINT = 4  # SphereLight with treatAsPoint or radius 0
LIGHT_CYLINDER = 5  # CylinderLight: its side along the frame's X (a line light: radius 0)
# LIGHT_DOME (6): a DomeLight, its sky in Light.dome (wsoft.scene.dome)
LIGHT_KIND_NAMES = {LIGHT_RECT: "rect", LIGHT_DISK: "disk", LIGHT_SPHERE: "sphere", LIGHT_DISTANT: "distant", LIGHT_POINT: "point",
                    LIGHT_CYLINDER: "cylinder", LIGHT_DOME: "dome"}

# the 12 triangles of a box's 8 corners (corner k: bit 0 -> x, bit 1 -> y, bit 2 -> z high)
BOX_TRIANGLES = ((0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6), (0, 1, 5), (0, 5, 4), (2, 6, 7), (2, 7, 3), (0, 4, 6), (0, 6, 2),
                 (1, 3, 7), (1, 7, 5))
EXACT_CASTER_POINTS = 4_000_000  # instanced vertices up to which Scene.caster_points holds them all (else instance box corners)

WRAP_REPEAT = 0
WRAP_MIRROR = 1
WRAP_CLAMP = 2
WRAP_BLACK = 3
WRAP_NAMES = {"repeat": WRAP_REPEAT, "mirror": WRAP_MIRROR, "clamp": WRAP_CLAMP, "black": WRAP_BLACK}  # UsdUVTexture's wrapS/wrapT tokens


@dataclass
class Texture:
    """A single-channel texture: the output (r, g, b or a) of the ``UsdUVTexture`` a cutout's opacity
    reads, its ``scale`` and ``bias`` applied (:mod:`wsoft.scene.usd_texture`); rows stored bottom-up
    so st=(0,0) is element [0, 0]."""

    asset: str
    data: np.ndarray  # shape [h, w], float32 (in [0, 1] unless scale or bias take it out)
    wrap_s: int = WRAP_REPEAT
    wrap_t: int = WRAP_REPEAT
    border: float = 0.0  # the value outside the image under WRAP_BLACK: transparent black, scaled and biased (the bias)


@dataclass
class Material:
    """What shadows need of a UsdPreviewSurface: albedo for shading and the cutout (alpha) test."""

    path: str
    albedo: tuple[float, float, float] = (0.8, 0.8, 0.8)
    opacity: float = 1.0  # constant opacity (used when texture is None)
    opacity_threshold: float = 0.0  # > 0 makes the material a cutout (UsdPreviewSurface rule)
    texture: int = -1  # index into Scene.textures of the opacity texture, -1 = constant
    st: StMap | None = None  # where the opacity texture's st comes from (None: no texture, or the mesh's ``st`` as it is)
    udim: dict[int, int] | None = None  # a UDIM file's tiles: tile (1001-1100) -> texture index (-1: unreadable, the fallback)
    fallback: float = 1.0  # the UsdUVTexture's fallback for the channel read: the opacity where a texture cannot be read
    tile: int = 0  # a UDIM material's tile this material stands for (0: not a tile; -1: st outside every tile)

    @property
    def is_cutout(self) -> bool:
        return self.opacity_threshold > 0.0 and (self.texture >= 0 or self.opacity < self.opacity_threshold)


@dataclass
class Light:
    """A shadow-casting light in world space.

    ``frame`` is a 3x3 matrix whose columns are the light's world-space X, Y and Z axes,
    unit length (a mirroring transform keeps its reflection: the columns are where the local
    axes go). Rect lights span ``±half_size`` along X/Y and disk lights an ellipse of semi-axes
    :attr:`semi_axes` in the XY plane; both emit from their front only, along −Z
    (:attr:`direction`): nothing behind their plane receives their light. Sphere lights are an
    ellipsoid of semi-axes :attr:`semi_axes` along the frame's axes about ``position`` (a ball of
    ``radius`` when round) and emit all around; distant lights shine along −Z with a cone of full
    angle ``angle_deg``. Cylinder lights are the side of a cylinder of length ``2 half_size[0]``
    along X and radius ``half_size[1]`` (= ``radius``) about ``position``, emitting all around from
    its side (not its end caps); of radius 0 a line light (:attr:`is_line`). A dome light
    (``LIGHT_DOME``) is the sky: no position or size, its radiance in ``dome`` (:mod:`wsoft.scene.dome`).
    """

    path: str
    kind: int
    position: np.ndarray  # world position (unused for distant)
    frame: np.ndarray  # 3x3, columns = X, Y, Z axes (unit)
    half_size: tuple[float, float] = (0.0, 0.0)  # rect half width / half height; cylinder half length / radius (world units)
    radius: float = 0.0  # disk / sphere / cylinder radius (world units); of an ellipse or ellipsoid its largest semi-axis
    angle_deg: float = 0.0  # distant light full cone angle
    intensity: float = 1.0
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    # UsdLux shadow controls (ShadowAPI and the shadowLink collection of LightAPI)
    shadow_excluded: tuple[int, ...] = ()
    """Indices into ``Scene.prims`` of the prims ``collection:shadowLink`` leaves out: they cast no
    shadow of this light (they are still seen and still receive its shadows). Empty: every prim casts."""
    shadow_distance: float = -1.0
    """``inputs:shadow:distance`` in scene units: casters farther than this from the receiver along
    the shadow ray cast no shadow. Negative (USD's -1): no limit."""
    shadow_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """``inputs:shadow:color``: the shadowed part of this light's contribution to ``R G B`` takes
    this colour (black: a plain shadow). Never applied to ``V``."""
    shadow_falloff: float = -1.0
    """``inputs:shadow:falloff`` (scene units; <= 0: none). Read, listed by ``wsoft plan``, not applied."""
    shadow_falloff_gamma: float = 1.0
    """``inputs:shadow:falloffGamma``. Read, listed by ``wsoft plan``, not applied."""
    aspect: tuple[float, float, float] = (1.0, 1.0, 1.0)
    """A disk's (X, Y) or sphere's (X, Y, Z) semi-axes along the frame's axes as fractions of
    ``radius``: (1, 1, 1) for a round light, else one of them 1 (``radius`` is the largest)."""
    shaping: Shaping = field(default_factory=Shaping)  # UsdLux.ShapingAPI: cone, softness, focus, focus tint about −Z
    dome: Dome | None = None  # a dome light's (kind LIGHT_DOME) sky: texture, rotation, sampling table (wsoft.scene.dome)

    @property
    def distance_limited(self) -> bool:
        """Does ``inputs:shadow:distance`` limit which casters shadow (a value >= 0)?"""
        return self.shadow_distance >= 0.0

    @property
    def name(self) -> str:
        return self.path.rstrip("/").split("/")[-1] or self.path

    @property
    def kind_name(self) -> str:
        return LIGHT_KIND_NAMES[self.kind]

    @property
    def direction(self) -> np.ndarray:
        """World direction the light emits along (its −Z axis)."""
        return -self.frame[:, 2]

    @property
    def one_sided(self) -> bool:
        """Does the light emit from one side only (a rect or disk light: its front, along
        :attr:`direction`)? Receivers on or behind its plane get none of its light."""
        return self.kind in (LIGHT_RECT, LIGHT_DISK)

    @property
    def elliptical(self) -> bool:
        """Is the light a disk or sphere light of unequal semi-axes (an ellipse or ellipsoid)?"""
        return self.kind in (LIGHT_DISK, LIGHT_SPHERE) and tuple(self.aspect) != (1.0, 1.0, 1.0)

    @property
    def semi_axes(self) -> tuple[float, ...]:
        """A disk light's semi-axes along the frame's X and Y, a sphere light's along X, Y and Z."""
        n = 2 if self.kind == LIGHT_DISK else 3
        return tuple(self.radius * a for a in self.aspect[:n])

    @property
    def is_line(self) -> bool:
        """Is the light a line light (a cylinder light of radius 0, or one with ``treatAsLine``)?"""
        return self.kind == LIGHT_CYLINDER and self.radius == 0.0

    def points_behind(self, points: np.ndarray) -> int:
        """How many of ``points`` ([N, 3]) lie on or behind a one-sided light's plane (0 for the others)."""
        if not self.one_sided or len(points) == 0:
            return 0
        d = (np.asarray(points, np.float64) - np.asarray(self.position, np.float64)) @ np.asarray(self.direction, np.float64)
        return int(np.count_nonzero(~(d > 0.0)))

    def size_description(self) -> str:
        if self.kind == LIGHT_RECT:
            return f"{2 * self.half_size[0]:g} x {2 * self.half_size[1]:g}"
        if self.kind == LIGHT_CYLINDER:
            return f"line, length {2 * self.half_size[0]:g}" if self.is_line else f"length {2 * self.half_size[0]:g}, radius {self.radius:g}"
        if self.elliptical:
            return f"{'ellipse' if self.kind == LIGHT_DISK else 'ellipsoid'}, semi-axes {' x '.join(f'{a:g}' for a in self.semi_axes)}"
        if self.kind in (LIGHT_DISK, LIGHT_SPHERE):
            return f"radius {self.radius:g}"
        if self.kind == LIGHT_DISTANT:
            return f"angle {self.angle_deg:g} deg"
        if self.kind == LIGHT_DOME:
            return f"sky, {self.dome.description()}"
        return "point"

    def extent(self) -> float:
        """Radius of the light's emitting region's bounding ball (world units; radians for distant)."""
        if self.kind in (LIGHT_RECT, LIGHT_CYLINDER):
            return math.hypot(*self.half_size)
        if self.kind in (LIGHT_DISK, LIGHT_SPHERE):
            return self.radius
        if self.kind == LIGHT_DISTANT:
            return math.radians(self.angle_deg) * 0.5
        return 0.0


@dataclass
class SkippedLight:
    path: str
    kind: str
    reason: str


@dataclass
class Camera:
    """A pinhole or orthographic camera. ``to_world`` is 4x4 (column vectors); looks down −Z.

    ``tan_half`` = (tan of half the horizontal field, tan of half the vertical field) for
    perspective; half extents in world units for orthographic. ``offset`` shifts the window
    in the same units.
    """

    path: str
    to_world: np.ndarray
    orthographic: bool = False
    tan_half: tuple[float, float] = (0.4, 0.3)
    offset: tuple[float, float] = (0.0, 0.0)
    clip: tuple[float, float] = (1e-3, 1e7)

    @property
    def position(self) -> np.ndarray:
        return self.to_world[:3, 3].copy()


@dataclass
class Prototype:
    """Geometry shared by instances (a PointInstancer's prototype, or the prototype of instanceable
    prims), in the prototype root's own frame: the same per-triangle fields as :class:`Scene`'s
    triangle soup, indices into its own ``points``. ``tri_prim`` indexes ``Scene.prims`` (the
    prototype's mesh prims); ``tri_closed`` as :func:`wsoft.scene.usd_mesh.closed_orientation` gives it
    in the prototype's frame."""

    path: str
    points: np.ndarray  # [V, 3] float32, prototype frame
    triangles: np.ndarray  # [T, 3] int32
    tri_prim: np.ndarray  # [T] int32 -> Scene.prims
    tri_material: np.ndarray  # [T] int32 -> Scene.materials
    tri_uv: np.ndarray  # [T, 3, 2] float32 st per corner (as Scene.tri_uv)
    tri_double_sided: np.ndarray  # [T] bool
    tri_closed: np.ndarray  # [T] int8
    tri_face: np.ndarray  # [T] int32
    tri_dynamic: np.ndarray | None = None  # [T] bool: dynamic caster in every instance (None: none is)
    tri_baked: np.ndarray | None = None  # [T, 3, 3] float32 baked light per corner, NaN where absent (None: no mesh has any)
    root: str = ""
    """The prim the meshes were read under, their names in ``Scene.prims`` start with it: a
    PointInstancer prototype's root (``path``), or the instanceable prim whose instance proxies
    were read (``path`` is then USD's prototype, ``/__Prototype_N``)."""
    prim_points: np.ndarray | None = None  # [M, 3] int64: (Scene.prims index, first, count) of each mesh's points in ``points``

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])


@dataclass
class Instances:
    """Instanced geometry kept instanced (``load_scene(..., instancing=True)``): ``prototypes`` once,
    and per instance the prototype it places and its prototype-to-world transform.

    ``xform[i]`` is 4x4 float64, column-vector convention (world = xform @ [p, 1]); a transform with a
    negative determinant mirrors (its triangles' winding flips in world space). ``prim[i]`` indexes
    ``Scene.prims``: the instance's own prim (an instanceable prim, or the PointInstancer that
    places it); ``instance_id[i]``: the PointInstancer's instance index, -1 for an instanceable
    prim; ``dynamic[i]``: the instance moves over time (time-sampled instancer attributes or a
    moving transform)."""

    prototypes: list[Prototype]
    proto: np.ndarray  # [I] int32 -> prototypes
    xform: np.ndarray  # [I, 4, 4] float64
    prim: np.ndarray  # [I] int32 -> Scene.prims
    instance_id: np.ndarray  # [I] int32
    dynamic: np.ndarray  # [I] bool

    @property
    def count(self) -> int:
        return int(self.proto.shape[0])

    @property
    def prototype_triangles(self) -> int:
        """Triangles stored once (the prototypes')."""
        return int(sum(p.triangle_count for p in self.prototypes))

    @property
    def instanced_triangles(self) -> int:
        """Triangles the instances place in the world (what flattening would store)."""
        per = np.array([p.triangle_count for p in self.prototypes], np.int64)
        return int(per[self.proto].sum()) if self.count else 0

    @cached_property
    def world_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per instance the world bounds of its prototype's triangles: (lo [I, 3], hi [I, 3]) float64,
        from the 8 corners of the prototype's own bounds (a box that holds the instance)."""
        plo = np.array([p.points[np.unique(p.triangles)].min(axis=0) if p.triangle_count else np.zeros(3) for p in self.prototypes], np.float64)
        phi = np.array([p.points[np.unique(p.triangles)].max(axis=0) if p.triangle_count else np.zeros(3) for p in self.prototypes], np.float64)
        lo, hi = plo[self.proto], phi[self.proto]
        c = 0.5 * (lo + hi)
        e = 0.5 * (hi - lo)
        M = self.xform[:, :3, :3]
        wc = np.einsum("ijk,ik->ij", M, c) + self.xform[:, :3, 3]
        we = np.einsum("ijk,ik->ij", np.abs(M), e)
        return wc - we, wc + we

    def placed_vertices(self) -> int:
        """Vertices the instances place in the world (each prototype's used vertices, per instance)."""
        per = np.array([len(np.unique(p.triangles)) if p.triangle_count else 0 for p in self.prototypes], np.int64)
        return int(per[self.proto].sum()) if self.count else 0

    def world_vertices(self) -> np.ndarray:
        """Every instance's used prototype vertices in world space, float32 [placed_vertices, 3]
        (computed in float64 and rounded once, as the flattening loader does)."""
        out = []
        for j, p in enumerate(self.prototypes):
            sel = np.flatnonzero(self.proto == j)
            if len(sel) == 0 or p.triangle_count == 0:
                continue
            v = p.points[np.unique(p.triangles)].astype(np.float64)
            M = self.xform[sel]
            out.append((np.einsum("ijk,vk->ivj", M[:, :3, :3], v) + M[:, None, :3, 3]).reshape(-1, 3).astype(np.float32))
        return np.concatenate(out) if out else np.zeros((0, 3), np.float32)

    def corners(self) -> np.ndarray:
        """The 8 corners of every instance's world bounds, float32 [8 I, 3] (stand-ins for the
        instances' vertices where a view is fitted to casters: every instanced vertex lies in the box)."""
        lo, hi = self.world_bounds
        out = np.empty((self.count, 8, 3), np.float64)
        for k in range(8):
            out[:, k] = np.where([(k >> 0) & 1, (k >> 1) & 1, (k >> 2) & 1], hi, lo)
        return out.reshape(-1, 3).astype(np.float32)


@dataclass
class Scene:
    """A loaded stage as a world-space triangle soup plus lights and cameras.

    With ``instances`` (``load_scene(..., instancing=True)`` on a stage with PointInstancers or
    instanceable prims), the triangle soup holds only the geometry that is not instanced and
    ``instances`` the rest, each prototype once; :meth:`flattened` gives the whole soup."""

    path: str
    points: np.ndarray  # [V, 3] float32
    triangles: np.ndarray  # [T, 3] int32, counter-clockwise seen from the front
    tri_prim: np.ndarray  # [T] int32 -> prims
    tri_material: np.ndarray  # [T] int32 -> materials
    tri_uv: np.ndarray  # [T, 3, 2] float32 st per corner: where the material's opacity texture is read (its st network applied), else the mesh's st (0 without)
    tri_double_sided: np.ndarray  # [T] bool
    prims: list[str] = field(default_factory=list)
    tri_face: np.ndarray | None = None  # [T] int32: the face of its prim (faceVertexCounts order) a triangle comes from
    prim_points: np.ndarray | None = None  # [P, 2] int64: a prim's points are points[first : first + count], in its own order
    tri_closed: np.ndarray | None = None  # [T] int8: +1/-1 closed surface facing out/in, 0 open (see closed_orientation)
    tri_dynamic: np.ndarray | None = None  # [T] bool: dynamic caster (time-sampled, animated or wsoft:dynamic)
    tri_baked: np.ndarray | None = None  # [T, 3, 3] float32 baked light per corner (primvars:wsoft:bakedLight), NaN where absent
    materials: list[Material] = field(default_factory=list)
    textures: list[Texture] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)  # shadow-casting lights
    unshadowed_lights: list[Light] = field(default_factory=list)  # shadow:enable = false
    skipped_lights: list[SkippedLight] = field(default_factory=list)
    cameras: list[Camera] = field(default_factory=list)
    up_axis: str = "Y"
    meters_per_unit: float = 0.01
    time: float | None = None
    warnings: list[str] = field(default_factory=list)
    render_settings: RenderSettings | None = None  # the UsdRender settings it was loaded with (wsoft.scene.render_settings)
    render_settings_source: str = "none"  # how they were chosen: flag, metadata, GetStageRenderSettings or none
    purposes: tuple[str, ...] = ("default", "render")  # the UsdGeomImageable purposes that were loaded
    instances: Instances | None = None  # instanced geometry kept instanced (None: everything is in the soup)
    notes: list[str] = field(default_factory=list)  # what the load did that is worth knowing but is no problem (subdivision surfaces read as their cage)
    subdiv_level: int = 0  # how many times subdivision surfaces were refined (0: their control cages; wsoft.scene.subdiv)
    material_purpose: str = "full"  # the UsdShade purpose material bindings were resolved for (full or preview; else all-purpose)
    skinned: int = 0  # meshes a UsdSkel skeleton posed at the load's time code (wsoft.scene.usd_skel)
    skin_ms: float = 0.0  # the load's time posing them (blend shapes, skinning transforms, the skinning kernels)

    @property
    def triangle_count(self) -> int:
        return int(self.triangles.shape[0])

    @property
    def total_triangles(self) -> int:
        """Triangles in the world: the soup's plus those the instances place."""
        return self.triangle_count + (self.instances.instanced_triangles if self.instances is not None else 0)

    @property
    def instanced(self) -> bool:
        """Does the scene keep instances (``instances`` holds at least one)?"""
        return self.instances is not None and self.instances.count > 0

    @cached_property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World bounds of the points that triangles use, instances' bounds included (computed once:
        scenes are not edited in place)."""
        used = self.caster_points
        if len(used) == 0:
            if len(self.points) == 0:
                return np.zeros(3), np.zeros(3)
            used = self.points
        return used.min(axis=0).astype(np.float64), used.max(axis=0).astype(np.float64)

    @cached_property
    def caster_points(self) -> np.ndarray:
        """The vertices of the triangles (points no triangle uses are not casters), float32 [N, 3].
        Of an instanced scene: the soup's plus the instances' vertices in world space
        (:meth:`Instances.world_vertices`, the same points as the flattened stage's) up to
        :data:`EXACT_CASTER_POINTS` of them, beyond that the corners of every instance's world
        bounds (:meth:`Instances.corners`: every instanced vertex lies inside its box, so a view
        fitted to them still maps every caster, a little more widely)."""
        own = self.points[np.unique(self.triangles)] if self.triangle_count else np.zeros((0, 3), np.float32)
        if self.instanced:
            inst = self.instances
            extra = inst.world_vertices() if inst.placed_vertices() <= EXACT_CASTER_POINTS else inst.corners()
            return np.concatenate([own, extra]).astype(np.float32)
        return own

    def caster_mesh(self) -> tuple[np.ndarray, np.ndarray]:
        """Every triangle as (points float32 ``[V, 3]``, triangles ``[T, 3]`` into them): what a
        distant light's view tests for casters crossing its region
        (:func:`~wsoft.lightspace.fit.distant_caster_depth`). Of an instanced scene: the soup's,
        plus the 12 triangles of every instance's world bounds (:meth:`Instances.corners`: every
        instanced triangle lies inside its box). Built once (see :meth:`changed`); read-only."""
        if "_caster_mesh" in self.__dict__:
            return self.__dict__["_caster_mesh"]
        pts = np.asarray(self.points, np.float32)
        tris = np.asarray(self.triangles).reshape(-1, 3)
        if self.instanced:
            corners = self.instances.corners()
            boxes = (np.arange(len(corners) // 8, dtype=np.int64)[:, None, None] * 8 + np.array(BOX_TRIANGLES, np.int64)[None]).reshape(-1, 3)
            tris = np.concatenate([tris.astype(np.int64), boxes + len(pts)])
            pts = np.concatenate([pts, corners]).astype(np.float32)
        self.__dict__["_caster_mesh"] = (pts, tris)
        return pts, tris

    @property
    def diagonal(self) -> float:
        lo, hi = self.bounds
        return max(float(np.linalg.norm(hi - lo)), 1e-6)

    def cutout_triangle_counts(self) -> dict[str, int]:
        """Material path -> number of triangles using that cutout material (the instances' included:
        a prototype's triangles once per instance)."""
        counts = np.bincount(self.tri_material, minlength=len(self.materials)).astype(np.int64) if self.triangle_count else np.zeros(len(self.materials), np.int64)
        if self.instanced:
            per = np.bincount(self.instances.proto, minlength=len(self.instances.prototypes))
            for p, n in zip(self.instances.prototypes, per):
                if n and p.triangle_count:
                    counts += n * np.bincount(p.tri_material, minlength=len(self.materials)).astype(np.int64)[: len(counts)]
        out: dict[str, int] = {}
        for i, m in enumerate(self.materials):  # a UDIM material's tiles are materials of one path
            if m.is_cutout and counts[i] > 0:
                out[m.path] = out.get(m.path, 0) + int(counts[i])
        return out

    @property
    def has_cutouts(self) -> bool:
        return bool(self.cutout_triangle_counts())

    def dynamic_prims(self) -> list[str]:
        """Prims whose triangles are dynamic casters."""
        if self.tri_dynamic is None or not self.tri_dynamic.any():
            return []
        return [self.prims[i] for i in np.unique(self.tri_prim[self.tri_dynamic])]

    def subset(self, tri_mask: np.ndarray) -> "Scene":
        """A scene of the selected triangles only (same points, materials, lights and cameras)."""
        from dataclasses import replace

        m = np.asarray(tri_mask, bool)
        pick = lambda a: None if a is None else a[m]  # noqa: E731
        sub = replace(
            self, triangles=self.triangles[m], tri_prim=self.tri_prim[m], tri_material=self.tri_material[m], tri_uv=self.tri_uv[m],
            tri_double_sided=self.tri_double_sided[m], tri_closed=pick(self.tri_closed), tri_face=pick(self.tri_face), tri_dynamic=pick(self.tri_dynamic), tri_baked=pick(self.tri_baked),
        )
        sub.changed()
        return sub

    def translated(self, offset) -> "Scene":
        """The scene moved by ``offset`` (world units, float64 [3]): points, lights, cameras and
        instances' placements, computed in float64 and rounded once to float32 (an ``offset`` that
        is float32-representable and near the points moves them exactly). How a render works in a
        frame local to what it sees (:func:`wsoft.pipeline.framing.local_origin`). Built once per
        offset and kept on the scene."""
        from dataclasses import replace

        d = np.asarray(offset, np.float64).reshape(3)
        cache = self.__dict__.setdefault("_translated", {})
        key = tuple(float(x) for x in d)
        if key in cache:
            return cache[key]

        def move_light(l: Light) -> Light:
            return replace(l, position=np.asarray(l.position, np.float64) + d)

        def move_camera(c: Camera) -> Camera:
            m = np.array(c.to_world, np.float64)
            m[:3, 3] += d
            return replace(c, to_world=m)

        inst = self.instances
        if inst is not None:
            xf = np.array(inst.xform, np.float64)
            xf[:, :3, 3] += d
            inst = replace(inst, xform=xf)
        moved = replace(self, points=(self.points.astype(np.float64) + d).astype(np.float32), lights=[move_light(l) for l in self.lights],
                        unshadowed_lights=[move_light(l) for l in self.unshadowed_lights], cameras=[move_camera(c) for c in self.cameras],
                        instances=inst, warnings=list(self.warnings))
        cache[key] = moved
        return moved

    def casting_mask(self, light: Light) -> np.ndarray | None:
        """Which triangles cast ``light``'s shadow (bool ``[T]``): those of prims its
        ``collection:shadowLink`` includes. None when every triangle does (no exclusion: the common
        case, which adds no pass and no test). Computed once per light (see :meth:`changed`)."""
        if not light.shadow_excluded:
            return None
        cache = self.__dict__.setdefault("_casting", {})
        key = (light.path, light.shadow_excluded)
        if key not in cache:
            cache[key] = ~np.isin(self.tri_prim, np.asarray(light.shadow_excluded, np.int32))
        return cache[key]

    def casting_triangles(self, light: Light) -> np.ndarray | None:
        """The indices (int32) of the triangles that cast ``light``'s shadow; None: every triangle."""
        m = self.casting_mask(light)
        return None if m is None else np.flatnonzero(m).astype(np.int32)

    def dynamic_subset(self) -> "Scene":
        """The dynamic casters as a scene of their own (built once; see :meth:`changed`)."""
        if "_dynamic_subset" not in self.__dict__:
            self.__dict__["_dynamic_subset"] = self.subset(self.tri_dynamic)
        return self.__dict__["_dynamic_subset"]

    def device_copy(self, device: str, build):
        """This scene's arrays on ``device`` (a DeviceScene), built once by ``build(scene, device)``.

        Renders of the same Scene object reuse the BVH and arrays. After editing the scene's
        arrays in place, call :meth:`changed`.
        """
        cache = self.__dict__.setdefault("_device_cache", {})
        if device not in cache:
            cache[device] = build(self, device)
            return cache[device], False
        return cache[device], True

    def changed(self) -> None:
        """Forget device copies and derived values after the arrays were edited in place (and the
        stage :meth:`flattened` would load again: it flattens the edited arrays instead)."""
        for k in ("_device_cache", "bounds", "caster_points", "_dynamic_subset", "_casting", "_flattened", "_source", "_adjacency", "_translated", "_caster_mesh"):
            self.__dict__.pop(k, None)
        if self.instances is not None:
            self.instances.__dict__.pop("world_bounds", None)

    def flattened(self) -> "Scene":
        """The whole scene as one triangle soup: what ``load_scene(..., instancing=False)`` gives
        (same time, render settings and purposes). ``self`` when nothing is instanced. A scene
        :func:`~wsoft.scene.usd.load_scene` returned carries how to load its stage again, flat (a
        callable, ``_source``); a scene built by hand (or edited, see :meth:`changed`) has its
        instances flattened here (:meth:`_flatten_instances`). Built once."""
        if not self.instanced:
            return self
        if "_flattened" not in self.__dict__:
            load_flat = self.__dict__.get("_source")
            flat = load_flat() if load_flat is not None else self._flatten_instances()
            self.__dict__["_flattened"] = flat
        return self.__dict__["_flattened"]

    def _flatten_instances(self) -> "Scene":
        """:meth:`flattened` in numpy: the soup, then every instance's prototype triangles moved to the
        world by its transform (float32 points, as the loader keeps them), their winding flipped where
        the transform mirrors and zero-area triangles dropped (as the loader drops them). Instanced
        meshes are named as the flat loader names them (``mesh@instancer[i]``, or the instance proxy's
        path); a light's ``shadow_excluded`` leaves out the meshes of the prims it left out."""
        from dataclasses import replace

        inst = self.instances
        soup_prims = np.ones(len(self.prims), bool)
        for proto in inst.prototypes:
            soup_prims[proto.tri_prim] = False
            if proto.prim_points is not None:
                soup_prims[proto.prim_points[:, 0]] = False
        soup_prims[inst.prim] = False
        soup_prims[np.unique(self.tri_prim)] = True
        old_ids = np.flatnonzero(soup_prims)
        remap = np.full(len(self.prims), -1, np.int64)
        remap[old_ids] = np.arange(len(old_ids))
        prims = [self.prims[i] for i in old_ids]
        old_pp = self.prim_points if self.prim_points is not None and len(self.prim_points) == len(self.prims) else None
        prim_points = [tuple(old_pp[i]) for i in old_ids] if old_pp is not None else []
        n_soup = self.triangle_count
        baked_any = self.tri_baked is not None or any(p.tri_baked is not None for p in inst.prototypes)
        parts = {k: [] for k in ("pts", "tris", "prim", "mat", "uv", "ds", "cl", "dyn", "bk", "face")}
        parts["pts"].append(self.points.astype(np.float32))
        parts["tris"].append(self.triangles.astype(np.int64))
        parts["prim"].append(remap[self.tri_prim] if n_soup else np.zeros(0, np.int64))
        parts["mat"].append(self.tri_material)
        parts["uv"].append(self.tri_uv)
        parts["ds"].append(self.tri_double_sided)
        parts["cl"].append(self.tri_closed if self.tri_closed is not None else np.zeros(n_soup, np.int8))
        parts["dyn"].append(self.tri_dynamic if self.tri_dynamic is not None else np.zeros(n_soup, bool))
        parts["bk"].append(self.tri_baked if self.tri_baked is not None else np.full((n_soup, 3, 3), np.nan, np.float32))
        parts["face"].append(self.tri_face if self.tri_face is not None else np.zeros(n_soup, np.int32))
        excluded_of = {}  # flat prim index -> (prototype mesh prim, instance prim) it comes from
        nverts = len(self.points)
        for k in range(inst.count):
            proto = inst.prototypes[int(inst.proto[k])]
            if proto.triangle_count == 0:
                continue
            M = inst.xform[k]
            with np.errstate(over="ignore", invalid="ignore"):
                pw = (proto.points.astype(np.float64) @ M[:3, :3].T + M[:3, 3]).astype(np.float32)
            # a mirroring instance: the winding flips in the world (the corners, and what is per corner)
            flip = [0, 2, 1] if np.linalg.det(M[:3, :3]) < 0 else [0, 1, 2]
            tris = proto.triangles.astype(np.int64)[:, flip]
            q = pw.astype(np.float64)[tris]
            keep = np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1) > 0.0
            where = self.prims[int(inst.prim[k])]
            # one flat prim per prototype mesh prim, named as the flat loader names it
            mesh_ids = np.unique(proto.tri_prim)
            local = np.full(int(mesh_ids.max()) + 1, -1, np.int64)
            for m in mesh_ids:
                name = self.prims[int(m)]
                if inst.instance_id[k] >= 0:
                    name = f"{name}@{where}[{int(inst.instance_id[k])}]"
                elif proto.root and name.startswith(proto.root):
                    name = where + name[len(proto.root):]
                local[m] = len(prims)
                excluded_of[len(prims)] = (int(m), int(inst.prim[k]))
                prims.append(name)
                first, count = 0, 0
                if proto.prim_points is not None:
                    row = proto.prim_points[proto.prim_points[:, 0] == m]
                    if len(row):
                        first, count = int(row[0, 1]) + nverts, int(row[0, 2])
                prim_points.append((first, count))
            n = int(keep.sum())
            parts["pts"].append(pw)
            parts["tris"].append(tris[keep] + nverts)
            nverts += len(pw)
            parts["prim"].append(local[proto.tri_prim[keep]])
            parts["mat"].append(proto.tri_material[keep])
            parts["uv"].append(proto.tri_uv[keep][:, flip])
            parts["ds"].append(proto.tri_double_sided[keep])
            parts["cl"].append(proto.tri_closed[keep])
            dyn = proto.tri_dynamic[keep] if proto.tri_dynamic is not None else np.zeros(n, bool)
            parts["dyn"].append(dyn | bool(inst.dynamic[k]))
            parts["bk"].append(proto.tri_baked[keep][:, flip] if proto.tri_baked is not None else np.full((n, 3, 3), np.nan, np.float32))
            parts["face"].append(proto.tri_face[keep])

        lights = []
        for light in self.lights:
            if light.shadow_excluded:
                out = set(light.shadow_excluded)
                ex = [int(remap[i]) for i in light.shadow_excluded if remap[i] >= 0]
                ex += [j for j, (m, w) in excluded_of.items() if m in out or w in out]
                light = replace(light, shadow_excluded=tuple(sorted(ex)))
            lights.append(light)
        cat = np.concatenate
        flat = replace(
            self, points=cat(parts["pts"]).astype(np.float32), triangles=cat(parts["tris"]).astype(np.int32).reshape(-1, 3),
            tri_prim=cat(parts["prim"]).astype(np.int32), tri_material=cat(parts["mat"]).astype(np.int32),
            tri_uv=cat(parts["uv"]).astype(np.float32).reshape(-1, 3, 2), tri_double_sided=cat(parts["ds"]).astype(bool),
            tri_closed=cat(parts["cl"]).astype(np.int8), tri_dynamic=cat(parts["dyn"]).astype(bool),
            tri_baked=cat(parts["bk"]).astype(np.float32) if baked_any else None, tri_face=cat(parts["face"]).astype(np.int32),
            prims=prims, prim_points=np.asarray(prim_points, np.int64).reshape(-1, 2) if old_pp is not None else None,
            lights=lights, warnings=list(self.warnings), instances=None,
        )
        return flat

    def light_label(self, light: Light) -> str:
        """How channels and stats name a light: its prim name, or its path when two lights share the name."""
        names = [l.name for l in self.lights]
        return light.name if names.count(light.name) == 1 else light.path

    def find_light(self, path_or_name: str) -> Light:
        for light in self.lights:
            if path_or_name in (light.path, light.name):
                return light
        known = [l.path for l in self.lights]
        off = [l.path for l in self.unshadowed_lights] + [s.path for s in self.skipped_lights]
        msg = f"no shadow-casting light {path_or_name!r}; shadow-casting lights: {', '.join(known) or 'none'}"
        if path_or_name in off or any(p.endswith("/" + path_or_name) for p in off):
            msg += " (that light casts no shadow or is not handled; see `wsoft plan`)"
        from wsoft.errors import ParameterError

        raise ParameterError(msg, file=self.path)

    def find_camera(self, path: str) -> Camera:
        for cam in self.cameras:
            if cam.path == path:
                return cam
        from wsoft.errors import ParameterError

        raise ParameterError(
            f"no camera {path!r}; cameras: {', '.join(c.path for c in self.cameras) or 'none'}", file=self.path
        )
