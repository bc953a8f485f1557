"""The homography problem's scene constants (its own scene, not the paper's: Hamel et al.,
*Homography estimation on the Special Linear group*; the scene is
`visjax.sim.homography_scene`) and its robust baselines' settings."""

from ...sim import (
    HOMOGRAPHY_ANGULAR_VELOCITY,
    HOMOGRAPHY_CAMERA,
    HOMOGRAPHY_PLANE_DISTANCE,
    HOMOGRAPHY_PLANE_POINTS,
    HOMOGRAPHY_START,
    HOMOGRAPHY_START_ROTATION,
    HOMOGRAPHY_VELOCITY,
)

# ---------------------------------------------------------------------------------------
# The problem `homography`: a camera moving before a planar target (its own scene, not the
# paper's), the observer against per-frame homographies; and the observer as the front end
# of the velocity problem of Chitrakaran et al.

# the scene's constants, under the names of version 3 (`visjax.sim.HOMOGRAPHY_*`)
PLANE_POINTS = HOMOGRAPHY_PLANE_POINTS
PLANE_DISTANCE = HOMOGRAPHY_PLANE_DISTANCE
START = HOMOGRAPHY_START
START_ROTATION = HOMOGRAPHY_START_ROTATION
VELOCITY = HOMOGRAPHY_VELOCITY
ANGULAR_VELOCITY = HOMOGRAPHY_ANGULAR_VELOCITY
CAMERA = HOMOGRAPHY_CAMERA


ROBUST_ITERATIONS = 200  # RANSAC hypotheses per frame of the robust `dlt` (8 points)
ROBUST_THRESHOLD_PX = 3.0  # its inlier threshold, as the OpenCV `ransac` baseline's
