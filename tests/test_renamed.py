"""The old vocabulary, read on: the names of visjax 0.3 still give the renamed objects, each
with a `FutureWarning` naming the new one; an unknown name is an `AttributeError`."""

import importlib

import pytest

from visjax import design, estimators, geometry, plots
from visjax.papers import hamel, jang, nath, spica

MODULES = (estimators, design, geometry, spica, hamel, jang, nath, plots)
CASES = [(m, old, new) for m in MODULES for old, new in m.RENAMED.items()]


@pytest.mark.parametrize("module, old, new", CASES, ids=[c[1] for c in CASES])
def test_an_old_name_gives_the_new_object_with_a_warning(module, old, new):
    with pytest.warns(FutureWarning, match=f"{module.__name__}.{old} is now .*{new}"):
        got = getattr(module, old)
    assert got is getattr(module, new)
    assert old not in vars(module)  # not a second public name


def test_an_import_of_an_old_name_works_and_an_unknown_name_fails():
    with pytest.warns(FutureWarning, match="MovingPointEstimator"):
        from visjax.estimators import MovingPointObserver  # noqa: F401
    with pytest.raises(AttributeError, match="no attribute 'NoSuchName'"):
        importlib.import_module("visjax.estimators").NoSuchName  # noqa: B018


def test_a_moved_name_says_where_it_went():
    """A paper's helper that left a package below `papers` (which may not import it back)
    is an `AttributeError` naming its new home."""
    from visjax.papers import chitrakaran

    with pytest.raises(AttributeError, match="visjax.papers.chitrakaran.eq56_matrix"):
        estimators.paper_eq56_matrix  # noqa: B018
    assert callable(chitrakaran.eq56_matrix)


def test_the_landmark_problems_pieces_live_in_their_layers():
    """The point-depth and homography observers are `estimators`', their EKF model and the
    OpenCV baseline `baselines`', their scenes `sim`'s; the papers' modules give the same
    objects under their old names."""
    from visjax import baselines, sim

    assert spica.PointDepthEstimator is estimators.PointDepthEstimator
    assert spica.point_depth_stream is estimators.point_depth_stream
    assert spica.InverseDepthModel is baselines.InverseDepthModel
    assert spica.point_depth_scene is sim.point_depth_scene
    assert spica.POINTS is sim.POINT_DEPTH_POINTS
    assert hamel.HomographyEstimator is estimators.HomographyEstimator
    assert hamel.homography_stream is estimators.homography_stream
    assert hamel.ransac_homographies is baselines.ransac_homographies
    assert hamel.homography_scene is sim.homography_scene
    assert hamel.CAMERA is sim.HOMOGRAPHY_CAMERA
