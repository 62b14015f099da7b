"""Map-space acceleration and filtering: separable blurs, min/max and moment pyramids, summed-area tables and their tile
grids, the irregular z-buffer's and the object-based techniques' light-space grids, PCF taps, SSM's pruning structures."""

import wsoft.parallel  # noqa: F401  (Warp configured before this package's kernels are defined)
