"""Generic studies over any estimator or baseline: comparisons on identical inputs (sweeps
and tuning to come).

The papers' own experiments live in `visjax.papers`.
"""

from ._compare import compare as compare
from ._problems import (
    Problem as Problem,
    euclidean_problem as euclidean_problem,
    structure_observer_for_data as structure_observer_for_data,
    structure_problem as structure_problem,
    velocity_observer_bandwidth_hz as velocity_observer_bandwidth_hz,
    velocity_problem as velocity_problem,
)
