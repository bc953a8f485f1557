"""Documented data formats: each estimator's input as a file (NPZ, and CSV for pixel
tracks), for users with their own logged data. See `visjax.io._formats` for the tables."""

from ._formats import (
    DataFormatError as DataFormatError,
    EuclideanData as EuclideanData,
    StructureData as StructureData,
    VelocityData as VelocityData,
    load_tracks_csv as load_tracks_csv,
    save_tracks_csv as save_tracks_csv,
)
