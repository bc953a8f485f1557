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
from ._moving_point import (
    MovingPointProblem as MovingPointProblem,
    moving_point_observer_for_data as moving_point_observer_for_data,
    moving_point_problem as moving_point_problem,
)
from ._reproduction import Reproduction as Reproduction
from ._static_points import (
    FinalEstimate as FinalEstimate,
    StaticPointsProblem as StaticPointsProblem,
    static_points_problem as static_points_problem,
)
from ._velocity import (
    VelocityProblem as VelocityProblem,
    velocity_observer_bandwidth_hz as velocity_observer_bandwidth_hz,
    velocity_problem as velocity_problem,
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
