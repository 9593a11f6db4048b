"""Design workflow: evaluating designs over grids, and the paper's design figures."""
