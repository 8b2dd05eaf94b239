"""Evaluation: scoring drives, the common end state, trajectories from samples, the paper's study."""
