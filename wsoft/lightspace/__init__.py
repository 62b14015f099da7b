"""Light-space maths: light views fitted to receivers (:mod:`~wsoft.lightspace.view`), lights on the
device (:mod:`~wsoft.lightspace.light`), light-sample patterns, edge coverage of a light, occlusion
bitmasks, depth moments and the soft textured shadow volumes' per-sample look-up."""

import wsoft.parallel  # noqa: F401  (Warp configured before this package's kernels are defined)
