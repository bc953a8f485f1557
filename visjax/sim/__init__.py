"""Scenarios: true motion and camera -> measurements and ground truth."""

from ._fixed_camera import (
    K_EQ63 as K_EQ63,
    RHO_EQ63 as RHO_EQ63,
    FixedCameraScenario as FixedCameraScenario,
    fixed_camera_scenario as fixed_camera_scenario,
    section6_velocity as section6_velocity,
)
from ._moving_camera import (
    KC_REFINED as KC_REFINED,
    KC_TOOLBOX as KC_TOOLBOX,
    SETS as SETS,
    MovingCameraScenario as MovingCameraScenario,
    ThesisSet as ThesisSet,
    moving_camera_scenario as moving_camera_scenario,
)
from ._planar import (
    PlanarScenes as PlanarScenes,
    random_planar_scenes as random_planar_scenes,
    rotation_from_vector as rotation_from_vector,
)
from ._uncalibrated import (
    UncalibratedScenario as UncalibratedScenario,
    uncalibrated_scenario as uncalibrated_scenario,
)
