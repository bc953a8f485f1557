"""The `moving_point` problem: the 3-D position of a moving point seen by a moving camera
whose velocity is measured (Jang's thesis), with the unknown input observer and its
baselines."""

from typing import final

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float, Int

from ..._util import Note, number_text
from ...baselines import moving_point_ekf, triangulate_point
from ...design import certified_lipschitz, design_uio_for_motion
from ...estimators import (
    AbstractAdjoint,
    DirectAdjoint,
    MovingPointEstimator,
    SaveAt,
    WindowRMS,
    integration_step,
    moving_point_innovation,
    moving_point_stream,
    run,
)
from ...io import MovingPointData
from ...plots import plot_moving_point
from ...sim import add_pixel_noise, sample_times
from ...studies import AbstractProblem, Parameter, as_default, held, noise_parameter
from . import _scene as jang


@final
class MovingPointProblem(AbstractProblem):
    """The position of a point (possibly moving) from a moving camera's pixels and measured
    velocity (Jang's thesis). Build it with `moving_point_problem`.

    Methods: `estimator`, the unknown input observer (eq. (3.5)) at 1 kHz on the held
    30 Hz frames (the thesis' logger); `batch` and `batch_window`, triangulation over all
    frames up to $t$ and over the last `window_s` seconds (both causal; a static point
    model for a static set, constant velocity for a moving one); `ekf`, the inverse-depth
    EKF (`baselines.moving_point_ekf`, predicted at 1 ms).

    Parameters: `K` and `Y` (the observer's gains, 3 x 2: the set's published ones, or the
    LMI design for a data file; entries of either sign) and `K_scale`, `Y_scale`,
    multipliers of them (default 1); the baselines': `window_frames` (`batch_window`'s
    frames per fit, a structural parameter), `ekf_q` (the EKF's random-walk intensity of
    the point's velocity, units^2/s^3: the frame interval for a moving set, 0 for a static
    one, then not tuned) and `ekf_sigma_depth0` (its prior's standard deviation of the
    depth over the shared depth guess, default 0.5). Metrics: `rms` (3,) per axis in
    metres against the true position over the second half of the run (at 1 kHz for the
    observer, at the frames for the baselines), and `rms_worst`, its largest component
    (the depth's, in practice).
    """

    methods = ("estimator", "batch", "batch_window", "ekf")
    metric = "rms_worst"
    label = "worst-axis RMS position, second half (m)"
    trivial_label = "the initial depth guess"
    data_parameters = ("noise_px",)
    grid = "K_scale=0.1:10:7,Y_scale=0.1:10:7"
    columns = {
        "rms": ("rms_X", "rms_Y", "rms_Z"), "position": ("X", "Y", "Z"),
        "x_hat": ("x1_hat", "x2_hat", "x3_hat"),
    }  # fmt: skip
    units = {
        "rms": "m", "rms_worst": "m",
        "position": "the observer's unit: cm on a thesis set (`to_m` 0.01), else m",
        "x_hat": "x1 = X/Z, x2 = Y/Z (-); x3 = 1/Z (1/the observer's unit)",
    }  # fmt: skip
    structural_parameters = ("window_frames",)
    own_parameters = {
        "estimator": ("K", "Y", "K_scale", "Y_scale"),
        "batch": (),
        "batch_window": ("window_frames",),
        "ekf": ("ekf_q", "ekf_sigma_depth0"),
    }

    ts: Float[ArrayLike, " n"]  # the observer's samples (the frames held at 1 kHz for a scene)
    frame_index: Int[ArrayLike, " n"]  # the frame held at each of `ts`
    frame_ts: Float[ArrayLike, " f"]
    frame_pixels: Float[ArrayLike, "f 2"]  # noise-free
    frame_velocities: Float[ArrayLike, "f 6"]
    Kc: Float[ArrayLike, "3 3"]
    truth_ts: Float[ArrayLike, " t"]
    truth: Float[ArrayLike, "t 3"] | None  # the position in the observer's units (cm for a set)
    observer: MovingPointEstimator  # the reference observer (the published or designed gains)
    noise_px: Float[ArrayLike, ""]  # a data parameter (`at`): a noise sweep is one `vmap`
    to_m: float = eqx.field(static=True)
    moving: bool = eqx.field(static=True)
    window_s: tuple = eqx.field(static=True)
    window_frames: int = eqx.field(static=True)
    source: str = eqx.field(static=True)  # a `Note`: it does not key compilation
    frame_interval: float = eqx.field(static=True, default=1 / 30)  # median, s
    save_every: int = eqx.field(static=True, default=1)  # the observer's, about 100 Hz
    set_name: str | None = eqx.field(static=True, default=None)
    adjoint: AbstractAdjoint = DirectAdjoint()

    @property
    def title(self) -> str:
        return f"moving point (Jang's thesis), {self.source}, {number_text(self.noise_px)} px noise"

    @property
    def scored(self) -> bool:
        return self.truth is not None

    def truth_outputs(self, method, solution):
        """`position`: the true position held at the solution's times, in the observer's
        units as the estimate (none without a truth)."""
        if self.truth is None or not hasattr(solution.outputs, "position"):
            return {}
        return {"position": held(self.truth_ts, self.truth, solution.ts)}

    def parameters(self) -> dict[str, Parameter]:
        q = self._q_velocity()
        return {
            "K": Parameter(as_default(self.observer.K), "", False, "observer gain K (3 x 2)"),
            "Y": Parameter(as_default(self.observer.Y), "", False, "observer gain Y (3 x 2)"),
            "K_scale": Parameter(1.0, "", True, "multiplier of K"),
            "Y_scale": Parameter(1.0, "", True, "multiplier of Y"),
            "noise_px": noise_parameter(self.noise_px),
            "window_frames": Parameter(
                float(self.window_frames), "frames", True, "frames per sliding-window fit"
            ),
            "ekf_q": Parameter(
                q,
                "units^2/s^3",
                self.moving,
                "the EKF's velocity random walk",
                span=(q / 100, q * 100) if q > 0 else None,
            ),
            "ekf_sigma_depth0": Parameter(0.5, "", True, "the EKF's prior depth spread / guess"),
        }

    def _q_velocity(self) -> float:
        # the expected change of the point's velocity: the documented rule of
        # `moving_point_ekf` (1 unit/s^2 over a frame interval); a static point: none
        return self.frame_interval if self.moving else 0.0

    def gains(self, params) -> dict:
        p = self.resolve(params)
        return {
            "K": (np.asarray(p["K"]) * np.asarray(p["K_scale"])).tolist(),
            "Y": (np.asarray(p["Y"]) * np.asarray(p["Y_scale"])).tolist(),
        }

    def inputs(self, key):

        return {"pixels": add_pixel_noise(key, self.frame_pixels, self.noise_px)}

    def _window(self):

        return WindowRMS(*self.window_s, field="position")

    def _frames(self, pixels):
        return moving_point_stream(
            self.frame_ts, pixels, self.frame_velocities, self.Kc, dropped="extrapolate",
            throw=False,
        )  # fmt: skip

    def solve(self, method, params, inputs, *, outputs=False):

        pixels = inputs["pixels"]
        if method == "estimator":
            k = self.frame_index
            truth = None if self.truth is None else held(self.truth_ts, self.truth, self.ts)
            stream = moving_point_stream(
                self.ts, pixels[k], self.frame_velocities[k], self.Kc, truth=truth, throw=False
            )
            obs = eqx.tree_at(
                lambda o: (o.K, o.Y, o.K_u),
                self.observer,
                (
                    params["K"] * params["K_scale"],
                    params["Y"] * params["Y_scale"],
                    self.observer.K_u * params["K_scale"],
                ),
            )
            reducer = None if truth is None else self._window()
            return run(
                obs,
                stream,
                saveat=SaveAt(every=self.save_every, outputs=outputs),
                reducer=reducer,
                adjoint=self.adjoint,
                throw=False,
            )
        order = 1 if self.moving else 0
        if method in ("batch", "batch_window"):
            window = self.frame_ts.shape[0] if method == "batch" else self.window_frames
            return triangulate_point(self._frames(pixels), window=window, order=order, throw=False)
        if method == "ekf":
            interval = self.frame_interval
            depth0 = 1.0 / jnp.asarray(self.observer.x3_guess)
            return moving_point_ekf(
                self._frames(pixels),
                r_norm=jnp.maximum(self.noise_px, 0.05) / self.Kc[0, 0],
                depth0=depth0,
                sigma_depth0=params["ekf_sigma_depth0"] * depth0,
                q_velocity=params["ekf_q"],
                sigma_velocity0=2.0 if self.moving else 0.0,
                substeps=max(1, int(round(interval / 1e-3))),
                throw=False,
            )
        raise ValueError(f"{self.title}: unknown method {method!r}; choose {self.methods}.")

    def metrics(self, method, solution):
        if self.truth is None:
            return {}
        if method == "estimator":
            rms = solution.summary.rms
        else:
            truth = held(self.truth_ts, self.truth, solution.ts)
            rms = self._window().over(solution.ts, solution.outputs, truth).rms
        rms = rms * self.to_m
        return {"rms_worst": jnp.max(rms), "rms": rms}

    def trivial(self):
        """The metrics of the initial depth guess held: at each frame, the point on the
        pixel's ray at the observer's initial depth $1/\\hat x_3(0)$ (the noise-free
        pixels), scored as the baselines are."""
        if self.truth is None:
            return {}

        rays = jnp.linalg.solve(
            self.Kc,
            jnp.concatenate([self.frame_pixels, jnp.ones_like(self.frame_pixels[:, :1])], 1).T,
        ).T
        position = rays / rays[:, 2:] / self.observer.x3_guess
        truth = held(self.truth_ts, self.truth, self.frame_ts)
        rms = WindowRMS(*self.window_s).over(self.frame_ts, position, truth).rms * self.to_m
        return {"rms_worst": jnp.max(rms), "rms": rms}

    def innovation(self, method, params, solution, inputs):
        """The observer's output error at each frame, $y - \\hat y$ (normalized image
        coordinates), against the noise its frames imply (`estimators.moving_point_innovation`)
        over the scoring window; `None` for the baselines and a solution saved without its
        time series."""

        if method != "estimator" or getattr(solution, "outputs", None) is None:
            return None
        return moving_point_innovation(
            self.frame_ts, inputs["pixels"], self.Kc, solution.ts, solution.outputs.x_hat,
            t_start=self.window_s[0], t_end=self.window_s[1] + 1e-9,
        )  # fmt: skip

    def updates(self, method):
        return int(self.frame_ts.shape[0])

    def settings(self) -> dict:
        out = {
            "source": self.source,
            "noise_px": float(self.noise_px),
            "observer_step_s": float(self.ts[1] - self.ts[0]),
            "point_model": "constant velocity" if self.moving else "static",
            "batch": "all frames up to t (causal)",
            "window_frames": self.window_frames,
            "scoring_window_s": list(self.window_s),
            "scoring": "against the true position, second half of the run (metres)",
            "ekf_r_norm": max(float(self.noise_px), 0.05) / float(self.Kc[0, 0]),
            "ekf_depth0": float(1.0 / self.observer.x3_guess),
        }
        if self.set_name is not None:
            s = jang.SETS[self.set_name]
            out.update(
                set=self.set_name,
                reference_gains="the thesis' published K and Y of the set (chapter 5)",
                thesis_rms_m=list(s.thesis_rms),
                lmi={
                    "A": [list(r) for r in s.A],
                    "C": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                    "D": [[x] for x in s.D],
                },
            )
        return out

    def checks(self, params) -> dict:
        """For a thesis set: the LMI of section 3.6 for the gains at `params`, the
        Lipschitz bound they certify (`design.certified_lipschitz`) beside the published
        gains' own."""
        if self.set_name is None:
            return {}

        s = jang.SETS[self.set_name]
        A, C, D = np.array(s.A, float), np.eye(3)[:2], np.array(s.D, float)[:, None]
        g, g0 = self.gains(params), self.gains({})
        tuned = certified_lipschitz(A, C, D, np.array(g["K"]), np.array(g["Y"]))
        published = certified_lipschitz(A, C, D, np.array(g0["K"]), np.array(g0["Y"]))
        return {
            "lmi": {
                "certified_lipschitz": tuned,
                "published_certified_lipschitz": published,
                "satisfies_lmi": bool(tuned > 0),
                "covers_published_bound": bool(tuned >= published * (1 - 1e-6)),
            }
        }

    def check_lines(self, summary) -> list[str]:
        if "lmi" not in summary:
            return []
        lmi = summary["lmi"]
        return [
            f"thesis RMS {self.settings()['thesis_rms_m']}; the gains satisfy the LMI of "
            f"section 3.6: {lmi['satisfies_lmi']} (certified Lipschitz bound "
            f"{lmi['certified_lipschitz']:.3g}, published gains "
            f"{lmi['published_certified_lipschitz']:.3g})"
        ]

    def figure(self, method, solution):
        """Like Figs. 5-7 and 5-8 of Jang's thesis (`plots.plot_moving_point`): the true and
        the estimated position, and the error zoomed on the second half; the estimate
        alone without a truth."""

        ts = solution.ts
        truth = None if self.truth is None else held(self.truth_ts, self.truth, ts) * self.to_m
        estimate = np.asarray(solution.outputs.position) * self.to_m
        velocities = held(self.frame_ts, self.frame_velocities, ts)
        D = np.asarray(self.observer.D)[:, 0] if self.moving else None
        weak = weak_parallax(estimate if truth is None else truth, velocities, D)
        return plot_moving_point(
            np.asarray(ts),
            None if truth is None else np.asarray(truth),
            estimate,
            weak=weak,
            title=f"{self.title}: {method}",
        )


