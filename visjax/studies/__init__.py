"""Generic studies over any estimator or baseline: comparisons on identical inputs
(`compare`), batched sweeps over gains and noise seeds (`sweep`) and gradient-based tuning
(`tune`).

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
from ._sweep import (
    best as best,
    grid as grid,
    log_axis as log_axis,
    parse_grid as parse_grid,
    random_points as random_points,
    save_table as save_table,
    summarise as summarise,
    sweep as sweep,
)
from ._tune import TuneResult as TuneResult, objective as objective, tune as tune
from ._tuning import (
    TuningProblem as TuningProblem,
    euclidean_tuning as euclidean_tuning,
    structure_tuning as structure_tuning,
    velocity_tuning as velocity_tuning,
)
