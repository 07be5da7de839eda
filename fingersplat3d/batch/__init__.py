"""Dataset runs: every capture of a dataset fused (and rendered) on Ray, resumable, with a results table and report."""
