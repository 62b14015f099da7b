"""Rasterization and eye rays: the eye-view G-buffer, light-view depth maps (the rasterizer),
cameras, shading of G-buffer samples and the receiver's horizon."""

import wsoft.parallel  # noqa: F401  (Warp configured before this package's kernels are defined)
