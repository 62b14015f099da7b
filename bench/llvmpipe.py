"""A peer for the light depth map: the same triangles drawn into a depth-only target by Mesa's
llvmpipe (the CPU OpenGL rasterizer), through ``moderngl`` on a headless EGL context.

Optional, like the Embree peer of :mod:`wsoft.bench.foundation`: ``moderngl`` (the ``peers`` extra)
is imported only here and only when a map is drawn, and the system needs Mesa's EGL and its
software driver (Debian: ``libegl-mesa0``, ``libgl1-mesa-dri``). :func:`unavailable` says why the
peer cannot run (None when it can).

What is drawn is what :func:`wsoft.raster.depth_map.rasterize` draws for a view: the device scene's
soup (or a list of its triangles), and an instanced scene's prototypes once per instance whose
world bounds reach the view (:func:`~wsoft.lightspace.view.boxes_in_view`, chosen while the buffers
are filled, apart from the timed draw) through instanced rendering, each instance's transform a
per-instance attribute. Cutout triangles are alpha-tested in the fragment shader with wsoft's own
data and rule (:func:`~wsoft.scene.surfaces.surface_present`: the bilinear sample of the texture
at the perspective-correct st under the UsdUVTexture wrap mode, kept where ``alpha >= threshold``).
No face is culled: depth-min over every face is the map wsoft's exact far-face culling gives.

The view-projection: a perspective view is a frustum over its window of tangents between its near
and far depths; an orthographic view a box over its window whose near plane is moved back to the
nearest point drawn (wsoft does not clip an orthographic view at its near depth). The target is
a ``width x height`` depth texture of 24-bit fixed point (moderngl's ``depth_texture``), depth
test ``LESS``, cleared to 1. :meth:`LlvmpipeDepthMap.linear_depth` turns its window depths back
into wsoft's linear view depth (``DEPTH_CLEAR`` where nothing was drawn); the 24-bit step there is
:meth:`LlvmpipeDepthMap.depth_step` (orthographic: ``(far - near) / 2^24``; perspective: ``z^2 (far -
near) / (far near 2^24)`` at depth z).

llvmpipe's thread count is read from ``LP_NUM_THREADS`` when the first context starts: one context
per process (:func:`context`), and a second asking for another thread count is refused.
"""

from __future__ import annotations

import os
import time

import numpy as np

INSTALL_HINT = "pip install 'wsoft[peers]' (moderngl) and Mesa's EGL with its software driver (Debian: libegl-mesa0, libgl1-mesa-dri)"
DEPTH_BITS = 24
SAME_SURFACE_STEPS = 16  # depths of one surface in both maps: within this many steps of the 24-bit target (quantisation and float32 set-up)

_CONTEXT: dict = {}  # the process's one context: {"ctx": moderngl.Context, "threads": int} or {"error": str}

VERTEX = """#version 330
uniform mat4 view_proj;
in vec3 p;
#ifdef INSTANCED
in vec4 r0; in vec4 r1; in vec4 r2;  // the instance's to-world rows
#endif
#ifdef CUTOUT
in vec2 st_in;
out vec2 st;
#endif
void main() {
    vec4 q = vec4(p, 1.0);
#ifdef INSTANCED
    q = vec4(dot(r0, q), dot(r1, q), dot(r2, q), 1.0);
#endif
#ifdef CUTOUT
    st = st_in;
#endif
    gl_Position = view_proj * q;
}
"""

FRAGMENT_DEPTH = """#version 330
void main() {}
"""

