"""Rigid-body motion and serial-robot kinematics."""

from ._perspective import (
    camera_term as camera_term,
    known_input_term as known_input_term,
    perspective_dynamics as perspective_dynamics,
)
from ._rigid import integrate_pose as integrate_pose
