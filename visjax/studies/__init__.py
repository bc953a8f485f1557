"""Experiments, vmapped Monte-Carlo sweeps and gain studies."""

from ._euclidean import (
    DEFAULT_GAINS as DEFAULT_GAINS,
    EuclideanRun as EuclideanRun,
    euclidean_experiment as euclidean_experiment,
    final_errors as final_errors,
    initial_estimator as initial_estimator,
)
from ._structure import (
    StructureRun as StructureRun,
    observer_for as observer_for,
    structure_experiment as structure_experiment,
)
from ._velocity import (
    DOF_NAMES as DOF_NAMES,
    VelocityRun as VelocityRun,
    summarise as summarise,
    velocity_experiment as velocity_experiment,
    velocity_noise_study as velocity_noise_study,
)