# wsoft.scene.surfaces.surface_present, texel by texel (wrap_coord, texel_value, sample_alpha)
FRAGMENT_CUTOUT = """#version 330
uniform sampler2D tex;
uniform int has_tex;
uniform float opacity;
uniform float threshold;
uniform ivec2 size;
uniform ivec2 wrap;  // 0 repeat, 1 mirror, 2 clamp, 3 black
uniform float border;
in vec2 st;

int floor_mod(int i, int n) { return i >= 0 ? i - n * (i / n) : i + n * ((n - 1 - i) / n); }

int wrap_coord(int i, int n, int mode) {
    if (mode == 0) return floor_mod(i, n);
    if (mode == 1) { int r = floor_mod(i, 2 * n); return r >= n ? 2 * n - 1 - r : r; }
    if (mode == 2) return clamp(i, 0, n - 1);
    return (i < 0 || i >= n) ? -1 : i;
}

float texel(int x, int y) {
    int xi = wrap_coord(x, size.x, wrap.x);
    int yi = wrap_coord(y, size.y, wrap.y);
    if (xi < 0 || yi < 0) return border;
    return texelFetch(tex, ivec2(xi, yi), 0).r;
}

void main() {
    float alpha = opacity;
    if (has_tex == 1) {
        float fx = st.x * float(size.x) - 0.5;
        float fy = st.y * float(size.y) - 0.5;
        int x0 = int(floor(fx));
        int y0 = int(floor(fy));
        float ax = fx - float(x0);
        float ay = fy - float(y0);
        float a = texel(x0, y0) * (1.0 - ax) + texel(x0 + 1, y0) * ax;
        float b = texel(x0, y0 + 1) * (1.0 - ax) + texel(x0 + 1, y0 + 1) * ax;
        alpha = a * (1.0 - ay) + b * ay;
    }
    if (!(alpha >= threshold)) discard;
}
"""


def unavailable(threads: int | None = None) -> str | None:
    """Why the peer cannot run here (moderngl missing, no EGL context, a renderer that is not
    llvmpipe, llvmpipe started with another thread count), or None when it can."""
    try:
        context(threads)
    except PeerUnavailable as exc:
        return str(exc)
    return None


class PeerUnavailable(RuntimeError):
    """The llvmpipe peer cannot run here; the message says why."""


def context(threads: int | None = None):
    """The process's moderngl context on llvmpipe, started with ``LP_NUM_THREADS = threads``
    (default: wsoft's CPU thread count). Raises :class:`PeerUnavailable` with the reason."""
    from wsoft.parallel import cpu_threads

    threads = int(threads or cpu_threads())
    if "error" in _CONTEXT:
        raise PeerUnavailable(_CONTEXT["error"])
    if "ctx" in _CONTEXT:
        if _CONTEXT["threads"] != threads:
            raise PeerUnavailable(f"llvmpipe started in this process with LP_NUM_THREADS={_CONTEXT['threads']}, not {threads} "
                                  "(it reads the variable once)")
        return _CONTEXT["ctx"]
    try:
        import moderngl
    except ImportError:
        _CONTEXT["error"] = f"moderngl not installed ({INSTALL_HINT})"
        raise PeerUnavailable(_CONTEXT["error"]) from None
    old = {k: os.environ.get(k) for k in ("LP_NUM_THREADS", "LIBGL_ALWAYS_SOFTWARE", "GALLIUM_DRIVER")}
    os.environ["LP_NUM_THREADS"] = str(threads)
    os.environ["LIBGL_ALWAYS_SOFTWARE"] = "1"  # Mesa: a software driver even where a GPU's is present
    os.environ["GALLIUM_DRIVER"] = "llvmpipe"
    t0 = time.perf_counter()
    try:
        ctx = moderngl.create_standalone_context(backend="egl")
    except Exception as exc:  # glcontext raises plain Exceptions for a missing libEGL or no EGL device
        _CONTEXT["error"] = f"no headless EGL context ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__}; {INSTALL_HINT})"
        raise PeerUnavailable(_CONTEXT["error"]) from None
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    renderer = ctx.info.get("GL_RENDERER", "")
    if "llvmpipe" not in renderer:
        ctx.release()
        _CONTEXT["error"] = f"the EGL context's renderer is {renderer!r}, not llvmpipe"
        raise PeerUnavailable(_CONTEXT["error"])
    _CONTEXT.update(ctx=ctx, threads=threads, renderer=renderer, version=ctx.info.get("GL_VERSION", ""),
                    start_ms=1e3 * (time.perf_counter() - t0), moderngl=moderngl.__version__)
    return ctx


def context_info() -> dict:
    """The running context's renderer, GL version, moderngl version, thread count and start time (ms)."""
    return {k: _CONTEXT[k] for k in ("renderer", "version", "moderngl", "threads", "start_ms") if k in _CONTEXT}


