"""What one technique instance sees of the render context (:class:`TechniqueContext`: its keys, pass
names and counters, and :meth:`~TechniqueContext.add_pass`, which checks each pass against the
technique's :class:`~wsoft.techniques.PassSpec`), and the visibility a technique's pass writes."""

from __future__ import annotations

from dataclasses import dataclass

import warp as wp

from wsoft.errors import DeclarationError
from wsoft.graph import Key, Pass
from wsoft.lightspace.cube import CubeFace
from wsoft.scene.types import Light


@dataclass
class Visibility:
    """Per G-buffer sample visibility of one light (flat float32), optional standard error."""

    vis: wp.array
    stderr: wp.array | None = None

    def arrays(self) -> dict[str, wp.array]:
        out = {"vis": self.vis}
        if self.stderr is not None:
            out["stderr"] = self.stderr
        return out


class TechniqueContext:
    """A :class:`~wsoft.pipeline.context.RenderContext` seen by one technique instance (``label`` tells instances apart):
    its keys, pass names and counters carry the label; the shared providers are the render
    context's own."""

    def __init__(self, ctx, tech, label: str):
        self.ctx = ctx
        self.tech = tech
        self.label_ = label
        self.face_views: dict[str, list[Key]] = {}  # light path -> the cube-map face views its passes read

    # the render context's state and providers
    scene = property(lambda self: self.ctx.scene)
    device = property(lambda self: self.ctx.device)
    width = property(lambda self: self.ctx.width)
    height = property(lambda self: self.ctx.height)
    pixel_samples = property(lambda self: self.ctx.pixel_samples)
    camera = property(lambda self: self.ctx.camera)

    def scene_arrays(self) -> Key:
        return self.ctx.scene_arrays()

    def gbuffer(self) -> Key:
        return self.ctx.gbuffer()

    def light_view(self, light: Light, size: int, soft: bool = False, view: str = "fitted") -> Key:
        key = self.ctx.light_view(light, size, soft, view, self.tech.cube_guard_texels())
        self._note_face_view(light, key)
        return key

    def light_depth(self, light: Light, size: int, conservative: bool = False, soft: bool = False, inner: bool = False,
                    opaque: bool = False, faces: str = "all", view: str = "fitted", read: int | None = None) -> Key:
        guard = self.tech.cube_guard_texels()
        self._note_face_view(light, self.ctx.light_view(light, size, soft, view, guard))
        return self.ctx.light_depth(light, size, conservative, soft, inner, opaque, faces, view, guard, read)

    def _note_face_view(self, light: Light, key: Key) -> None:
        """Remember the views of a cube map's faces this technique reads (its counters count their texels)."""
        if isinstance(light, CubeFace):
            self.face_views.setdefault(light.path, []).append(key)

    def front_fraction(self, light: Light, centre: bool = False) -> Key:
        return self.ctx.front_fraction(light, centre)

    def label(self, light: Light) -> str:
        return self.ctx.label(light)

    def light_gpu(self, light: Light):
        return self.ctx.light_gpu(light)

    # -- keys and names ------------------------------------------------------------------------------
    def visibility_key(self, light: Light) -> Key:
        return Key("visibility", self.label(light), technique=self.label_)

    def key(self, kind: str, light: Light, variant: str = "") -> Key:
        """A resource of this technique instance alone."""
        return Key(kind, self.label(light), technique=self.label_, variant=variant)

    def shared_key(self, kind: str, light: Light, size: int, *params: str) -> Key:
        """A resource any instance of this technique may share: it depends on the light, the map
        ``size`` and the named parameters only (non-default values appear in the variant), and on the
        light view (``view``, :class:`~wsoft.params.LightViewParams`) of a technique that has one."""
        p = self.tech.params
        d = self.tech.defaults()
        if "view" in d and "view" not in params:
            params = params + ("view",)
        extra = ",".join(f"{n}={getattr(p, n)}" for n in params if getattr(p, n) != d[n])
        return Key(kind, self.label(light), variant=f"@{size}" + (f"{{{extra}}}" if extra else ""))

    def pass_name(self, base: str, light: Light, suffix: str = "") -> str:
        """``base[light]suffix``, or ``base[label:light]suffix`` for a labelled instance."""
        inner = self.label(light) if self.label_ == self.tech.name else f"{self.label_}:{self.label(light)}"
        return f"{base}[{inner}]{suffix}"

    def frame_seed(self, seed: int) -> int:
        """The seed of this frame's random samples: ``seed`` in a single frame; in a sequence that
        reseeds (:class:`~wsoft.pipeline.history.History`), ``seed`` plus the frame's index, so the
        noise of a stochastic estimate changes from frame to frame as it does on screen."""
        return self.ctx.history.seed(seed) if self.ctx.history is not None else int(seed)

    def previous(self, light: Light) -> dict | None:
        """What this technique kept for ``light`` in the previous frame of its sequence (:meth:`keep`),
        or None: a single frame, or the first frame of a sequence."""
        h = self.ctx.history
        return h.previous(self.label_, self.label(light)) if h is not None else None

    def keep(self, light: Light, state: dict) -> None:
        """Keep ``state`` for ``light`` for the next frame of the sequence (nothing in a single frame)."""
        if self.ctx.history is not None:
            self.ctx.history.keep(self.label_, self.label(light), state)

    @property
    def origin(self):
        """The render's local origin in world space (None: world space; :func:`~wsoft.pipeline.framing.local_origin`)."""
        return self.ctx.origin

    @property
    def in_sequence(self) -> bool:
        """Is this frame part of a sequence (a history is kept)?"""
        return self.ctx.history is not None

    def visibility(self, vis: wp.array, stderr: wp.array | None = None) -> Visibility:
        return Visibility(vis, stderr)

    def counters(self, light: Light) -> dict:
        """This technique's counters for ``light`` (``stats["counters"]["techniques"][label][light]``)."""
        t = self.ctx.counters["techniques"].setdefault(self.label_, {})
        return t.setdefault(self.label(light), {})

    def add_pass(self, name: str, inputs, outputs, run, *, stage: str, kind: str | None = None, light: Light | None = None) -> Key:
        """Register a pass of this technique, of its declared ``stage`` (:class:`~wsoft.techniques.PassSpec`:
        the kinds of ``inputs`` and ``outputs`` must be the declared ones, else a
        :class:`~wsoft.errors.DeclarationError`); ``name`` from :meth:`pass_name`, ``kind`` defaults
        to ``reference`` for the reference and ``technique`` otherwise."""
        check_declared(self.tech, name, stage, inputs, outputs)
        if kind is None:
            kind = "reference" if self.tech.name == "reference" else "technique"
        shared = all(not k.technique for k in outputs)
        return self.ctx.add(Pass(name, tuple(inputs), tuple(outputs), run, kind=kind, stage=stage,
                                 technique="" if shared else self.label_, light=self.label(light) if light is not None else ""))


def check_declared(tech, name: str, stage: str, inputs, outputs) -> None:
    """Raise a :class:`~wsoft.errors.DeclarationError` unless the pass ``name`` of ``tech`` reads and
    writes the kinds of resource its :class:`~wsoft.techniques.PassSpec` of ``stage`` declares
    (every declared read, optional ones or not, nothing else; exactly the declared writes)."""
    spec = tech.pass_spec(stage)
    got_in, got_out = {k.kind for k in inputs}, {k.kind for k in outputs}
    need, may = set(spec.reads), set(spec.reads) | set(spec.optional)
    if not need <= got_in <= may or got_out != set(spec.writes):
        raise DeclarationError(f"technique {tech.name!r}: pass {name!r} reads {', '.join(sorted(got_in)) or 'nothing'} and writes "
                               f"{', '.join(sorted(got_out))}; its stage {stage!r} declares {spec.text()}")
