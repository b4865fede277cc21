"""Evaluation: quality metrics for reference motions and, later, for policies tracking them."""
