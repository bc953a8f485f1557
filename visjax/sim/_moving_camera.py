"""Simulated analogues of the seven experiment sets of seed 003 (Jang's thesis, chapter 5).

A point seen by a camera on a PUMA 560 (I.1-I.4: the point is static; II.1-II.3: it moves
on a two-link robot). The truth is the perspective dynamics (2.11) integrated with an
8th-order solver (`visjax.kinematics.perspective_dynamics`, the same function the observer
uses); the camera samples the image (pixel noise optional) and its velocities at 30 Hz, as
in the thesis (section 5.1); the observer runs at 1 kHz on the held samples.

What the thesis leaves open, chosen here (each a documented assumption):

- **Units.** The thesis' PUMA dimensions are in centimetres (Table 4-1), and its matrices
  $A = [[0, \\omega_z, -v_{cx}], [-\\omega_z, 0, -v_{cy}], [0, 0, 0]]$ (THESIS_NOTES, restored)
  are only physically consistent if $v_c$ is in cm/s: read in m/s, set I.1's camera would
  cross a metre of table per second and lose the point within a second. So lengths are in
  cm inside the scenario and the observer ($x_3 = 1/Z$ in 1/cm); positions are reported in
  metres, as the thesis' RMS tables are.
- **Camera velocities.** $\\omega_z$, $v_{cx}$, $v_{cy}$ are read off each set's $A$; the other
  three are 0 (the downward-looking camera of section 5.2). Where the thesis says the
  velocity is time-varying (I.3, I.4, II.2, II.3), a sinusoid is added around the value of
  $A$ (amplitudes in `SETS`).
- **The point.** Depth 80 cm (a camera above a work table); the start is placed so that the
  image of the point crosses the image centre mid-run. Moving sets: the two-link robot
  moves it in a plane parallel to the image plane (Assumption 3.1) with
  $v_{px} = 2\\sin(0.5t)$ cm/s, and in II.3 also $v_{py} = 0.05\\cos(0.3t)$ cm/s (the second
  unknown input, the UUB case). It drives $e_3$ through $M_{32} = Y_{32} = 4.6$ (the
  thesis' gains): noise-free, $|e_3|$ stays below about $0.8\\,x_3$ at this amplitude and
  grows in proportion to it, so a larger $v_{py}$ (1.5 cm/s gives errors of metres) makes
  the depth meaningless; the second input is kept small.
- **Camera.** The true camera is the thesis' least-squares $\\hat K_c$; the observer may be
  given the thesis' toolbox $K_c$ (the perturbed nominal of Tables 5-1/5-2) or a refined one.
- **Durations.** 30 s; steady-state RMS over the last 15 s.
"""

from dataclasses import dataclass

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..kinematics import perspective_dynamics

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


class MovingCameraScenario(eqx.Module):
    """A simulated experiment set: the 1 kHz truth and the 30 Hz camera measurements.

    **Fields:** `ts` (N,) at 1 kHz; `x` (N, 3) true $[X/Z, Y/Z, 1/Z]$ (1/cm); `position`
    (N, 3) true $[X, Y, Z]$ in metres; `y` (N, 2) and `u` (N, 6): the held 30 Hz camera
    measurements (normalized coordinates through the observer's $K_c$, cm/s and rad/s);
    `pixels` (N, 2) the held noisy pixels; `Kc_true`.
    """

    ts: Float[Array, " N"]
    x: Float[Array, "N 3"]
    position: Float[Array, "N 3"]
    y: Float[Array, "N 2"]
    u: Float[Array, "N 6"]
    pixels: Float[Array, "N 2"]
    Kc_true: Float[Array, "3 3"]


def moving_camera_scenario(
    set_name: str,
    duration: float = 30.0,
    *,
    rate_hz: int = 1000,
    camera_hz: int = 30,
    noise_px: float = 0.0,
    key: PRNGKeyArray | None = None,
    Kc_observer=KC_REFINED,
    depth_cm: float = 80.0,
) -> MovingCameraScenario:
    """The simulated analogue of a thesis experiment set (`"I.1"` ... `"II.3"`).

    **Arguments:**

    - `set_name`: the set.
    - `duration`: seconds.
    - `rate_hz`: the observer's rate (1 kHz in the thesis).
    - `camera_hz`: the camera's rate (30 Hz); samples are held (zero-order hold). The
      hold index is integer arithmetic, exact.
    - `noise_px`: Gaussian pixel noise (sigma, px) on the image measurements.
    - `key`: PRNG key, required with noise.
    - `Kc_observer`: the camera matrix the observer uses to normalize pixels.
    - `depth_cm`: the point's depth.
    """
    if set_name not in SETS:
        raise ValueError(f"unknown set {set_name!r}; expected one of {list(SETS)}.")
    if noise_px > 0 and key is None:
        raise ValueError("`key` is required when `noise_px > 0`.")
    s = SETS[set_name]
    n = int(round(duration * rate_hz))
    ts = jnp.arange(n) / rate_hz
    # start so that the image of the point crosses the centre mid-run
    u_mean, vp_mean = _velocities(s, jnp.zeros(()))
    drift = (np.asarray(u_mean[:2]) - np.asarray(vp_mean[:2])) * duration / 2
    x0 = jnp.array([drift[0] / depth_cm, drift[1] / depth_cm, 1.0 / depth_cm])

    def field(t, x, args):
        u, v_p = _velocities(s, t)
        return perspective_dynamics(x, u, v_p)  # eq. (2.11)

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(field),
        diffrax.Dopri8(),
        0.0,
        ts[-1],
        None,
        x0,
        saveat=diffrax.SaveAt(ts=ts),
        stepsize_controller=diffrax.PIDController(rtol=1e-11, atol=1e-13),
        max_steps=200_000,
    )
    x = sol.ys
    position = jnp.stack([x[:, 0] / x[:, 2], x[:, 1] / x[:, 2], 1.0 / x[:, 2]], axis=1) / 100.0

    # camera: sample at camera_hz, hold; the sample index by integer arithmetic
    held = (np.arange(n) * camera_hz) // rate_hz
    first = np.searchsorted(held, np.arange(held[-1] + 1))  # 1 kHz index of each frame
    Kc_true = jnp.array(KC_REFINED)
    Kc_obs = jnp.asarray(Kc_observer, float)
    p = x[first, :2] @ Kc_true[:2, :2].T + Kc_true[:2, 2]
    if noise_px > 0:
        p = p + noise_px * jax.random.normal(key, p.shape)
    y = (p - Kc_obs[:2, 2]) / jnp.diag(Kc_obs)[:2]
    u_frames = jax.vmap(lambda t: _velocities(s, t)[0])(ts[first])
    return MovingCameraScenario(
        ts=ts,
        x=x,
        position=position,
        y=y[held],
        u=u_frames[held],
        pixels=p[held],
        Kc_true=Kc_true,
    )
