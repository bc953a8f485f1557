"""Experiments, vmapped Monte-Carlo sweeps and gain studies."""

from ._velocity import (
    DOF_NAMES as DOF_NAMES,
    VelocityRun as VelocityRun,
    summarise as summarise,
    velocity_experiment as velocity_experiment,
    velocity_noise_study as velocity_noise_study,
)