WEAK_PARALLAX = 0.1
"""`weak_parallax`'s threshold: a fraction of the run's median parallax (an assumption of
visjax's, for figures; the thesis states no observability threshold)."""


def weak_parallax(position, velocities, D=None, fraction: float = WEAK_PARALLAX) -> np.ndarray:
    """Where the depth of the point is weakly observable from the camera's motion: the
    parallax the camera's translation induces in the normalised coordinates, per unit
    inverse depth, $w = [v_{cx} - x_1 v_{cz}, v_{cy} - x_2 v_{cz}]$ (the $x_3$ terms of
    eq. (2.11)), below `fraction` of its median over the run. For a moving point,
    the part of $w$ along the unknown input's direction in $(x_1, x_2)$ (`D`, eq. (2.11):
    the point's own velocity there is not known, so that parallax does not separate the
    depth from it) is left out: in set II.3 the depth rests on $v_{cy}$ alone, and the
    error grows where $v_{cy}$ crosses zero.

    **Arguments:** `position` (N, 3), the point in the camera frame; `velocities` (N, 6),
    the camera's $[v_c, \\omega]$ (any length unit: only ratios matter); `D` (3,) or
    `None` (a static point); `fraction`. **Returns:** (N,) bool (NumPy; for figures)."""
    p = np.asarray(position, float)
    v = np.asarray(velocities, float)
    x1, x2 = p[:, 0] / p[:, 2], p[:, 1] / p[:, 2]
    w = np.stack([v[:, 0] - x1 * v[:, 2], v[:, 1] - x2 * v[:, 2]], axis=-1)
    if D is not None and np.linalg.norm(np.asarray(D, float)[:2]) > 0:
        d = np.asarray(D, float)[:2] / np.linalg.norm(np.asarray(D, float)[:2])
        w = w - (w @ d)[:, None] * d
    q = np.linalg.norm(w, axis=-1)
    if not np.isfinite(q).any():
        return np.zeros(q.shape, bool)
    return q < fraction * np.nanmedian(q)


