"""Cube maps: six 90° light views around a local light that surrounds its receivers.

A sphere, point or cylinder light emits all around. One perspective frustum holds its receivers
only while they lie within :data:`CUBE_THRESHOLD_DEG` of one axis (:func:`frustum_half_angle`);
beyond it the light view is a **cube map** (:func:`cube_decision`): six faces along the light's
own frame (:func:`cube_frame`), each a perspective :class:`~wsoft.lightspace.view.LightView` of
square window ``[-T, T]^2`` in tangents. A receiver belongs to the face of the dominant axis of
its direction from the light's centre (:func:`owner_faces`, :func:`owner_face` on the device);
every face holds its own receivers whole, so a technique's passes run unchanged on each face (a
:class:`CubeFace` is the light as one face sees it) and :func:`select_cube_face` takes each
receiver's visibility from its face.

**Seams.** A face's window reaches past its 90° (``T > 1``) by a *guard band*, the same for the
six faces of a light (the same texel size at every edge): at least the technique's widest kernel
in texels (:meth:`~wsoft.techniques.Technique.cube_guard_texels`), and for a soft view the growth
that maps every caster that can block part of the light from a face's receivers (as
:func:`~wsoft.lightspace.fit.fit_light_view` widens one frustum), up to :data:`GUARD_MAX`. Taps,
blocker searches and blur kernels that cross a face's edge then read that face's own texels of the
neighbouring directions: no cube-map direction lookup is needed, and no technique's kernel changes.

**Depth.** Each face stores linear depth along its own axis, as every perspective light view does:
receiver-plane depth, a blocker's spread ``w (1/z_b - 1/z_r)`` and texel coordinates are the
maths each technique already has for one frustum; distance to the light's centre would need
another form of each.

Faces without receivers are not drawn (:func:`cube_decision` keeps only the faces whose guard-band
window holds a receiver). A face's near plane lies outside the light's bound (its enclosing ball),
unless a receiver lies nearer."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import warp as wp

from wsoft.lightspace.light import reached_receivers
from wsoft.lightspace.view import LightView, frame_extent_of_bounds, to_frame
from wsoft.scene.types import LIGHT_CYLINDER, LIGHT_POINT, LIGHT_SPHERE, Light

CUBE_THRESHOLD_DEG = 75.0
"""A local light whose receivers need a single frustum opened more than this many degrees off its
axis gets a cube map (``cube=auto``). Chosen by measurement (``wsoft bench cube``, receivers spread
from 30° to 79° off a sphere light's axis, 512² maps): up to 70° one frustum is as accurate as a
cube map for ``hard`` and ``pcss`` and more accurate for the kernels sized in texels (``pcf``
penumbra MAE 0.111 against 0.140 at 70°: a cube face's texels are coarser than a fitted
frustum's), at about half the cost; at 79° a frustum's window, capped at ±80°, leaves 4 % of the
receivers out. The threshold sits between, short of the cap."""
CUBE_KINDS = (LIGHT_SPHERE, LIGHT_POINT, LIGHT_CYLINDER)
"""Lights that emit all around and so may surround their receivers. Rect and disk lights emit
through the hemisphere in front of them, which one frustum of at most ±80° holds but for its
grazing rim."""
FACE_NAMES = ("+x", "-x", "+y", "-y", "+z", "-z")
GUARD_OVERRIDE: float | None = None
"""The guard band forced to this many tangents for every cube map (None: each technique's, as
:func:`fit_cube_views` sizes it): how ``wsoft bench cube`` measures the seams without one."""
GUARD_MAX = 0.5
"""The widest guard band, in tangents past a face's edge (a face then spans ±56.3°): a wider one
would spread a face's texels over directions its neighbours already hold."""


@dataclass
class CubeFace(Light):
    """A light as one face of its cube map sees it: the same light (every field of it), and the
    face (an index into :data:`FACE_NAMES`). Techniques register their passes for it as for any
    light; its light view is the face's (:meth:`~wsoft.pipeline.context.RenderContext.light_view`)."""

    face: int = 0
    base_path: str = ""

    @staticmethod
    def of(light: Light, face: int) -> "CubeFace":
        values = {f.name: getattr(light, f.name) for f in dataclasses.fields(Light)}
        return CubeFace(**values, face=int(face), base_path=light.path)

    @property
    def face_name(self) -> str:
        return FACE_NAMES[self.face]


def cube_frame(light: Light) -> np.ndarray:
    """The cube's axes (3 x 3, columns): the light's frame, made right-handed (a mirrored frame's
    third axis turned)."""
    f = np.asarray(light.frame, np.float64).copy()
    f /= np.maximum(np.linalg.norm(f, axis=0), 1e-300)
    if np.linalg.det(f) < 0.0:
        f[:, 2] = -f[:, 2]
    return f


def face_axes(frame: np.ndarray, face: int) -> np.ndarray:
    """The view axes (columns x, y, view axis) of face ``face``: view axis ``±frame[:, i]``
    (``i = face // 2``, minus for odd faces), x and y the next two axes of the frame, right-handed."""
    i, s = face // 2, (-1.0 if face % 2 else 1.0)
    z = s * frame[:, i]
    x = frame[:, (i + 1) % 3]
    y = s * frame[:, (i + 2) % 3]
    return np.stack([x, y, z], axis=1)


def owner_faces(d: np.ndarray) -> np.ndarray:
    """The face each direction (rows of ``d``, in the cube's frame) belongs to: its dominant axis,
    ``2 i`` when positive, ``2 i + 1`` when negative (ties go to the lower axis)."""
    d = np.asarray(d, np.float64).reshape(-1, 3)
    i = np.argmax(np.abs(d), axis=1)
    neg = np.take_along_axis(d, i[:, None], axis=1)[:, 0] < 0.0
    return (2 * i + neg).astype(np.int32)


@wp.func
def owner_face(frame: wp.mat33, d: wp.vec3) -> int:
    """:func:`owner_faces` on the device: ``frame``'s rows are the cube's axes."""
    q = frame * d
    ax = wp.abs(q[0])
    ay = wp.abs(q[1])
    az = wp.abs(q[2])
    i = int(0)
    v = q[0]
    if ay > ax and ay >= az:
        i = 1
        v = q[1]
    elif az > ax and az > ay:
        i = 2
        v = q[2]
    return 2 * i + wp.where(v < 0.0, 1, 0)


def frustum_half_angle(light: Light, receivers: np.ndarray) -> float:
    """Degrees off its axis the single frustum that holds ``receivers`` must open (its axis toward
    their mean, as :func:`~wsoft.lightspace.fit.fit_light_view` aims it; each side's tangent the
    largest of the receivers' ``|x| / z``, ``|y| / z``): 180 when a receiver lies behind the light
    (beside or behind its centre), 0 with no receiver."""
    from wsoft.lightspace.fit import omni_axes

    rec = np.asarray(receivers, np.float64).reshape(-1, 3)
    if len(rec) == 0:
        return 0.0
    origin = np.asarray(light.position, np.float64)
    d = rec.mean(axis=0) - origin
    axes = omni_axes(light, d if np.linalg.norm(d) > 0.0 else -np.asarray(light.frame, np.float64)[:, 2])
    v = to_frame(rec, origin, axes)
    ext = float(np.linalg.norm(rec.max(axis=0) - rec.min(axis=0))) or 1.0
    v = v[np.linalg.norm(v, axis=1) > 1e-9 * ext]  # a receiver at the light's centre has no direction
    if len(v) == 0:
        return 0.0
    if np.any(v[:, 2] <= 0.0):
        return 180.0
    tan = float(np.max(np.maximum(np.abs(v[:, 0]), np.abs(v[:, 1])) / v[:, 2]))
    return math.degrees(math.atan(tan))


@dataclass
class CubeDecision:
    """Whether a light's views form a cube map, and why (``wsoft plan`` shows it): ``half_angle``
    the single frustum's (degrees, :func:`frustum_half_angle`), ``faces`` the faces holding
    receivers (indices into :data:`FACE_NAMES`), ``probe`` the samples it was decided from."""

    light_path: str
    eligible: bool  # a kind that may surround its receivers (CUBE_KINDS)
    half_angle: float
    faces: tuple[int, ...]
    probe: str
    cone: float = 180.0  # shaping:cone:angle (degrees off its axis; 180: no cone): receivers it does not reach are left out

    def cube(self, mode: str) -> bool:
        """Does a technique with ``cube=mode`` draw a cube map of this light?"""
        if not self.eligible or mode == "never" or not self.faces:
            return False
        return mode == "always" or self.half_angle > CUBE_THRESHOLD_DEG

    def why(self, mode: str) -> str:
        """One line: one frustum or a cube map, and the receivers' spread that decided it."""
        if not self.eligible:
            return "one frustum (a rect, disk or distant light emits through one hemisphere or cone)"
        spread = ("receivers beside or behind its centre" if self.half_angle >= 180.0
                  else f"receivers up to {self.half_angle:.0f} degrees off one axis")
        if self.cube(mode) and self.cone < 180.0:
            spread = f"its cone (shaping:cone:angle {self.cone:g}) reaches {spread}"
        if self.cube(mode):
            reason = "cube=always" if self.half_angle <= CUBE_THRESHOLD_DEG else f"{spread} (one frustum holds {CUBE_THRESHOLD_DEG:g} at most)"
            return f"cube map, {len(self.faces)} of 6 faces ({', '.join(FACE_NAMES[k] for k in self.faces)}): {reason}"
        if mode == "never" and self.half_angle > CUBE_THRESHOLD_DEG:
            return f"one frustum (cube=never), with {spread}: those beyond 80 degrees are left lit, with a warning"
        if not self.faces:
            return "one frustum (no receiver in view" + (f" that its {self.cone:g}-degree cone reaches)" if self.cone < 180.0 else ")")
        if self.cone < 180.0:
            return (f"one frustum: its cone (shaping:cone:angle {self.cone:g}) reaches receivers up to {self.half_angle:.0f} "
                    f"degrees off one axis (one frustum holds {CUBE_THRESHOLD_DEG:g}); those outside it have none of its light")
        return f"one frustum: {spread}"


def cube_decision(light: Light, receivers: np.ndarray, probe: str) -> CubeDecision:
    """Decide from ``receivers`` (world points, a low-resolution G-buffer's) whether ``light``'s
    views form a cube map, and which faces hold receivers: a face is kept when a receiver's
    direction lies within its window widened by :data:`GUARD_MAX` (a receiver near an edge the
    probe saw on one side may have neighbours on the other). A shaped light decides from the
    receivers its cone reaches (:func:`~wsoft.lightspace.light.reached_receivers`): a narrow cone's
    receivers fit one frustum."""
    eligible = light.kind in CUBE_KINDS
    rec = reached_receivers(light, np.asarray(receivers, np.float64).reshape(-1, 3))
    if not eligible:
        return CubeDecision(light.path, False, 0.0, (), probe, light.shaping.cone_deg)
    angle = frustum_half_angle(light, rec)
    frame = cube_frame(light)
    faces = []
    if len(rec):
        q = to_frame(rec, np.asarray(light.position, np.float64), frame)
        for k in range(6):
            v = q @ face_axes(np.eye(3), k)
            z = v[:, 2]
            inside = (z > 0.0) & (np.abs(v[:, 0]) <= (1.0 + GUARD_MAX) * z) & (np.abs(v[:, 1]) <= (1.0 + GUARD_MAX) * z)
            if inside.any():
                faces.append(k)
    return CubeDecision(light.path, True, angle, tuple(faces), probe, light.shaping.cone_deg)


def outside_view_remedy(light: Light, decision: CubeDecision | None, unmapped: list[str], no_cube: str = "") -> str:
    """What a user can do about receivers ``light``'s single-frustum view leaves out (``decision``:
    its :class:`CubeDecision`; ``unmapped``: the techniques that draw no light map and so shadow
    every receiver): a rect or disk light's map is one frustum (no cube map is built for a light
    that emits through one hemisphere); a sphere, point or cylinder light's view was one frustum
    where the technique asked for one (``cube=never``) or the decision found no need of a cube map;
    ``no_cube``: why the technique builds no cube map at all (its ``cube_refusal``), if so."""
    others = f"{', '.join(unmapped)} draw no light map and shadow them" if unmapped else "no technique shadows them"
    if light.kind not in CUBE_KINDS:
        return (f"wsoft draws a {light.kind_name} light's map in one frustum (cube maps are built for sphere, point and cylinder "
                f"lights only): {others}")
    if no_cube:
        return f"{no_cube}: {others}"
    has = "a technique whose Params subclass wsoft.params.LightViewParams has the parameter cube"
    if decision is not None and decision.cube("auto"):
        return (f"this view is one frustum (cube=never, or a technique without the parameter): cube=auto draws a "
                f"{decision.why('auto')} ({has}), or {others}")
    why = decision.why("auto") if decision is not None else "one frustum"
    return f"cube=auto decided on {why}: cube=always draws a cube map that holds them ({has}), or {others}"


def guard_window(guard_texels: float, size: int) -> float:
    """The half-window ``T`` of a map ``size`` texels wide whose border past 1 holds ``guard_texels``
    texels: ``(T - 1) size / (2 T) = guard_texels`` (at most a quarter of the map). A cube face's
    window in tangents, a dual-paraboloid hemisphere's in paraboloid coordinates."""
    g = min(max(float(guard_texels), 0.0), 0.25 * size)
    return 1.0 / (1.0 - 2.0 * g / size)


def fit_cube_views(light: Light, receivers: np.ndarray, faces: tuple[int, ...], size: int, guard_texels: float,
                   casters: np.ndarray | None = None) -> tuple[dict[int, LightView], dict]:
    """The views of the cube map's ``faces`` (:class:`CubeDecision`) fitted to ``receivers`` (the
    frame's, world [N, 3]), each ``size`` texels a side, all with the same window ``[-T, T]^2``:
    ``T - 1`` the guard band (:func:`guard_window` of ``guard_texels``; with ``casters``, a soft
    view, at least the growth that maps every caster that can block part of the light from a
    face's receivers; at most :data:`GUARD_MAX`). Each face's depth range runs from a near plane
    outside the light's bound (or half the nearest receiver's depth, if nearer) to just past the
    farthest receiver its window holds. Returns (views by face, facts: receivers per face,
    receivers at the light's centre, the guard band, whether the soft growth was capped)."""
    from wsoft.lightspace.fit import _caster_growth
    from wsoft.lightspace.light import light_bound

    rec = np.asarray(receivers, np.float64).reshape(-1, 3)
    origin = np.asarray(light.position, np.float64)
    frame = cube_frame(light)
    lo = rec.min(axis=0) if len(rec) else None
    hi = rec.max(axis=0) if len(rec) else None
    ext = frame_extent_of_bounds(lo, hi, light)
    q = to_frame(rec, origin, frame)
    at_light = np.linalg.norm(q, axis=1) <= 1e-7 * ext
    owner = owner_faces(q)
    owner[at_light] = -1
    T = guard_window(guard_texels, size)
    capped = False
    _, bound, _ = light_bound(light)
    w = light.extent()
    per_face = {}
    for k in faces:
        axes = face_axes(frame, k)
        v = q @ face_axes(np.eye(3), k)
        own = v[owner == k]
        per_face[k] = (axes, v, own)
        if casters is not None and w > 0.0 and len(own):
            g = _caster_growth(np.asarray(casters).reshape(-1, 3), origin, axes, (-1.0, 1.0, -1.0, 1.0), w, 1e-3 * ext,
                               float(own[:, 2].max()))
            if g is not None:
                if 1.0 + g > 1.0 + GUARD_MAX:
                    capped = True
                T = max(T, min(1.0 + g, 1.0 + GUARD_MAX))
    if GUARD_OVERRIDE is not None:
        T = 1.0 + float(GUARD_OVERRIDE)
    views = {}
    for k in faces:
        axes, v, own = per_face[k]
        z = v[:, 2]
        held = (z > 0.0) & (np.abs(v[:, 0]) <= T * z) & (np.abs(v[:, 1]) <= T * z)
        near = max(1.0001 * bound, 1e-4 * ext, 1e-7)
        if len(own):
            near = min(near, 0.5 * float(own[:, 2].min()))
        zmax = float(z[held].max()) if held.any() else ext
        far = zmax * 1.01 + 1e-3 * ext
        views[k] = LightView(light_path=light.path, persp=True, origin=origin.copy(), axes=axes, window=(-T, T, -T, T),
                             near=float(near), far=float(max(far, 2.0 * near)), width=size, height=size, receivers_outside=0,
                             extent=ext, growth=float(T - 1.0), face=int(k))
    facts = {"receivers": {FACE_NAMES[k]: int(np.count_nonzero(owner == k)) for k in faces}, "at_light": int(at_light.sum()),
             "guard": float(T - 1.0), "guard_capped": capped}
    return views, facts


vec6i = wp.types.vector(length=6, dtype=wp.int32)


@wp.func
def face_value(k: int, f0: wp.array[float], f1: wp.array[float], f2: wp.array[float], f3: wp.array[float], f4: wp.array[float],
               f5: wp.array[float], i: int) -> float:
    """Sample ``i`` of face ``k``'s visibility."""
    if k == 0:
        return f0[i]
    if k == 1:
        return f1[i]
    if k == 2:
        return f2[i]
    if k == 3:
        return f3[i]
    if k == 4:
        return f4[i]
    return f5[i]


@wp.kernel
def select_cube_face(
    offset: int,
    pos: wp.array[wp.vec3],
    prim: wp.array[wp.int32],
    origin: wp.vec3,
    frame: wp.mat33,
    drawn: vec6i,
    f0: wp.array[float],
    f1: wp.array[float],
    f2: wp.array[float],
    f3: wp.array[float],
    f4: wp.array[float],
    f5: wp.array[float],
    eps: float,
    # outputs
    vis: wp.array[float],
    face_of: wp.array[wp.int32],
):
    """Per G-buffer sample, the visibility its own face gave (face ``k``'s in ``fk``; ``drawn[k]``
    >= 0 where face ``k`` was drawn; ``frame``'s rows are the cube's axes). ``face_of``: the face;
    6 for background (V = 1), -1 for a sample at the light's centre (no direction: V = 1), -2 for one
    whose face was not drawn (V = 1)."""
    i = wp.tid() + offset
    if prim[i] < 0:
        vis[i] = 1.0
        face_of[i] = 6
        return
    d = pos[i] - origin
    if wp.length(d) <= eps:
        vis[i] = 1.0
        face_of[i] = -1
        return
    k = owner_face(frame, d)
    if drawn[k] < 0:
        vis[i] = 1.0
        face_of[i] = -2
        return
    vis[i] = face_value(k, f0, f1, f2, f3, f4, f5, i)
    face_of[i] = k
