"""Map-space acceleration and filtering: separable blurs (later: pyramids, summed-area tables)."""
