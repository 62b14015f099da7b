"""Per-S-triangle maths of the soft textured shadow volume (Forest, Barthe, Guennebaud and Paulin
2009, §2, Algorithm 1, equations 1–5): the transmittance lookup of a perforated triangle between a
receiver and a light sample, and the triangle's conservative shadow volume for an area light.

``@wp.func``s for the techniques' kernels (``pwedge`` and ``dcs`` call them for their perforated
triangles), with thin NumPy-in / NumPy-out wrappers for tests.

**How equations 1–5 are read.** A triangle ``v0 v1 v2`` with texture coordinates ``t0 t1 t2``
and *unit* normal ``n = normalize((v1 - v0) x (v2 - v0))``:

* (2) ``M' = [v0v1 | v0v2 | -n]^-1``: world vectors to triangle coordinates ``(u, v, g)`` with
  ``w = u v0v1 + v v0v2 - g n``. It is linear, so ``J = W M'`` acts on the light sample *relative
  to the receiver*, ``s - p`` (a 3x3 matrix cannot translate; the paper's ``J . s`` only makes
  sense with ``s`` taken from ``p``, the projective centre).
* ``e`` is the *signed* distance ``(p - v0) . n`` = ``(M' (v0 - p)).z``; the paper's "orthogonal
  distance" is its magnitude, but the sign is what lets one formula serve receivers on both sides.
  (The paper's ``k``, the light's distance to the plane, appears in no equation.)
* (3) ``W = [[1, 0, -c.x/e], [0, 1, -c.y/e], [0, 0, 1/e]]`` with ``c = M' (v0 - p)``. The paper
  prints the last row as ``(0, 0, 1)``; with it ``s*_h = (u/t, v/t, e/t)`` (``t`` the segment
  parameter where ``p + t (s - p)`` meets the plane, ``(u, v)`` its barycentrics), whose inside
  test ``z >= x + y`` would read ``e >= u + v`` and whose projection (5) would give
  ``texcoord / e``. With ``1/e``, ``s*_h = (u, v, 1) / t``: homogeneous barycentrics, as the text
  says, and (4)–(5) give the texture coordinate exactly. We take the printed row as a slip.
* The occlusion test: ``x >= 0, y >= 0, z >= x + y`` (the paper's; it implies ``z >= 0``, so a
  sample on ``p``'s side of the plane, ``t < 0``, fails it) plus ``z >= 1``, i.e. ``t <= 1``: the
  crossing lies between ``p`` and the light sample (the paper relies on the volume for that).
* (4)–(5) ``s' = (S s*_h).xy / (S s*_h).z`` with ``S = [[t0t1.x, t0t2.x, t0.x], [t0t1.y, t0t2.y,
  t0.y], [0, 0, 1]]``; ``(S s*_h).z = s*_h.z``. Barycentric weights of the corners are
  ``(z - x - y, x, y) / z``, which is what :func:`wsoft.scene.surfaces.surface_present` takes.

**The volume** (§2.2, §2.3, §6) is kept as up to five half-spaces ``a . x + b <= 0`` (rows of a
5x4 matrix; an all-zero row is no constraint), each *provably* conservative for a light inside a
ball (local lights: centre and radius, :func:`light_ball`) or a cone of directions (distant):

* the three outer planes of the penumbra wedges: through an edge, tangent to the light's bound
  with the bound on the positive side and the triangle on the negative side. A shadowed point is
  ``l + s (y - l)``, ``s >= 1``, ``l`` in the light, ``y`` on the triangle, so it is on the
  negative side. When no such plane exists (the light's bound reaches the edge's line, or the
  tangent plane would cut the triangle) the row is left empty;
* the front cap: the paper moves the vertices farther from the light centre toward it until all
  are as far as the nearest (``t'``); its plane bounds the volume when the light's bound lies
  wholly in front of it (else the row is empty). Distant lights: the plane perpendicular to the
  direction through the vertex nearest the light (always valid: every direction of the cone has a
  positive component along the axis);
* the triangle's own plane, facing the light side the volume is for.

The paper's back cap closes the volume for z-fail rasterization (its extruded corners and far
triangle); here every receiver is tested against the half-spaces themselves, an open volume is
a complete test, and no back cap is built.

**Both sides** (§6): a volume is built for the side of the triangle's plane the light centre is on
(side ``+1`` when the centre is in front of the normal); when the light's bound straddles the plane
(both faces lit), a second volume for the other side, bounded by the ball (or cone) of the part
of the light beyond the plane. :func:`lit_sides` says which: bit 0 side ``+1``, bit 1 side ``-1``.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from wsoft.lightspace.light import LightGPU, bound_radius, light_gpu
from wsoft.scene.surfaces import Surfaces, sample_alpha

planes_t = wp.types.matrix(shape=(5, 4), dtype=wp.float32)
"""A shadow volume: five half-spaces ``row . (x, y, z, 1) <= 0`` (a zero row: none)."""


@wp.struct
class STriangle:
    """Per-S-triangle constants of equation 1: ``Mp`` (M', eq. 2), ``S`` (eq. 4), a corner and the
    unit normal. ``ok = 0`` for a zero-area triangle (it occludes nothing)."""

    v0: wp.vec3
    n: wp.vec3
    Mp: wp.mat33
    S: wp.mat33
    ok: int


@wp.func
def s_triangle(v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, t0: wp.vec2, t1: wp.vec2, t2: wp.vec2) -> STriangle:
    """The constants of a perforated triangle (eqs. 2 and 4)."""
    st = STriangle()
    e1 = v1 - v0
    e2 = v2 - v0
    c = wp.cross(e1, e2)
    ln = wp.length(c)
    st.v0 = v0
    st.ok = 0
    st.S = wp.mat33(t1[0] - t0[0], t2[0] - t0[0], t0[0], t1[1] - t0[1], t2[1] - t0[1], t0[1], 0.0, 0.0, 1.0)
    if ln > 0.0:
        n = c / ln
        st.n = n
        st.Mp = wp.inverse(wp.mat33(e1[0], e2[0], -n[0], e1[1], e2[1], -n[1], e1[2], e2[2], -n[2]))
        st.ok = 1
    return st


@wp.func
def receiver_matrix(st: STriangle, p: wp.vec3) -> wp.mat33:
    """``J = W M'`` (eqs. 1 and 3) for receiver ``p``; it maps ``s - p`` to ``s*_h``. Zero when
    ``p`` lies on the triangle's plane or the triangle has no area (nothing is occluded)."""
    c = st.Mp * (st.v0 - p)
    e = c[2]
    if st.ok == 0 or e == 0.0:
        return wp.mat33(0.0)
    ie = 1.0 / e
    W = wp.mat33(1.0, 0.0, -c[0] * ie, 0.0, 1.0, -c[1] * ie, 0.0, 0.0, ie)
    return W * st.Mp


@wp.func
def sample_bary(J: wp.mat33, p: wp.vec3, s: wp.vec3) -> wp.vec3:
    """``s*_h = J (s - p)``: homogeneous barycentrics ``(u, v, 1) / t`` of the point where the
    segment from ``p`` to the light sample ``s`` meets the triangle's plane."""
    return J * (s - p)


@wp.func
def crosses(h: wp.vec3) -> bool:
    """Does the segment cross the triangle (inside or on an edge) between ``p`` and the sample?"""
    return h[0] >= 0.0 and h[1] >= 0.0 and h[2] >= h[0] + h[1] and h[2] >= 1.0


@wp.func
def sample_texcoord(st: STriangle, h: wp.vec3) -> wp.vec2:
    """Equations 4–5: the texture coordinate of ``s*_h`` (``h.z > 0``)."""
    sh = st.S * h
    return wp.vec2(sh[0] / sh[2], sh[1] / sh[2])


@wp.func
def sample_blocked(cut: Surfaces, tri: int, st: STriangle, J: wp.mat33, p: wp.vec3, s: wp.vec3) -> bool:
    """Algorithm 1's ``texture_access`` for a perforated triangle: is the light sample ``s`` hidden
    from ``p`` by triangle ``tri``? The crossing (eq. 1), then the cutout's alpha at eq. 5's texture
    coordinate against its threshold (:func:`~wsoft.scene.surfaces.surface_present`'s rule)."""
    h = sample_bary(J, p, s)
    if not crosses(h):
        return False
    c = cut.tri_cut[tri]
    if c < 0:
        return True
    alpha = cut.opacity[c]
    t = cut.tex[c]
    if t >= 0:
        alpha = sample_alpha(cut, t, sample_texcoord(st, h))
    return alpha >= cut.threshold[c]


@wp.func
def sample_transmittance(cut: Surfaces, tri: int, st: STriangle, J: wp.mat33, p: wp.vec3, s: wp.vec3) -> float:
    """The paper's general case: the share of the light sample ``s`` that triangle ``tri`` lets
    through to ``p``, ``1 - alpha`` at eq. 5's texture coordinate (alpha clamped to [0, 1]; the
    material's threshold is not applied), 1 where the segment misses the triangle."""
    h = sample_bary(J, p, s)
    if not crosses(h):
        return 1.0
    c = cut.tri_cut[tri]
    if c < 0:
        return 0.0
    alpha = cut.opacity[c]
    t = cut.tex[c]
    if t >= 0:
        alpha = sample_alpha(cut, t, sample_texcoord(st, h))
    return 1.0 - wp.clamp(alpha, 0.0, 1.0)


# --------------------------------------------------------------------------- the volume


@wp.func
def light_ball(L: LightGPU) -> wp.vec4:
    """The light's bound: a local light's enclosing ball (centre xyz, radius w); a distant light's
    direction toward the light (xyz, unit) and the sine of its cone's half angle (w)."""
    if L.kind == 3:
        return wp.vec4(L.az[0], L.az[1], L.az[2], wp.sqrt(wp.max(1.0 - L.cos_max * L.cos_max, 0.0)))
    r = bound_radius(L)
    return wp.vec4(L.position[0], L.position[1], L.position[2], r)


@wp.func
def ball_height(B: wp.vec4, distant: int, n: wp.vec3, a: wp.vec3) -> float:
    """Signed height of the bound's centre (or direction) over the plane through ``a`` normal ``n``."""
    c = wp.vec3(B[0], B[1], B[2])
    if distant != 0:
        return wp.dot(n, c)
    return wp.dot(n, c - a)


@wp.func
def lit_sides(v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, B: wp.vec4, distant: int) -> int:
    """Which sides of the triangle's plane the light's bound reaches: bit 0 the side its normal
    points to (``+1``), bit 1 the other (``-1``); 0 for a zero-area triangle."""
    c = wp.cross(v1 - v0, v2 - v0)
    ln = wp.length(c)
    if ln == 0.0:
        return 0
    h = ball_height(B, distant, c / ln, v0)
    sides = int(0)
    if h > -B[3]:
        sides = sides | 1
    if h < B[3]:
        sides = sides | 2
    return sides


@wp.func
def side_ball(B: wp.vec4, distant: int, m: wp.vec3, a: wp.vec3) -> wp.vec4:
    """A ball (or cone) holding the part of the bound ``B`` on the positive side of the plane through
    ``a`` normal ``m`` (unit): ``B`` itself unless its centre is on the negative side, then the
    ball of the cut disk (centre on the plane) — or, for a cone, the cone about the in-plane
    direction (the cut circle's enclosing cone)."""
    h = ball_height(B, distant, m, a)
    if h >= 0.0:
        return B
    c = wp.vec3(B[0], B[1], B[2])
    if distant != 0:
        # the cut part lies within angle g of the in-plane direction d: cos g = cos(alpha) / cos(beta),
        # beta the centre's angle below the plane (the spherical analogue of the cut disk's ball)
        d = c - m * h
        ld = wp.length(d)
        if ld == 0.0:
            return B
        cos_a = wp.sqrt(wp.max(1.0 - B[3] * B[3], 0.0))
        cos_b = wp.sqrt(wp.max(1.0 - h * h, 0.0))
        cos_g = wp.min(cos_a / cos_b, 1.0)
        d = d / ld
        return wp.vec4(d[0], d[1], d[2], wp.sqrt(wp.max(1.0 - cos_g * cos_g, 0.0)))
    cp = c - m * h
    rho = wp.sqrt(wp.max(B[3] * B[3] - h * h, 0.0))
    return wp.vec4(cp[0], cp[1], cp[2], rho)


@wp.func
def edge_plane(a: wp.vec3, b: wp.vec3, opp: wp.vec3, B: wp.vec4, distant: int) -> wp.vec4:
    """The outer plane of the penumbra wedge of edge ``a b``: through the edge, tangent to the
    bound ``B`` with ``B`` on its positive side and the opposite corner ``opp`` strictly on its
    negative side, as the row ``(n, -n . a)`` (``row . (x, 1) <= 0`` holds in the shadow). Zero
    when there is none."""
    e = b - a
    le = wp.length(e)
    if le == 0.0:
        return wp.vec4(0.0)
    eh = e / le
    q = wp.vec3(B[0], B[1], B[2])
    if distant == 0:
        q = q - a
    qp = q - eh * wp.dot(q, eh)
    D = wp.length(qp)
    if D <= B[3] or D == 0.0:
        return wp.vec4(0.0)
    qh = qp / D
    w = wp.cross(eh, qh)
    cos_t = B[3] / D
    sin_t = wp.sqrt(wp.max(1.0 - cos_t * cos_t, 0.0))
    n1 = qh * cos_t + w * sin_t
    n2 = qh * cos_t - w * sin_t
    o = opp - a
    n = n1
    if wp.dot(n2, o) < wp.dot(n1, o):
        n = n2
    if wp.dot(n, o) >= 0.0:
        return wp.vec4(0.0)
    return wp.vec4(n[0], n[1], n[2], -wp.dot(n, a))


@wp.func
def front_cap(v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, B: wp.vec4, distant: int) -> wp.vec4:
    """The plane of the front cap ``t'`` (§2.2: the corners moved toward the light centre to the
    nearest corner's distance) as a half-space row, when the bound lies wholly in front of it;
    zero otherwise. Distant lights: the plane normal to the direction through the nearest corner."""
    c = wp.vec3(B[0], B[1], B[2])
    if distant != 0:
        k = wp.max(wp.max(wp.dot(v0, c), wp.dot(v1, c)), wp.dot(v2, c))
        return wp.vec4(c[0], c[1], c[2], -k)  # c . x - k <= 0: beyond the nearest corner
    d0 = wp.length(v0 - c)
    d1 = wp.length(v1 - c)
    d2 = wp.length(v2 - c)
    dm = wp.min(wp.min(d0, d1), d2)
    if dm <= 0.0:
        return wp.vec4(0.0)
    w0 = c + (v0 - c) * (dm / d0)
    w1 = c + (v1 - c) * (dm / d1)
    w2 = c + (v2 - c) * (dm / d2)
    m = wp.cross(w1 - w0, w2 - w0)
    lm = wp.length(m)
    if lm == 0.0:
        return wp.vec4(0.0)
    m = m / lm
    h = wp.dot(m, c - w0)
    if h < 0.0:
        m = -m
        h = -h
    if h < B[3]:
        return wp.vec4(0.0)
    return wp.vec4(m[0], m[1], m[2], -wp.dot(m, w0))  # the light in front: the shadow behind


@wp.func
def stsv_planes(v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, B: wp.vec4, distant: int, side: int) -> planes_t:
    """The shadow volume of the triangle for the part of the light on side ``side`` (``+1``: the
    side its normal points to, ``-1`` the other) of its plane (module docstring)."""
    P = planes_t()
    c = wp.cross(v1 - v0, v2 - v0)
    ln = wp.length(c)
    if ln == 0.0:
        P[0] = wp.vec4(0.0, 0.0, 0.0, 1.0)  # empty: a zero-area triangle shadows nothing
        return P
    m = c / ln * float(side)
    Bs = side_ball(B, distant, m, v0)
    P[0] = edge_plane(v0, v1, v2, Bs, distant)
    P[1] = edge_plane(v1, v2, v0, Bs, distant)
    P[2] = edge_plane(v2, v0, v1, Bs, distant)
    P[3] = front_cap(v0, v1, v2, B, distant)  # the paper's front cap (where it bounds the shadow)
    P[4] = wp.vec4(m[0], m[1], m[2], -wp.dot(m, v0))  # behind the triangle, seen from this side
    return P


@wp.func
def in_volume(P: planes_t, x: wp.vec3, slack: float) -> bool:
    """Is ``x`` inside the volume, each plane loosened by ``slack`` (world units; rows have unit normals)?"""
    for k in range(5):
        r = P[k]
        if r[0] * x[0] + r[1] * x[1] + r[2] * x[2] + r[3] > slack:
            return False
    return True


# --------------------------------------------------------------------------- wrappers (tests)


@wp.kernel
def lookup_samples(
    tri: wp.array[wp.vec3],
    tri_uv: wp.array[wp.vec2],
    p: wp.array[wp.vec3],
    s: wp.array[wp.vec3],
    # outputs
    uv: wp.array[wp.vec2],
    bary: wp.array[wp.vec3],
    hit: wp.array[wp.int32],
):
    i = wp.tid()
    st = s_triangle(tri[3 * i], tri[3 * i + 1], tri[3 * i + 2], tri_uv[3 * i], tri_uv[3 * i + 1], tri_uv[3 * i + 2])
    J = receiver_matrix(st, p[i])
    h = sample_bary(J, p[i], s[i])
    hit[i] = int(crosses(h))
    if h[2] != 0.0:
        uv[i] = sample_texcoord(st, h)
        bary[i] = wp.vec3(h[2] - h[0] - h[1], h[0], h[1]) / h[2]


def stsv_lookup(tri: np.ndarray, tri_uv: np.ndarray, p: np.ndarray, s: np.ndarray, device: str = "cpu"):
    """Per row: triangle corners ``tri`` [N, 3, 3], texture coordinates ``tri_uv`` [N, 3, 2],
    receiver ``p`` [N, 3], light sample ``s`` [N, 3] -> (texture coordinate [N, 2], barycentric
    weights of the corners [N, 3], crossing between ``p`` and ``s`` inside the triangle [N] bool)."""
    n = len(p)
    arr = lambda a, t: wp.array(np.ascontiguousarray(a, np.float32).reshape(-1, 3 if t == wp.vec3 else 2), dtype=t, device=device)  # noqa: E731
    uv = wp.zeros(n, dtype=wp.vec2, device=device)
    bary = wp.zeros(n, dtype=wp.vec3, device=device)
    hit = wp.zeros(n, dtype=wp.int32, device=device)
    wp.launch(lookup_samples, dim=n, inputs=[arr(tri, wp.vec3), arr(tri_uv, wp.vec2), arr(p, wp.vec3), arr(s, wp.vec3)],
              outputs=[uv, bary, hit], device=device)
    return uv.numpy(), bary.numpy(), hit.numpy().astype(bool)


@wp.func
def triangle_volumes(v0: wp.vec3, v1: wp.vec3, v2: wp.vec3, L: LightGPU):
    """Both soft textured shadow volumes of a perforated triangle (§6): (lit sides as
    :func:`lit_sides` gives them, the volume of side +1, the volume of side -1), a volume empty (no
    point inside) where its side's half-space holds no part of the light."""
    B = light_ball(L)
    distant = int(L.kind == 3)
    lit = lit_sides(v0, v1, v2, B, distant)
    front = planes_t()
    front[0] = wp.vec4(0.0, 0.0, 0.0, 1.0)
    back = planes_t()
    back[0] = wp.vec4(0.0, 0.0, 0.0, 1.0)
    if (lit & 1) != 0:
        front = stsv_planes(v0, v1, v2, B, distant, 1)
    if (lit & 2) != 0:
        back = stsv_planes(v0, v1, v2, B, distant, -1)
    return lit, front, back


@wp.kernel
def build_volumes(
    tri: wp.array[wp.vec3],
    L: LightGPU,
    # outputs
    planes: wp.array2d[planes_t],
    sides: wp.array[wp.int32],
):
    i = wp.tid()
    lit, front, back = triangle_volumes(tri[3 * i], tri[3 * i + 1], tri[3 * i + 2], L)
    sides[i] = lit
    planes[i, 0] = front
    planes[i, 1] = back


@wp.kernel
def test_points(
    planes: wp.array2d[planes_t],
    x: wp.array[wp.vec3],
    slack: float,
    # outputs
    inside: wp.array2d[wp.int32],
):
    i, j = wp.tid()
    q = x[j]
    inside[i, j] = int(in_volume(planes[i, 0], q, slack) or in_volume(planes[i, 1], q, slack))


def stsv_volumes(tri: np.ndarray, light, scene_diagonal: float = 100.0, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """Volumes of the triangles ``tri`` [N, 3, 3] for ``light`` (a :class:`~wsoft.scene.types.Light`):
    planes [N, 2, 5, 4] (side ``+1``, side ``-1``; a volume that does not exist is empty) and the lit
    sides [N] (bits, :func:`lit_sides`)."""
    n = len(tri)
    planes = wp.zeros((n, 2), dtype=planes_t, device=device)
    sides = wp.zeros(n, dtype=wp.int32, device=device)
    wp.launch(build_volumes, dim=n, inputs=[wp.array(np.asarray(tri, np.float32).reshape(-1, 3), dtype=wp.vec3, device=device),
                                            light_gpu(light, scene_diagonal)], outputs=[planes, sides], device=device)
    return planes.numpy(), sides.numpy()


def points_in_volumes(planes: np.ndarray, x: np.ndarray, slack: float = 0.0, device: str = "cpu") -> np.ndarray:
    """[N, M] bool: is point ``x[j]`` inside either volume of triangle ``i``?"""
    n, m = planes.shape[0], len(x)
    out = wp.zeros((n, m), dtype=wp.int32, device=device)
    wp.launch(test_points, dim=(n, m), inputs=[wp.array(planes, dtype=planes_t, device=device),
                                                wp.array(np.asarray(x, np.float32), dtype=wp.vec3, device=device), float(slack)],
              outputs=[out], device=device)
    return out.numpy().astype(bool)
