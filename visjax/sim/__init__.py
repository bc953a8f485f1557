"""Scenarios: true motion and camera -> measurements and ground truth."""

from ._planar import (
    PlanarScenes as PlanarScenes,
    random_planar_scenes as random_planar_scenes,
    rotation_from_vector as rotation_from_vector,
)