def view_projection(view, near: float | None = None) -> np.ndarray:
    """The 4x4 (float64) taking world points to ``view``'s clip space (OpenGL: x, y, z in [-w, w]),
    window corner (l, b) at texel (0, 0) as wsoft places it; ``near`` overrides the view's near depth."""
    n = float(view.near if near is None else near)
    f = float(view.far)
    l, r, b, t = (float(x) for x in view.window)
    to_view = np.eye(4)
    to_view[:3, :3] = np.asarray(view.axes, np.float64).T
    to_view[:3, 3] = -to_view[:3, :3] @ np.asarray(view.origin, np.float64)
    p = np.zeros((4, 4))
    if view.persp:
        p[0, 0], p[0, 2] = 2.0 / (r - l), -(r + l) / (r - l)
        p[1, 1], p[1, 2] = 2.0 / (t - b), -(t + b) / (t - b)
        p[2, 2], p[2, 3] = (f + n) / (f - n), -2.0 * f * n / (f - n)
        p[3, 2] = 1.0
    else:
        p[0, 0], p[0, 3] = 2.0 / (r - l), -(r + l) / (r - l)
        p[1, 1], p[1, 3] = 2.0 / (t - b), -(t + b) / (t - b)
        p[2, 2], p[2, 3] = 2.0 / (f - n), -(f + n) / (f - n)
        p[3, 3] = 1.0
    return p @ to_view


