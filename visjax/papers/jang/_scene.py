"""The thesis' experiment sets as visjax simulates them (Jang, *Structure of a moving point seen
by a moving camera*): the camera matrices, the seven sets with their published gains and
numbers, the scenario of a set and the observer with its gains (`visjax.papers.jang` says
what is the thesis' and what is chosen)."""

from dataclasses import dataclass
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ...estimators import (
    MovingPointEstimator,
    Stream,
    moving_point_stream,
)
from ...sim import add_pixel_noise, hold_indices, moving_camera_point, sample_times

KC_TOOLBOX = ((560.98005, 0.0, 303.91196), (0.0, 749.53852, 345.99906), (0.0, 0.0, 1.0))
KC_REFINED = ((551.9794, 0.0, 304.0282), (0.0, 737.5125, 331.5052), (0.0, 0.0, 1.0))


@dataclass(frozen=True)
class ThesisSet:
    """One experiment set of the thesis: its matrices, gains and published RMS (metres)."""

    name: str
    moving: bool
    A: tuple
    D: tuple
    K: tuple
    Y: tuple
    thesis_rms: tuple
    vc_amplitude: tuple = (0.0, 0.0)  # sinusoid added to (v_cx, v_cy), cm/s
    vp_amplitude: tuple = (0.0, 0.0)  # the point's (v_px, v_py) amplitudes, cm/s


SETS = {
    s.name: s
    for s in (
        ThesisSet(
            "I.1",
            False,
            ((0, -0.05, -0.30), (0.05, 0, -1.50), (0, 0, 0)),
            (1, 0, 0),
            ((1.3120, 0), (0, 1.3120), (0.0590, 0)),
            ((0, 0), (0, -1), (0, 1.1793)),
            (0.0016, 0.0047, 0.0214),
        ),
        ThesisSet(
            "I.2",
            False,
            ((0, -0.07, 1.15), (0.07, 0, 1.30), (0, 0, 0)),
            (1, 0, 0),
            ((1.3082, 0), (0, 1.3082), (0.0896, 0)),
            ((0, 0), (0, -1), (0, -1.2796)),
            (0.0040, 0.0065, 0.0284),
        ),
        ThesisSet(
            "I.3",
            False,
            ((0, -0.10, 0), (0.10, 0, -1.50), (0, 0, 0)),
            (1, 0, 0),
            ((1.3292, 0), (0, 1.3292), (0.2016, 0)),
            ((0, 0), (0, -1), (0, 2.0161)),
            (0.0099, 0.0362, 0.0386),
            vc_amplitude=(1.5, 0.0),
        ),
        ThesisSet(
            "I.4",
            False,
            ((0, -0.05, -1.00), (0.05, 0, 0), (0, 0, 0)),
            (0, 1, 0),
            ((1.3149, 0), (0, 1.3149), (0.0590, -0.1256)),
            ((-1, 0), (0, 0), (2.5125, 0)),
            (0.0027, 0.0107, 0.0399),
            vc_amplitude=(0.5, 1.0),
        ),
        ThesisSet(
            "II.1",
            True,
            ((0, -0.05, 1.28), (0.05, 0, -0.38), (0, 0, 0)),
            (1, 0, 0),
            ((1.2298, 0), (0, 1.2298), (0.3476, 0)),
            ((0, 0), (0, -1), (0, 6.9530)),
            (0.0172, 0.0170, 0.0519),
            vp_amplitude=(2.0, 0.0),
        ),
        ThesisSet(
            "II.2",
            True,
            ((0, -0.05, 0), (0.05, 0, -0.30), (0, 0, 0)),
            (1, 0, 0),
            ((1.2443, 0), (0, 1.2443), (0.2763, 0)),
            ((0, 0), (0, -1), (0, 5.5261)),
            (0.0291, 0.0030, 0.0663),
            vc_amplitude=(1.5, 0.0),
            vp_amplitude=(2.0, 0.0),
        ),
        ThesisSet(
            "II.3",
            True,
            ((0, -0.05, -1.00), (0.05, 0, -0.30), (0, 0, 0)),
            (1, 0, 0),
            ((1.2892, 0), (0, 1.2892), (0.2313, 0)),
            ((0, 0), (0, -1), (0, 4.6261)),
            (0.0059, 0.0208, 0.0681),
            vc_amplitude=(0.5, 0.3),
            vp_amplitude=(2.0, 0.05),
        ),
    )
}


def _velocities(s: ThesisSet, t):
    """Camera velocity u = [v_c, w] (cm/s, rad/s) and point velocity v_p (cm/s) at t."""
    A = np.asarray(s.A, float)
    wz, vcx, vcy = A[0, 1], -A[0, 2], -A[1, 2]
    z = jnp.zeros_like(t)
    u = jnp.stack(
        [
            vcx + s.vc_amplitude[0] * jnp.sin(0.5 * t),
            vcy + s.vc_amplitude[1] * jnp.sin(0.4 * t),
            z,
            z,
            z,
            wz + z,
        ]
    )
    v_p = jnp.stack([s.vp_amplitude[0] * jnp.sin(0.5 * t), s.vp_amplitude[1] * jnp.cos(0.3 * t), z])
    return u, v_p


class _SetMotion(eqx.Module):
    """`_velocities(s, t)[which]` as a Module with the set as a static field: the compiled
    integration of eq. (2.11) is reused by every scenario of the set with the same length."""

    s: ThesisSet = eqx.field(static=True)
    which: int = eqx.field(static=True)

    def __call__(self, t):
        return _velocities(self.s, t)[self.which]


