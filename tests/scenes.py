"""Estimator-level helpers for the moving-target scenes of `visjax.sim`'s catalogue
(`sim.sideways_camera_scene`, `sim.circling_camera_scene`), shared by the tests and
`benchmarks/scenes_uio.py`: the unknown-input directions of each scene, the camera's 50 Hz
frame stream, the UIO designs (`visjax.design`) and observer, and the RMS error over the
last half of a run.

The truth is the scene at 1 kHz; the camera records frames at 50 Hz (pixels with optional
Gaussian noise, and the camera velocity in the camera frame); the observer runs at 1 kHz on
the held frames (`run(..., dt=1e-3)`), and the RMS of the position error (camera frame,
metres) is taken over the last half of the run against the 1 kHz truth. The initial depth
guess is 4 m ($x_{3,\\mathrm{guess}} = 0.25$/m).
"""

import jax.numpy as jnp
import numpy as np

from visjax import sim
from visjax.design import design_uio, design_uio_for_motion
from visjax.estimators import (
    MOVING_POINT_A_U,
    MovingPointEstimator,
    SaveAt,
    moving_point_stream,
    run,
)
from visjax.sim import add_pixel_noise

K_C = sim.MOVING_TARGET_K
IMAGE = sim.MOVING_TARGET_IMAGE
RATE_HZ = sim.MOVING_TARGET_RATE_HZ
CAMERA_HZ = sim.MOVING_TARGET_FRAME_HZ
X3_GUESS = 1.0 / 4.0

# the unknown input's directions: `sideways`, D1 = [0, 1, 0] (the target's image motion is
# vertical, d = v_py x_3, eq. (3.21)); `circle_diagonal`, the UUB split: D1 = [0, 1, 0]
# decoupled, D2 = [1, 0, 0] (d_2 = v_px x_3) a bounded disturbance
_DIRECTIONS = {
    "sideways": dict(D1=(0.0, 1.0, 0.0), D2=(0.0, 0.0, 0.0)),
    "circle_diagonal": dict(D1=(0.0, 1.0, 0.0), D2=(1.0, 0.0, 0.0)),
}
SCENES = {name: {**s, **_DIRECTIONS[name]} for name, s in sim.MOVING_TARGET_SCENES.items()}

scene = sim.moving_target_scene


def camera_stream(truth, noise_px: float = 0.0, key=None, drop=None, dropped="hold"):
    """The 50 Hz frames of a scene: pixels (noise, dropped frames: NaN, out of view: NaN)
    and the camera velocity; `drop` a boolean mask over the frames; `dropped` how the
    stream replaces a missing frame (`moving_point_stream`)."""
    step = RATE_HZ // CAMERA_HZ
    frames = slice(0, None, step)
    pixels = add_pixel_noise(key, truth.pixels[frames], noise_px)
    if drop is not None:
        pixels = jnp.where(jnp.asarray(drop)[:, None], jnp.nan, pixels)
    return moving_point_stream(
        truth.ts[frames], pixels, truth.camera_velocity[frames], K_C, dropped=dropped
    )


def velocity_range(name: str, margin: float = 1.1):
    """The box of camera velocities the design covers: the scene's planned peak speeds
    (known to whoever commands the camera), times a margin."""
    s = SCENES[name]
    w = 2.0 * np.pi * s["frequency_hz"]
    peak = (s["amplitude"] if name == "sideways" else s["radius"]) * w * margin
    u_max = np.zeros(6)
    u_max[0] = peak
    if name != "sideways":
        u_max[1] = peak
    return -u_max, u_max


def design(name: str, option: str, **grid):
    """The observer fields of a scene for one design option (see `DESIGNS`), and the
    `MovingPointDesign`; `grid` goes to `design_uio_for_motion` (the test uses a small grid)."""
    s = SCENES[name]
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    D1 = np.array(s["D1"])
    uub = bool(np.any(np.asarray(s["D2"]) != 0))
    if option == "fixed_A_peak":
        # the thesis' form: A frozen at the peak velocity, (3.6) with a small Lipschitz bound
        u = velocity_range(name, 1.0)[1]
        A = np.einsum("j,jab->ab", u, MOVING_POINT_A_U)
        d = design_uio(A, C, D1, 1e-3, uub=uub)
        return {"A": A, "K": d.K, "Y": d.Y}, d
    if option.startswith("persistent"):
        alpha = float(option.split("_alpha")[1]) if "_alpha" in option else 0.0
        d = design_uio(
            np.zeros((3, 3)),
            C,
            D1,
            0.0,
            u_range=velocity_range(name),
            persistent=True,
            alpha=alpha,
        )
        return {"A": np.zeros((3, 3)), **d.observer_fields()}, d
    if option.startswith("motion"):
        # the persistent design whose error decays fastest over one period of the planned
        # camera velocity (sampled at the camera's 50 Hz)
        if option == "motion_line_D":
            # D along the target's line (its direction known, its speed not): exact
            # decoupling of the whole unknown input, no D2 (eq. (3.21) with v_p = s e)
            e = np.asarray(s["target_velocity"], float)
            D1 = e / np.linalg.norm(e)
        truth = scene(name, 1.0 / s["frequency_hz"])
        step = RATE_HZ // CAMERA_HZ
        u_plan = np.asarray(truth.camera_velocity[::step])
        d, rate = design_uio_for_motion(
            np.zeros((3, 3)), C, D1, velocity_range(name), u_plan, 1.0 / CAMERA_HZ, **grid
        )
        fields = {"A": np.zeros((3, 3)), **d.observer_fields(), "D": D1}
        if option == "motion_line_D":
            fields["D2"] = np.zeros(3)
        return fields, d
    raise ValueError(option)


def observer(name: str, fields) -> MovingPointEstimator:
    s = SCENES[name]
    fields = {"D": s["D1"], "D2": s["D2"], **fields}
    return MovingPointEstimator(x3_guess=X3_GUESS, **fields)


def rms_last_half(name: str, obs, truth, stream, throw: bool = True):
    """The RMS of the position error (m) over the last half, and the run's result."""
    sol = run(obs, stream, dt=1.0 / RATE_HZ, saveat=SaveAt(), throw=throw)
    n = sol.ts.shape[0]
    est = np.asarray(sol.outputs.position)
    true = np.asarray(truth.position[:n])
    half = np.asarray(sol.ts) >= 0.5 * float(truth.ts[-1])
    err = est[half] - true[half]
    return np.sqrt(np.mean(err**2, axis=0)), sol
