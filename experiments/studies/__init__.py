"""Studies built on the pipeline: the paper's tables, identifiability, calibration, motion."""
