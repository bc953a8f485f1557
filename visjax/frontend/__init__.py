"""Pixels from images: KLT tracking and synthetic rendering (NumPy and OpenCV, not jit)."""

from ._klt import klt_track as klt_track, klt_translation as klt_translation
from ._render import render_marker as render_marker
