"""Rigid-body motion and serial-robot kinematics."""

from ._rigid import integrate_pose as integrate_pose
