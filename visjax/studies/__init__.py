"""Generic studies over any problem: `AbstractProblem` (one definition of "estimate X from
Y": inputs, methods, parameters, metrics, figure; a plain function joins as a
`FunctionProblem`), `evaluate` (one parameter point over noise keys, differentiable),
`compare` (every method on identical inputs), `sweep` (batched over parameter points and
noise keys), `tune` (gradient-based) and `held_out`, each `(problem, ..., keys, *,
study=Study(...))` and returning a `Result` (`.to_pandas()`); `plan` (a study's runs and
memory before it runs); the registries of problems and reproductions the command line
looks up.

The papers' problems live in `visjax.papers`.
"""

from ._compare import (
    Comparison as Comparison,
    StudyTooLong as StudyTooLong,
    compare as compare,
    comparison_report as comparison_report,
    statistics_tables as statistics_tables,
    table_text as table_text,
)
from ._executors import RayExecutor as RayExecutor
from ._methods import Method as Method, WithMethods as WithMethods
from ._parts import (
    PartsError as PartsError,
    clear_parts as clear_parts,
    find_parts as find_parts,
    merge_parts as merge_parts,
    merge_sweeps as merge_sweeps,
    read_manifest as read_manifest,
    saved_runs as saved_runs,
    sweep_parts as sweep_parts,
)
from ._plan import (
    MAX_RUNS as MAX_RUNS,
    Plan as Plan,
    Selection as Selection,
    check_grid as check_grid,
    check_grid_text as check_grid_text,
    check_run_count as check_run_count,
    check_study as check_study,
    grid_size as grid_size,
    merge_summary as merge_summary,
    plan as plan,
    study_runs as study_runs,
    sweep_then_hold_out as sweep_then_hold_out,
    sweep_then_tune as sweep_then_tune,
)
from ._problem import (
    INNOVATION_GATE as INNOVATION_GATE,
    QUALITY_RATIO as QUALITY_RATIO,
    AbstractProblem as AbstractProblem,
    Evaluation as Evaluation,
    FunctionProblem as FunctionProblem,
    Parameter as Parameter,
    as_default as as_default,
    as_json as as_json,
    check_values as check_values,
    evaluate as evaluate,
    fingerprint as fingerprint,
    held as held,
    innovation_line as innovation_line,
    judge as judge,
    judge_innovation as judge_innovation,
    noise_level as noise_level,
    noise_parameter as noise_parameter,
    quality as quality,
    quality_line as quality_line,
    robust_parameters as robust_parameters,
    solution as solution,
)
from ._registry import (
    UserCodeError as UserCodeError,
    add_method as add_method,
    build_problems as build_problems,
    load_module as load_module,
    problem as problem,
    problem_names as problem_names,
    register_problem as register_problem,
    registered as registered,
    remove_method as remove_method,
)
from ._reproductions import (
    REFERENCE_KINDS as REFERENCE_KINDS,
    ROW_KEYS as ROW_KEYS,
    RegisteredReproduction as RegisteredReproduction,
    RunFailed as RunFailed,
    check_rows as check_rows,
    register_reproduction as register_reproduction,
    registered_reproduction as registered_reproduction,
    reproduction_names as reproduction_names,
    reproduction_row as reproduction_row,
)
from ._search import (
    BUDGET as BUDGET,
    MethodTuning as MethodTuning,
    Tuning as Tuning,
    compare_tuned as compare_tuned,
    searched_parameters as searched_parameters,
    tune_methods as tune_methods,
)
from ._stats import (
    Interval as Interval,
    Paired as Paired,
    bootstrap_interval as bootstrap_interval,
    paired_comparison as paired_comparison,
    wilcoxon_signed_rank as wilcoxon_signed_rank,
)
from ._study import (
    Interrupted as Interrupted,
    Refused as Refused,
    Result as Result,
    Study as Study,
    device_mesh as device_mesh,
    handling_signals as handling_signals,
    interruptible as interruptible,
    parse_shard as parse_shard,
)
from ._sweep import (
    MemoryLimitError as MemoryLimitError,
    SweepResult as SweepResult,
    available_memory as available_memory,
    best as best,
    grid as grid,
    held_out as held_out,
    log_axis as log_axis,
    parse_grid as parse_grid,
    random_points as random_points,
    save_table as save_table,
    solution_outputs as solution_outputs,
    solution_table as solution_table,
    summarise as summarise,
    sweep as sweep,
)
from ._tune import TuneResult as TuneResult, objective as objective, tune as tune
from ._verdict import Verdict as Verdict, judge_records as judge_records, verdict as verdict
