"""Visualization: rerun recordings of human and robot motion."""
