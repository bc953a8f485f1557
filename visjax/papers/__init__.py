"""One module per paper: its constants, published gains and numbers, its scenario (built
with `visjax.sim`), its experiment and metrics; and the problems built on `visjax.studies`.
Nothing outside knows a paper's numbers.

- `chitrakaran`: Chitrakaran, Dawson, Dixon, Chen, *Identification of a moving object's
  velocity with a fixed camera* (the velocity estimator, section 6). Problem: `velocity`
  (`VelocityProblem`, `velocity_problem`).
- `jang`: Jang's thesis on the structure of a moving point seen by a moving camera (the
  unknown input observer, seven experiment sets). Problem: `moving_point`
  (`MovingPointProblem`, `moving_point_problem`; one variant per experiment set).
- `nath`: Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features
  using a moving uncalibrated camera* (the adaptive least-squares estimator). Problem:
  `static_points` (`StaticPointsProblem`, `static_points_problem`).

Beyond the three papers:

- `spica`: Spica, Robuffo Giordano, Chaumette, *Active Structure from Motion: Application
  to Point, Sphere, and Cylinder* (the observer of the depth of static points). Problem:
  `point_depth` (`spica.PointDepthProblem`, `spica.point_depth_problem`; variants
  `planar` and `spherical`).
- `hamel`: Hamel, Mahony, Trumpf, Morin, Hua, *Homography estimation on the Special Linear
  group based on direct point correspondence* (the observer on SL(3)). Problem:
  `homography` (`hamel.HomographyProblem`, `hamel.VelocityFrontEndProblem`,
  `hamel.homography_problem`; variants `tracking` and `velocity_front_end`).
"""

from .. import studies as _studies
from . import (
    chitrakaran as chitrakaran,
    hamel as hamel,
    jang as jang,
    nath as nath,
    spica as spica,
)
from ._reproduction import Reproduction as Reproduction
from .chitrakaran import (
    VelocityProblem as VelocityProblem,
    velocity_observer_bandwidth_hz as velocity_observer_bandwidth_hz,
    velocity_problem as velocity_problem,
)
from .jang import (
    MovingPointProblem as MovingPointProblem,
    moving_point_observer_for_data as moving_point_observer_for_data,
    moving_point_problem as moving_point_problem,
)
from .nath import (
    FinalEstimate as FinalEstimate,
    StaticPointsProblem as StaticPointsProblem,
    static_points_problem as static_points_problem,
)

_studies.register_problem(
    "velocity",
    velocity_problem,
    summary="velocity of a moving planar object, fixed camera (Chitrakaran et al.)",
    replace=True,
)
_studies.register_problem(
    "moving_point",
    moving_point_problem,
    variants=tuple(jang.SETS),
    aliases=("structure",),
    summary="position of a moving point, moving camera (Jang's thesis)",
    replace=True,
)
_studies.register_problem(
    "static_points",
    static_points_problem,
    aliases=("euclidean",),
    summary="positions of static features, uncalibrated moving camera (Nath et al.)",
    replace=True,
)
_studies.register_problem(
    "point_depth",
    spica.point_depth_problem,
    variants=("planar", "spherical"),
    aliases=("point-depth",),  # its name before version 0.4
    summary="depth of static points, moving camera with known velocity (Spica et al.)",
    replace=True,
)
_studies.register_problem(
    "homography",
    hamel.homography_problem,
    variants=("tracking", "velocity_front_end"),
    summary="homography of a planar target on SL(3), moving camera (Hamel et al.)",
    replace=True,
)

# the reproductions `visjax reproduce` runs, in this order (`studies.register_reproduction`)
_studies.register_reproduction(
    "velocity",
    chitrakaran.reproduce_velocity,
    title="Chitrakaran et al., section 6: the velocity estimator",
    quick="in full",
    replace=True,
)
_studies.register_reproduction(
    "geometry",
    chitrakaran.reproduce_geometry,
    title="Chitrakaran et al., section 3: Euclidean reconstruction vs OpenCV",
    quick="20 scenes, not 100",
    replace=True,
)
_studies.register_reproduction(
    "moving_point",
    jang.reproduce_moving_point,
    title="Jang's thesis: the unknown input observer on the seven sets (simulated)",
    quick="20 s per set, not 30",
    replace=True,
)
_studies.register_reproduction(
    "static_points",
    nath.reproduce_static_points,
    title="Nath et al.: Euclidean structure from an uncalibrated moving camera",
    quick="20 s, not 30",
    replace=True,
)
_studies.register_reproduction(
    "testbed",
    jang.reproduce_testbed,
    title="Jang's thesis, chapters 4-5: the testbed twin (PUMA 560, rendered video, KLT)",
    quick="sets I.1 and II.1 of 10 s, without the camera matrix and v_py studies",
    replace=True,
)
_studies.register_reproduction(
    "point_depth",
    spica.reproduce_point_depth,
    title="Spica et al.: the depth error against the assigned second-order response",
    quick="1.5 s, not 2",
    replace=True,
)
_studies.register_reproduction(
    "homography",
    hamel.reproduce_homography,
    title="Hamel et al.: the SL(3) observer as the velocity estimator's front end",
    quick="2 seeds of 4 s, not 5 of 10",
    replace=True,
)