def moving_point_problem(
    *,
    variant: str | None = None,
    data=None,
    noise_px: float = 0.1,
    duration: float = 20.0,
    window_s: float = 1.0,
    adjoint: AbstractAdjoint | None = None,
    Kc_observer=None,
) -> MovingPointProblem:
    """The `moving_point` problem (`MovingPointProblem`) on the simulated analogue of a
    thesis set (`variant`, default `"I.1"`, a static point; `duration` s) or on a
    `visjax.io.MovingPointData` file (`data`: its observer from
    `moving_point_observer_for_data`'s LMI design, 1 kHz on its frames), with
    `noise_px` of pixel noise per seed.

    On the moving sets the camera's velocity is constant, and then the depth of a point
    moving in 3-D is not determined by the images (the family
    $(\\lambda P_0, \\lambda V + (1-\\lambda)v_c)$ fits them all): the triangulation
    reports `singular`; the observer resolves it with what it knows of the unknown input's
    direction $D$ (eq. (3.1)).

    `Kc_observer`: on a thesis set, the camera matrix the observer normalises the pixels
    with (default the thesis' refined least-squares one, which is also the simulated
    camera's: `jang.KC_REFINED`); a file carries its own."""

    if not (np.isfinite(noise_px) and noise_px >= 0):
        raise ValueError(f"`noise_px` must be finite and non-negative; got {noise_px!r}.")
    if data is not None:
        if variant is not None or Kc_observer is not None:
            raise ValueError(
                "a thesis set (`variant`, `Kc_observer`) and a data file exclude each other."
            )

        d = MovingPointData.load(data)
        observer, u, _ = moving_point_observer_for_data(d)
        frame_ts = jnp.asarray(d.t, float)
        t0, t1 = float(frame_ts[0]), float(frame_ts[-1])
        # `run`'s rule (`dt="auto"`, `integration_step`) with the thesis' 1 kHz law as the
        # longest step: the frames held at that step, or the frames themselves if faster
        frames = moving_point_stream(frame_ts, d.pixels, u, d.A, dropped="extrapolate", throw=False)
        dt = integration_step(frames, observer, max_step=1e-3)
        ts = frame_ts if dt is None else t0 + sample_times(t1 - t0, 1.0 / dt)
        index = np.clip(
            np.searchsorted(np.asarray(frame_ts), np.asarray(ts) + 1e-9, side="right") - 1,
            0,
            frame_ts.shape[0] - 1,
        )
        truth = None if d.position is None else jnp.asarray(d.position, float)
        frame_pixels = jnp.asarray(d.pixels, float)
        interval = float(np.median(np.diff(np.asarray(frame_ts))))
        return MovingPointProblem(
            ts=ts,
            frame_index=jnp.asarray(index),
            frame_ts=frame_ts,
            frame_pixels=frame_pixels,
            frame_velocities=jnp.asarray(u, float),
            Kc=jnp.asarray(d.A, float),
            truth_ts=frame_ts,
            truth=truth,
            observer=observer,
            noise_px=jnp.asarray(float(noise_px)),
            to_m=1.0,
            moving=True,
            window_s=(t0 + (t1 - t0) / 2, t1 + 1.0),
            window_frames=max(2, int(round(window_s / interval))),
            source=Note(str(data)),
            frame_interval=interval,
            save_every=_save_every(ts),
            adjoint=DirectAdjoint() if adjoint is None else adjoint,
        )
    set_name = "I.1" if variant is None else variant
    if set_name not in jang.SETS:
        raise ValueError(f"unknown set {set_name!r}; choose from {list(jang.SETS)}.")
    sc = jang.scenario(
        set_name, duration, Kc_observer=jang.KC_REFINED if Kc_observer is None else Kc_observer
    )
    interval = float(np.median(np.diff(np.asarray(sc.frame_ts))))
    return MovingPointProblem(
        ts=sc.ts,
        frame_index=sc.frame_index,
        frame_ts=sc.frame_ts,
        frame_pixels=sc.frame_pixels,
        frame_velocities=sc.frame_velocities,
        Kc=sc.Kc_observer,
        truth_ts=sc.ts,
        truth=sc.position * 100.0,  # the observer's units: the thesis' centimetres
        observer=jang.observer(set_name),
        noise_px=jnp.asarray(float(noise_px)),
        to_m=0.01,
        moving=jang.SETS[set_name].moving,
        window_s=(duration / 2, duration + 1.0),
        window_frames=max(2, int(round(window_s / interval))),
        source=Note(f"thesis set {set_name} (simulated), {duration:g} s"),
        frame_interval=interval,
        save_every=_save_every(sc.ts),
        set_name=set_name,
        adjoint=DirectAdjoint() if adjoint is None else adjoint,
    )


def _save_every(ts) -> int:
    """The observer's saving period in steps: about 100 Hz."""
    step = float(np.diff(np.asarray(ts)[:2])[0])
    return max(1, int(round(0.01 / step)))


def moving_point_observer_for_data(data):
    """The unknown input observer of Jang's thesis for a `MovingPointData` file, and the
    camera velocities at the frame times.

    The camera velocities are interpolated (linearly) to the frame times; the observer's
    $A(u)$ is the thesis' matrix of the camera velocities (`MOVING_POINT_A_U`), and its gains
    are designed by `visjax.design.design_uio_for_motion` for the velocity range of the
    file (10% margin) and the measured velocities (up to the first 250 frames), with
    $D$ the file's unknown-input direction. The design takes $\\bar f = 0$ (Lipschitz
    bound 0): exact for a camera that translates parallel to its image plane and turns
    about its optical axis; other motion ($v_{cz}$, $\\omega_x$, $\\omega_y$) is returned
    as `unmodelled_motion`.

    **Returns:** `(observer, u, info)`: `u` (N, 6) the velocities at the frame times and
    `info` a dict (`depth_guess_m`, `D`, `design`, `unmodelled_motion`).
    """

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
    observer = MovingPointEstimator(
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
