"""The paper's experiments as commands (``fs3d eval ...``): runs of the pipeline scored against ground truth."""
