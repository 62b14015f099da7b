"""What a sequence carries from one frame to the next (:class:`History`), handed to each frame's
render (``wsoft.render(..., history=h)``): the frame's index, with which techniques that draw new
noise every frame seed their samples (:meth:`~wsoft.pipeline.technique_context.TechniqueContext.frame_seed`),
and per technique label and light label the state a time-aware technique kept for the next frame
(:meth:`~wsoft.pipeline.technique_context.TechniqueContext.keep`, read back with
:meth:`~wsoft.pipeline.technique_context.TechniqueContext.previous`): its accumulated signal, its G-buffer's
points and normals, the camera, so that it can reproject them."""

from __future__ import annotations


class History:
    """A sequence's memory between frames. ``frame``: the index of the frame being rendered (0 the
    first); ``reseed``: whether techniques draw other samples in each frame (seed + frame). Call
    :meth:`advance` after each frame: what the frame kept becomes the next frame's previous state."""

    def __init__(self, reseed: bool = True):
        self.frame = 0
        self.reseed = reseed
        self._previous: dict[tuple[str, str], dict] = {}
        self._kept: dict[tuple[str, str], dict] = {}
        self.fit_receivers: dict | None = None  # light path -> world points of every frame (view=sequence light views)

    def previous(self, technique: str, light: str) -> dict | None:
        """The state ``technique`` (a label) kept for ``light`` (a label) in the previous frame, or None."""
        return self._previous.get((technique, light))

    def keep(self, technique: str, light: str, state: dict) -> None:
        self._kept[(technique, light)] = state

    def seed(self, seed: int) -> int:
        """The seed of this frame's samples: ``seed + frame`` (within the seeds' range) when reseeding."""
        return (int(seed) + self.frame) % (2**31 - 1) if self.reseed else int(seed)

    def advance(self) -> None:
        self._previous, self._kept = self._kept, {}
        self.frame += 1
