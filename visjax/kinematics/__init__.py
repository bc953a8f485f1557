"""Rigid-body motion, perspective dynamics and serial-robot kinematics (Jang's thesis,
chapter 4: the PUMA 560 and a two-link planar robot)."""

from ._perspective import (
    camera_term as camera_term,
    known_input_term as known_input_term,
    perspective_dynamics as perspective_dynamics,
)
from ._rigid import integrate_pose as integrate_pose
from ._serial import (
    PUMA560_TABLE as PUMA560_TABLE,
    InverseVelocity as InverseVelocity,
    PoseSolution as PoseSolution,
    SerialChain as SerialChain,
    TwoLinkArm as TwoLinkArm,
    link_transform as link_transform,
    puma560 as puma560,
    puma560_forward as puma560_forward,
)
