"""The three estimation problems as comparisons: the paper's estimator, its batch
baselines (all frames, sliding window) and its EKF, on identical noisy inputs, from a
paper's scenario or from a user's data file (`visjax.io`). `studies.compare` runs them."""

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Problem:
    """A comparison set up for `studies.compare`.

    **Fields:** `name`; `methods` (name -> pure function of the inputs, returning a
    `Solution` with a result code); `inputs` (`key -> (inputs, truth)`, noise added to
    the pixels); `score` (`(method, solution, truth) -> dict` of the estimator's own
    accuracy keys, `None` for a failed run); `updates` (estimate updates per call, for the
    latency); `accuracy` (record -> the headline number of the figure) and its `label`;
    `settings` (every stated setting: gains, windows, bandwidths, noise models).
    """

    name: str
    methods: dict
    inputs: Any
    score: Any
    updates: dict
    accuracy: Any
    label: str
    settings: dict = field(default_factory=dict)


def structure_observer_for_data(data):
    """The unknown input observer of Jang's thesis for a `StructureData` file, and the
    camera velocities at the frame times.

    The camera velocities are interpolated (linearly) to the frame times; the observer's
    $A(u)$ is the thesis' matrix of the camera velocities (`THESIS_A_U`), and its gains
    are designed by `visjax.design.design_uio_for_motion` for the velocity range of the
    file (10% margin) and the measured velocities (up to the first 250 frames), with
    $D$ the file's unknown-input direction. The design takes $\\bar f = 0$ (Lipschitz
    bound 0): exact for a camera that translates parallel to its image plane and turns
    about its optical axis; other motion ($v_{cz}$, $\\omega_x$, $\\omega_y$) is returned
    as `unmodelled_motion`.

    **Returns:** `(observer, u, info)`: `u` (N, 6) the velocities at the frame times and
    `info` a dict (`depth_guess_m`, `D`, `design`, `unmodelled_motion`).
    """
    from ..design import design_uio_for_motion
    from ..estimators import UnknownInputObserver

    t = np.asarray(data.t, float)
    u = np.stack(
        [np.interp(t, data.camera_t, data.camera_velocity[:, j]) for j in range(6)], axis=1
    )
    lo, hi = u.min(axis=0), u.max(axis=0)
    mid, half_width = (lo + hi) / 2, (hi - lo) / 2
    u_range = (mid - 1.1 * half_width, mid + 1.1 * half_width)
    D = np.asarray(data.D, float) / np.linalg.norm(data.D)
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    frame_dt = float(np.median(np.diff(t)))
    design, rate = design_uio_for_motion(np.zeros((3, 3)), C, D, u_range, u[:250], frame_dt)
    depth_guess = 1.0 if data.depth_guess is None else float(data.depth_guess)
    observer = UnknownInputObserver(
        A=np.zeros((3, 3)), D=D, x3_guess=1.0 / depth_guess, **design.observer_fields()
    )
    info = {
        "depth_guess_m": depth_guess,
        "D": [float(x) for x in D],
        "design": {
            "method": "design_uio_for_motion",
            "alpha": float(design.alpha),
            "convergence_rate_per_s": float(rate),
        },
        "unmodelled_motion": float(np.max(np.abs(u[:, [2, 3, 4]]))),
    }
    return observer, u, info


def _noisy(key, pixels, noise_px):
    """The pixels plus i.i.d. Gaussian noise (sigma `noise_px`); NaN (not seen) stays NaN."""
    import jax.numpy as jnp

    from ..sim import add_pixel_noise

    if noise_px == 0:
        return jnp.asarray(pixels)
    return add_pixel_noise(key, jnp.asarray(pixels), noise_px)


def _held(sample_ts, values, t):
    """`values` (at `sample_ts`) held at the times `t`: the last sample at or before each."""
    k = np.searchsorted(np.asarray(sample_ts), np.asarray(t) + 1e-9, side="right") - 1
    return np.asarray(values)[np.clip(k, 0, len(sample_ts) - 1)]


def _last_half(t):
    t = np.asarray(t)
    return t >= t[0] + 0.5 * (t[-1] - t[0])


def _ok(sol) -> bool:
    from .._results import result_names

    return result_names(sol.result) == "successful"


def _rms_last_half(sol, field, truth_ts, truth, scale=1.0):
    """RMS per component over the second half of the run, of `sol.outputs.<field>` (times
    `scale`) against the truth held at the solution's times; `None` for a failed run."""
    if truth is None or not _ok(sol):
        return None
    t = np.asarray(sol.ts)
    est = np.asarray(getattr(sol.outputs, field)) * scale
    err = est - _held(truth_ts, truth, t)
    err = err[_last_half(t)]
    return [float(x) for x in np.sqrt(np.mean(err.reshape(err.shape[0], -1) ** 2, axis=0))]