class LlvmpipeDepthMap:
    """``view``'s depth map of the device scene ``ds`` drawn by llvmpipe: buffers filled and the
    target made once (:attr:`upload_ms`), :meth:`draw` (clear, draw calls, ``glFinish``) as often as
    wanted, :meth:`linear_depth` the map as wsoft stores it. ``alpha_tested``: cutouts alpha-tested
    (as :func:`~wsoft.raster.depth_map.rasterize`); ``triangles``: only these soup triangles."""

    def __init__(self, ds, view, alpha_tested: bool, triangles: np.ndarray | None = None, threads: int | None = None):
        self.ctx = ctx = context(threads)  # first: raises PeerUnavailable where moderngl or EGL is missing
        import moderngl

        from wsoft.lightspace.view import boxes_in_view

        t0 = time.perf_counter()
        self.view = view
        alpha = bool(alpha_tested and ds.has_cutouts)
        cut = ds.cutouts
        tri_cut = cut.tri_cut.numpy() if alpha else None
        tri_uv = cut.tri_uv.numpy().reshape(-1, 3, 2) if alpha else None
        self.moderngl = moderngl
        self.draws = []  # (vao, vertices, instances, cutout uniforms or None)
        self._programs = {}
        self._textures = {}
        self._keep = []
        self._cut = {k: getattr(cut, k).numpy() for k in ("threshold", "opacity", "tex", "tex_offset", "tex_w", "tex_h", "tex_wrap_s",
                                                          "tex_wrap_t", "tex_border", "tex_data")} if alpha else {}
        inst = ds.instances
        self.instances_drawn = 0
        near_pts = []
        # the soup (its dummy triangle, in an all-instanced scene, has no area and draws nothing)
        pts = ds.points.numpy().astype(np.float32)
        idx = ds.indices.numpy().reshape(-1, 3)
        sel = np.arange(len(idx)) if triangles is None else np.asarray(triangles, np.int64)
        near_pts.append(pts[np.unique(idx[sel])] if len(sel) else np.zeros((0, 3)))
        self._batch(pts, idx, sel, 0, tri_cut, tri_uv, None, 0)
        if inst is not None:
            seen, _ = boxes_in_view(view, inst.lo, inst.hi)
            ppts = inst.proto_points.numpy().astype(np.float32)
            pidx = inst.proto_indices.numpy().reshape(-1, 3)
            for p in range(len(inst.proto_ntri)):
                which = np.flatnonzero(seen & (inst.proto == p))
                if len(which) == 0 or inst.proto_ntri[p] == 0:
                    continue
                rows = inst.to_world[which][:, :3, :].astype(np.float32)  # [I, 3, 4]: to-world rows
                first, ntri = int(inst.proto_first[p]), int(inst.proto_ntri[p])
                self._batch(ppts, pidx, np.arange(first, first + ntri), int(inst.tri_base), tri_cut, tri_uv, rows, len(which))
                self.instances_drawn += len(which)
            corners = np.concatenate([np.where([(k >> 0) & 1, (k >> 1) & 1, (k >> 2) & 1], inst.hi[seen], inst.lo[seen]) for k in range(8)])
            near_pts.append(corners)
        near = None
        if not view.persp:  # no near clip: the near plane goes back to the nearest point drawn
            allp = np.concatenate([np.asarray(a, np.float64).reshape(-1, 3) for a in near_pts])
            zmin = float((view.to_view(allp)[:, 2]).min()) if len(allp) else float(view.near)
            near = min(float(view.near), zmin - 1e-3 * max(float(view.far) - zmin, 1e-6))
        self.gl_near = float(view.near if near is None else near)
        m = view_projection(view, near)
        vp = m.T.astype(np.float32).tobytes()  # GLSL matrices are column-major
        for prog in self._programs.values():
            prog["view_proj"].write(vp)
        self.target = ctx.depth_texture((int(view.width), int(view.height)))
        self.fbo = ctx.framebuffer(depth_attachment=self.target)
        self.upload_ms = 1e3 * (time.perf_counter() - t0)
        self.draw_calls = len(self.draws)

    def _program(self, instanced: bool, cutout: bool):
        key = (instanced, cutout)
        if key not in self._programs:
            defs = ("#define INSTANCED\n" if instanced else "") + ("#define CUTOUT\n" if cutout else "")
            vs = VERTEX.replace("#version 330\n", "#version 330\n" + defs)
            self._programs[key] = self.ctx.program(vertex_shader=vs, fragment_shader=FRAGMENT_CUTOUT if cutout else FRAGMENT_DEPTH)
        return self._programs[key]

    def _batch(self, pts, idx, sel, tri_base, tri_cut, tri_uv, rows, count):
        """Draw calls for triangles ``sel`` (indices into ``idx`` over ``pts``; combined index
        ``tri_base + sel``): one indexed call for the opaque ones, one per cutout for the others;
        ``rows`` (per-instance to-world rows) makes them instanced ``count`` times."""
        ctx = self.ctx
        if len(sel) == 0:
            return
        c = tri_cut[tri_base + sel] if tri_cut is not None else np.full(len(sel), -1)
        inst_buf = None
        inst_fmt = []
        if rows is not None:
            inst_buf = ctx.buffer(np.ascontiguousarray(rows).tobytes())
            inst_fmt = [(inst_buf, "4f 4f 4f/i", "r0", "r1", "r2")]
            self._keep.append(inst_buf)
        instances = count if rows is not None else 1
        opaque = sel[c < 0]
        if len(opaque):
            prog = self._program(rows is not None, False)
            vbo = ctx.buffer(pts.tobytes())
            ibo = ctx.buffer(np.ascontiguousarray(idx[opaque], np.int32).tobytes())
            vao = ctx.vertex_array(prog, [(vbo, "3f", "p")] + inst_fmt, index_buffer=ibo, index_element_size=4)
            self._keep += [vbo, ibo]
            self.draws.append((vao, 3 * len(opaque), instances, None))
        for k in np.unique(c[c >= 0]):
            tris = sel[c == k]
            corners = pts[idx[tris]].reshape(-1, 3)
            st = tri_uv[tri_base + tris].reshape(-1, 2).astype(np.float32)
            prog = self._program(rows is not None, True)
            vbo = ctx.buffer(np.hstack([corners, st]).astype(np.float32).tobytes())
            vao = ctx.vertex_array(prog, [(vbo, "3f 2f", "p", "st_in")] + inst_fmt)
            self._keep.append(vbo)
            self.draws.append((vao, 3 * len(tris), instances, self._cutout_uniforms(int(k))))

    def _cutout_uniforms(self, k: int) -> dict:
        """The alpha test of cutout ``k``: its threshold, constant opacity, and texture (if any)."""
        cut = self._cut
        t = int(cut["tex"][k])
        u = {"threshold": float(cut["threshold"][k]), "opacity": float(cut["opacity"][k]), "has_tex": int(t >= 0)}
        if t >= 0:
            if t not in self._textures:
                w, h, off = int(cut["tex_w"][t]), int(cut["tex_h"][t]), int(cut["tex_offset"][t])
                tex = self.ctx.texture((w, h), 1, np.ascontiguousarray(cut["tex_data"][off: off + w * h], np.float32).tobytes(), dtype="f4")
                tex.filter = (self.moderngl.NEAREST, self.moderngl.NEAREST)  # read by texelFetch
                self._textures[t] = tex
            u.update(texture=self._textures[t], size=(int(cut["tex_w"][t]), int(cut["tex_h"][t])),
                     wrap=(int(cut["tex_wrap_s"][t]), int(cut["tex_wrap_t"][t])), border=float(cut["tex_border"][t]))
        return u

    def draw(self) -> None:
        """Clear the target, issue every draw call, wait for llvmpipe (``glFinish``)."""
        ctx = self.ctx
        self.fbo.use()
        ctx.enable_only(self.moderngl.DEPTH_TEST)
        ctx.depth_func = "<"
        self.fbo.clear(depth=1.0)
        for vao, vertices, instances, u in self.draws:
            if u is not None:
                prog = vao.program
                for name in ("threshold", "opacity", "has_tex", "size", "wrap", "border"):
                    if name in u:
                        prog[name].value = u[name]
                if "texture" in u:
                    u["texture"].use(0)
                    prog["tex"].value = 0
            vao.render(self.moderngl.TRIANGLES, vertices=vertices, instances=instances)
        ctx.finish()

    def window_depth(self) -> np.ndarray:
        """The target's window depths, ``[height, width]`` float32 in [0, 1] (1: nothing drawn), row 0 at the window's bottom."""
        return np.frombuffer(self.target.read(), np.float32).reshape(int(self.view.height), int(self.view.width)).copy()

    def linear_depth(self) -> np.ndarray:
        """The map as wsoft stores it: linear view depth, ``[height, width]`` float32, ``DEPTH_CLEAR`` where nothing was drawn."""
        from wsoft.lightspace.view import DEPTH_CLEAR

        d = self.window_depth().astype(np.float64)
        n, f = self.gl_near, float(self.view.far)
        if self.view.persp:
            a, b = (f + n) / (f - n), -2.0 * f * n / (f - n)
            with np.errstate(divide="ignore"):
                z = b / ((2.0 * d - 1.0) - a)
        else:
            z = n + d * (f - n)
        return np.where(d >= 1.0, DEPTH_CLEAR, z).astype(np.float32)

    def depth_step(self, z: np.ndarray) -> np.ndarray:
        """The linear depth one step of the 24-bit target spans at depth ``z``."""
        n, f = self.gl_near, float(self.view.far)
        q = 1.0 / (2 ** DEPTH_BITS - 1)
        if self.view.persp:
            return np.asarray(z, np.float64) ** 2 * (f - n) / (f * n) * q
        return np.full(np.shape(z), (f - n) * q)

    def release(self) -> None:
        for vao, *_ in self.draws:
            vao.release()
        for b in self._keep:
            b.release()
        for t in self._textures.values():
            t.release()
        for p in self._programs.values():
            p.release()
        self.fbo.release()
        self.target.release()