@final
class ThesisScenario(eqx.Module):
    """A simulated experiment set: the 1 kHz truth and the 30 Hz camera measurements.

    **Fields:** `ts` (N,) at 1 kHz; `x` (N, 3) true $[X/Z, Y/Z, 1/Z]$ (1/cm); `position`
    (N, 3) true $[X, Y, Z]$ in metres; `frame_ts` (F,) the camera's 30 Hz frame times,
    `frame_pixels` (F, 2) its noisy pixels and `frame_velocities` (F, 6) the measured
    camera velocities (cm/s, rad/s) at those frames; `frame_index` (N,) the frame held at
    each 1 kHz sample; `Kc_true`, `Kc_observer`.
    """

    ts: Float[Array, " N"]
    x: Float[Array, "N 3"]
    position: Float[Array, "N 3"]
    frame_ts: Float[Array, " F"]
    frame_pixels: Float[Array, "F 2"]
    frame_velocities: Float[Array, "F 6"]
    frame_index: Array
    Kc_true: Float[Array, "3 3"]
    Kc_observer: Float[Array, "3 3"]

    def camera_stream(self) -> Stream:
        """The UIO's stream of the 30 Hz camera frames (run it with `dt=1e-3`)."""
        return moving_point_stream(
            self.frame_ts, self.frame_pixels, self.frame_velocities, self.Kc_observer
        )

    def held_stream(self) -> Stream:
        """The same frames held at the 1 kHz samples (as a logger at 1 kHz records them),
        with the true state as `truth`."""
        pixels, velocities = _held(self.frame_pixels, self.frame_velocities, self.frame_index)
        return moving_point_stream(self.ts, pixels, velocities, self.Kc_observer, truth=self.x)


def scenario(
    set_name: str,
    duration: float = 30.0,
    *,
    rate_hz: int = 1000,
    camera_hz: int = 30,
    noise_px: float = 0.0,
    key: PRNGKeyArray | None = None,
    Kc_observer=KC_REFINED,
    depth_cm: float = 80.0,
) -> ThesisScenario:
    """The simulated analogue of a thesis experiment set (`"I.1"` ... `"II.3"`).

    **Arguments:**

    - `set_name`: the set.
    - `duration`: seconds.
    - `rate_hz`: the truth's and the observer's rate (1 kHz in the thesis).
    - `camera_hz`: the camera's rate (30 Hz).
    - `noise_px`: Gaussian pixel noise (sigma, px) on the image measurements.
    - `key`: PRNG key, required with noise.
    - `Kc_observer`: the camera matrix the observer uses to normalize pixels.
    - `depth_cm`: the point's depth.
    """
    if set_name not in SETS:
        raise ValueError(f"unknown set {set_name!r}; expected one of {list(SETS)}.")
    s = SETS[set_name]
    ts = sample_times(duration, rate_hz)
    n = ts.shape[0]
    # start so that the image of the point crosses the centre mid-run
    u_mean, vp_mean = _velocities(s, jnp.zeros(()))
    drift = (np.asarray(u_mean[:2]) - np.asarray(vp_mean[:2])) * duration / 2
    x0 = jnp.array([drift[0] / depth_cm, drift[1] / depth_cm, 1.0 / depth_cm])
    x = moving_camera_point(_SetMotion(s, 0), _SetMotion(s, 1), x0, ts)  # eq. (2.11)
    # camera: sample at camera_hz, hold; the sample index by integer arithmetic
    held, first = hold_indices(n, rate_hz, camera_hz)
    Kc_true = jnp.array(KC_REFINED)
    position, frame_ts, p, u_frames = _measurements(_SetMotion(s, 0), ts, x, first, Kc_true)
    p = add_pixel_noise(key, p, noise_px)
    return ThesisScenario(
        ts=ts,
        x=x,
        position=position,
        frame_ts=frame_ts,
        frame_pixels=p,
        frame_velocities=u_frames,
        frame_index=jnp.asarray(held),
        Kc_true=Kc_true,
        Kc_observer=jnp.asarray(Kc_observer, float),
    )


@eqx.filter_jit
def _measurements(camera_twist, ts, x, first, Kc_true):
    """The true position (m), the frame times, the frames' pixels and the camera velocities
    at the frames (one compiled program, not one per operation)."""
    position = jnp.stack([x[:, 0] / x[:, 2], x[:, 1] / x[:, 2], 1.0 / x[:, 2]], axis=1) / 100.0
    p = x[first, :2] @ Kc_true[:2, :2].T + Kc_true[:2, 2][None, :]
    return position, ts[first], p, jax.vmap(camera_twist)(ts[first])


@jax.jit
def _held(pixels, velocities, k):
    return pixels[k], velocities[k]


def observer(set_name: str, K=None, Y=None, x3_guess_cm: float = 100.0) -> MovingPointEstimator:
    """The UIO of a thesis set, with the thesis' gains unless `K`, `Y` are given."""
    s = SETS[set_name]
    return MovingPointEstimator(
        A=s.A,
        D=jnp.array(s.D, float)[:, None],
        K=s.K if K is None else K,
        Y=s.Y if Y is None else Y,
        x3_guess=1.0 / x3_guess_cm,
    )


@final
class MovingPointRun(eqx.Module):
    """One set: times, true and estimated positions (metres, camera frame), RMS window, and
    the camera velocity the observer was given at the 30 Hz frames (`frame_ts`,
    `camera_velocity` (F, 6) $= [v_c, \\omega_c]$ in m/s and rad/s, camera frame: the
    thesis' Figs. 5-5/5-6 and their like for each set)."""

    ts: Float[Array, " N"]
    position: Float[Array, "N 3"]
    estimate: Float[Array, "N 3"]
    rms: Float[Array, "3"]
    frame_ts: Float[Array, " F"]
    camera_velocity: Float[Array, "F 6"]
