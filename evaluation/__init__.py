"""Evaluation: problem sets, methods side by side in the Drake world, the paper's tables and plots."""
