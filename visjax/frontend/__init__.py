"""Pixels from images: KLT tracking, video files and synthetic rendering (NumPy and OpenCV,
imported lazily; never jit)."""

from ._bags import BAG_PROBLEMS as BAG_PROBLEMS, import_bag as import_bag
from ._klt import klt_track as klt_track, klt_translation as klt_translation
from ._render import render_marker as render_marker
from ._scene_render import (
    TAG_FAMILIES as TAG_FAMILIES,
    Plane as Plane,
    fiducial_marker as fiducial_marker,
    plane_homography as plane_homography,
    project_points as project_points,
    render_planes as render_planes,
    textured_table as textured_table,
)
from ._tags import detect_tags as detect_tags, track_tags as track_tags
from ._tracking import (
    LOST_REASONS as LOST_REASONS,
    Tracks as Tracks,
    detect_aruco as detect_aruco,
    reject_homography_outliers as reject_homography_outliers,
    track_frames as track_frames,
    track_marker as track_marker,
)
from ._video import (
    annotate_frames as annotate_frames,
    read_video as read_video,
    write_video as write_video,
)
