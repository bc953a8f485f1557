"""Documented data formats: each estimator's input as a file (NPZ, and CSV for pixel
tracks), for users with their own logged data (the tables are in `visjax.io._formats`); and
the outputs of the command line: the schema of every `summary.json`, table and array file
(`SUMMARIES`, `TABLES`, `ARRAYS`), checked when written and loaded with `read_summary`;
staged (atomic) output folders (`staged_output`); and the writing of a command's files and
summary (`Outputs`, `write_outputs`, `command_summary`)."""

from ._bags import (
    BagRecording as BagRecording,
    pose_from_text as pose_from_text,
    read_bag as read_bag,
)
from ._formats import (
    DATA_FORMATS as DATA_FORMATS,
    DROPPED_RESULT as DROPPED_RESULT,
    MAX_DATA_BYTES as MAX_DATA_BYTES,
    MAX_DROPPED_FRACTION as MAX_DROPPED_FRACTION,
    MAX_INTERVAL_S as MAX_INTERVAL_S,
    MAX_LENGTH_M as MAX_LENGTH_M,
    MIN_INTERVAL_S as MIN_INTERVAL_S,
    MIN_LENGTH_M as MIN_LENGTH_M,
    MIN_OBSERVATIONS as MIN_OBSERVATIONS,
    SLOW_INTERVAL_S as SLOW_INTERVAL_S,
    TIME_UNITS as TIME_UNITS,
    DataFormatError as DataFormatError,
    MovingPointData as MovingPointData,
    StaticPointsData as StaticPointsData,
    VelocityData as VelocityData,
    coverage_line as coverage_line,
    dropped_report as dropped_report,
    file_coverage as file_coverage,
    load_tracks_csv as load_tracks_csv,
    max_data_bytes as max_data_bytes,
    read_npz as read_npz,
    save_tracks_csv as save_tracks_csv,
)
from ._from_tracks import (
    COPLANAR_PX as COPLANAR_PX,
    PROBLEMS as PROBLEMS,
    choose_coplanar as choose_coplanar,
    data_from_tracks as data_from_tracks,
    read_camera_file as read_camera_file,
    read_tracks as read_tracks,
)
from ._outputs import (
    ARRAYS as ARRAYS,
    COMMON as COMMON,
    READ_ONLY_KINDS as READ_ONLY_KINDS,
    RENAMED_KINDS as RENAMED_KINDS,
    SUMMARIES as SUMMARIES,
    TABLES as TABLES,
    finite_or_null as finite_or_null,
    read_summary as read_summary,
    schema_markdown as schema_markdown,
    validate_summary as validate_summary,
    write_summary as write_summary,
)
from ._staging import (
    OutputConflictError as OutputConflictError,
    check_output_path as check_output_path,
    output_name as output_name,
    staged_output as staged_output,
    user_path as user_path,
    written_directly as written_directly,
)
from ._writing import (
    Outputs as Outputs,
    command_summary as command_summary,
    figure_files as figure_files,
    write_outputs as write_outputs,
)
