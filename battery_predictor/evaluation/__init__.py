"""Evaluation as the seed paper does it (section 5): Table 2, runtime (Fig. 5), routes (Fig. 8)."""