def compare(wsoft_depth: np.ndarray, peer: LlvmpipeDepthMap) -> dict:
    """Two maps of one view texel by texel: wsoft's linear depths against the peer's (converted,
    :meth:`LlvmpipeDepthMap.linear_depth`). ``coverage_differs``: the fraction of texels drawn in
    one map only; over texels drawn in both: max and mean |difference|, the max relative to wsoft's
    depth, the max and 99th percentile in steps of the 24-bit target
    (:meth:`~LlvmpipeDepthMap.depth_step`), and ``surface_differs``: the fraction of them more than
    :data:`SAME_SURFACE_STEPS` steps apart (another triangle nearest at the texel centre: the two
    rasterizers' rules at shared edges and silhouettes)."""
    from wsoft.lightspace.view import DEPTH_CLEAR

    a = np.asarray(wsoft_depth, np.float64)
    b = peer.linear_depth().astype(np.float64)
    ca, cb = a < DEPTH_CLEAR, b < DEPTH_CLEAR
    both = ca & cb
    d = np.abs(a - b)[both]
    steps = d / peer.depth_step(a[both]) if d.size else d
    return {"texels": int(a.size), "covered_wsoft": int(ca.sum()), "covered_peer": int(cb.sum()),
            "coverage_differs": float(np.mean(ca != cb)), "covered_by_wsoft_only": int((ca & ~cb).sum()), "covered_by_peer_only": int((cb & ~ca).sum()),
            "max_abs_diff": float(d.max()) if d.size else 0.0, "mean_abs_diff": float(d.mean()) if d.size else 0.0,
            "max_rel_diff": float((d / np.maximum(a[both], 1e-30)).max()) if d.size else 0.0,
            "max_diff_in_steps": float(steps.max()) if d.size else 0.0,
            "surface_differs": float(np.mean(steps > SAME_SURFACE_STEPS)) if d.size else 0.0, "p99_diff_in_steps": float(np.percentile(steps, 99)) if d.size else 0.0}
