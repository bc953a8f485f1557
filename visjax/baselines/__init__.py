"""Baselines run on the same data as the estimators (OpenCV imported lazily, inside calls)."""

from ._opencv import opencv_reconstruction as opencv_reconstruction
