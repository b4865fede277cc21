"""The LAFAN1 convention: Y-up, centimetres."""

import numpy as np

LAFAN_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""A +90 degree turn about X: maps LAFAN1's Y-up world to the pipeline's Z-up one, keeping handedness."""
LAFAN_CM_TO_M = 0.01
"""LAFAN1 lengths are in centimetres."""
