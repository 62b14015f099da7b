"""Rendering: one frame graph for one or several techniques on a scene, running only what is needed.

Follow a render from here: :func:`render` loads the stage (:mod:`~wsoft.pipeline.loading`),
resolves the camera and image (:mod:`~wsoft.pipeline.framing`) and builds the graph
(:mod:`~wsoft.pipeline.build`): a :class:`~wsoft.pipeline.context.RenderContext` whose providers
register the shared passes once, and each technique's passes per shadow-casting light it
supports, through a :class:`~wsoft.pipeline.technique_context.TechniqueContext`; ``shade`` lights every
G-buffer sample with a technique's visibilities and ``resolve`` turns them into per-pixel
channels. Only passes feeding the requested channels run; the frames' stats
(:mod:`~wsoft.pipeline.frames`) say which ran, of what kind, and which several techniques shared.
:func:`plan` says what would run, without running it.
"""

from __future__ import annotations

import time

from wsoft.parallel import compile_time, resolve_device
from wsoft.pipeline.build import Built, as_techniques, build_graph, execute, is_several, technique_labels
from wsoft.pipeline.context import RenderContext, TechniqueContext, Visibility
from wsoft.pipeline.frames import Frame, FrameSet, frames_of
from wsoft.pipeline.history import History
from wsoft.pipeline.framing import DEFAULT_SIZE, Framing, check_sizes, frame_setup
from wsoft.pipeline.loading import INSTANCING_MODES, instancing_plan, load_stage, with_render_settings
from wsoft.pipeline.planning import plan, shadow_controls

__all__ = ["DEFAULT_SIZE", "INSTANCING_MODES", "Built", "Frame", "FrameSet", "Framing", "History", "RenderContext", "TechniqueContext", "Visibility",
           "as_techniques", "build_graph", "check_sizes", "execute", "frame_setup", "frames_of", "instancing_plan", "is_several",
           "load_stage", "plan", "render", "shadow_controls", "technique_labels", "with_render_settings"]


def render(
    scene,
    technique,
    *,
    width: int | None = None,
    height: int | None = None,
    camera=None,
    light=None,
    device: str | None = None,
    pixel_samples: int = 1,
    time_code: float | None = None,
    render_settings: str | None = None,
    progress=None,
    frame_history=None,
    **params,
) -> Frame | FrameSet:
    """Render on ``scene`` (a :class:`Scene`, a USD path or a bundled stage's name such as
    ``"box_plane"``, :func:`wsoft.usd_scenes.resolve`) and return a :class:`Frame`, or a
    :class:`FrameSet` when ``technique`` is a list.

    ``technique``: a name with its parameters as keywords (``render(scene, "pcss",
    filter_samples=64)``), or a list of names, ``(name, {params})`` pairs and
    :class:`~wsoft.techniques.Technique` instances, rendered in one graph that shares the passes
    they have in common (``render(scene, ["pcss", ("essm", {"H": 2}), "reference"])``).
    ``width``, ``height``, ``camera`` (a camera prim path): None takes them from the scene's
    render settings, else 640 x 480 and the stage's first camera, else an automatic one (see
    :func:`frame_setup`; the settings' pixel aspect, conform policy and data window apply whatever
    was given). ``render_settings``: the ``RenderSettings`` prim to use (None: the stage's own, see
    :mod:`wsoft.scene.render_settings`); a :class:`Scene` loaded with other settings is loaded
    again, since their ``includedPurposes`` may change its geometry: from the ``Usd.Stage`` it was
    loaded from (its load rules and population mask kept), else from its file.
    ``light``: a light path or name (default: every shadow-casting light; ``V`` = the first a
    technique supports). A light a technique does not support is skipped with a warning.
    ``progress``: called as ``progress(done, total, pass_name)`` before each pass of the graph and
    ``progress(total, total, None)`` after the last (the command line's progress bar).

    ``frame_history``: a sequence's :class:`~wsoft.pipeline.history.History` (:mod:`wsoft.pipeline.sequence`
    passes one through its frames): time-aware techniques read their previous frame from it and
    stochastic ones seed with the frame's index; None renders a single frame.

    With a ``dataWindowNDC`` the whole image is rendered and the frame's channels are the data
    window's pixels (``stats["framing"]["data_window"]``), the same values as the whole render's.
    """
    scene = with_render_settings(scene, render_settings, time_code)
    check_sizes(width, height, pixel_samples)
    several = is_several(technique)
    dev = resolve_device(device)
    from wsoft.techniques import TECHNIQUES  # noqa: F401  (the technique modules load before the clock starts)

    t0 = time.perf_counter()
    built = build_graph(scene, technique, width=width, height=height, camera=camera, light=light, device=dev,
                        pixel_samples=pixel_samples, params=params, history=frame_history)
    res, records, _ = execute(built, dev, progress=progress)
    t1 = time.perf_counter()
    fs = frames_of(built, res, records, 1e3 * (t1 - t0), compile_ms=1e3 * compile_time(t0, t1)[0])
    if several:
        return fs
    return fs[built.labels[0]]
