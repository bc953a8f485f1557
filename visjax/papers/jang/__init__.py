"""Jang's thesis, *structure of a moving point seen by a moving camera*: the published
matrices, gains and RMS tables of its seven experiment sets, their simulated analogues
(chapter 5), the observer of each set and the experiment, and the testbed as a twin
(`testbed`: the PUMA 560 of chapter 4 carrying the camera, the two-link robot carrying the
marker, rendered frames tracked by KLT, encoder velocities; its assumptions in `TESTBED`).
Nothing else in visjax knows these numbers.

A point seen by a camera on a PUMA 560 (I.1-I.4: the point is static; II.1-II.3: it moves
on a two-link robot). The truth is the perspective dynamics (2.11) integrated with an
8th-order solver (`visjax.sim.moving_camera_point`, on the same function the observer
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
- **Camera.** Its frames are held between samples (`ThesisScenario.held_stream`, or the
  30 Hz `camera_stream` run with `dt=1e-3`: the same computation). The true camera is
  the thesis' least-squares $\\hat K_c$; the observer may be given the thesis' toolbox
  $K_c$ (the perturbed nominal of Tables 5-1/5-2) or a refined one.
- **Durations.** 30 s; steady-state RMS over the last 15 s.
"""

from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..._results import RESULTS, result_names
from ..._util import renamed
from ...estimators import (
    moving_point_stream,
    run,
)
from ...frontend import (
    Plane,
    annotate_frames,
    fiducial_marker,
    render_planes,
    textured_table,
    track_marker,
    write_video,
)
from ...geometry import camera_matrix, camera_matrix_lstsq
from ...io import Outputs
from ...kinematics import TwoLinkArm, puma560
from ...plots import plot_camera_velocity, plot_moving_point, plot_testbed
from ...sim import encoder_twist, follow_tool_twist, hold_indices, planar_path, sample_times
from ...studies import reproduction_row, solution
from .._reproduction import (
    Reproduction,
    SeedClock,
    check_seeds,
    floats,
    median,
    write_report,
)
from ._problem import (
    WEAK_PARALLAX as WEAK_PARALLAX,
    MovingPointProblem as MovingPointProblem,
    moving_point_observer_for_data as moving_point_observer_for_data,
    moving_point_problem as moving_point_problem,
    weak_parallax as weak_parallax,
)
from ._scene import (
    KC_REFINED as KC_REFINED,
    KC_TOOLBOX as KC_TOOLBOX,
    SETS as SETS,
    MovingPointRun as MovingPointRun,
    ThesisScenario as ThesisScenario,
    ThesisSet as ThesisSet,
    _held as _held,
    _measurements as _measurements,
    _SetMotion as _SetMotion,
    _velocities as _velocities,
    observer as observer,
    scenario as scenario,
)


def moving_point_experiment(
    set_name: str,
    duration: float = 30.0,
    noise_px: float = 0.0,
    *,
    seed: int = 0,
    Kc_observer=KC_REFINED,
    K=None,
    Y=None,
) -> MovingPointRun:
    """A thesis set as the `moving_point` problem states it (`moving_point_problem`):
    the simulated set with `noise_px` of pixel noise (seed `seed`), the UIO (eq. (3.5))
    at 1 kHz on the held 30 Hz frames, run once (`studies.solution`, the thesis' gains
    unless `K`, `Y` are given), and the steady-state RMS position error (metres) over the
    second half of the run (at the 100 Hz saved samples).

    **Raises:** `RuntimeError` if the run fails (its result code and sample)."""

    problem = moving_point_problem(
        variant=set_name, noise_px=noise_px, duration=duration, Kc_observer=Kc_observer
    )
    gains = {k: v for k, v in (("K", K), ("Y", Y)) if v is not None}
    sol = solution(problem, gains, jax.random.key(seed))
    if not bool(sol.result == RESULTS.successful):
        raise RuntimeError(
            f"the unknown input observer failed on set {set_name}: "
            f"{result_names(sol.result)} at sample {int(sol.failed_sample)}."
        )
    every = int(round(0.01 / float(problem.ts[1] - problem.ts[0])))
    estimate = sol.outputs.position * problem.to_m  # the thesis' cm -> m
    truth = problem.truth[::every] * problem.to_m
    steady = sol.ts >= duration / 2
    err = np.asarray(estimate - truth)[np.asarray(steady)]
    # the thesis' lengths are in cm: the camera's linear velocity to m/s
    to_si = jnp.array([0.01, 0.01, 0.01, 1.0, 1.0, 1.0])
    return MovingPointRun(
        ts=sol.ts,
        position=truth,
        estimate=estimate,
        rms=jnp.sqrt(jnp.mean(err**2, axis=0)),
        frame_ts=problem.frame_ts,
        camera_velocity=problem.frame_velocities * to_si[None, :],
    )


# --------------------------------------------------------------------------------------
# The testbed as a digital twin (chapters 4-5): a camera on a PUMA 560, a fiducial marker
# on the table (Experiment I) or on a two-link planar robot (Experiment II), frames
# rendered at 30 Hz and tracked by KLT, camera velocities from the PUMA's joint encoders,
# ground truth from both robots' forward kinematics at 1 kHz.

TESTBED = {
    # Every number here is an assumption: the thesis states none of them (its words:
    # "A camera is rigidly fixed to the end-effector of the PUMA 560. The PUMA and the
    # two-link robot are rigidly attached to a worktable", section 5.1).
    "table_z": -0.60,  # m: the table top in the PUMA's frame F (origin at the shoulder)
    "camera_height": 0.80,  # m above the table at mid-run (the 80 cm depth of `scenario`)
    "camera_mid_xy": (0.50, 0.10),  # m: the camera's position in F at mid-run
    # rad: a downward-looking posture with the wrist far from its singularities
    # (theta5 = 1.32 rad; a posture with theta5 near pi meets theta5 = pi within 6 s in
    # sets I.2, I.4 and II.1)
    "q_guess": (-2.645, -1.739, -0.082, np.pi, 1.321, -2.645),
    "tool": (0.0, 0.0, 0.10),  # m: the camera's centre in frame 6, 10 cm out along S6
    "marker_side": 0.06,  # m: the black square of the ArUco marker
    "marker_height": 0.02,  # m above the table, on the two-link robot (Experiment II)
    "two_link_lengths": (0.35, 0.25),  # m
    "two_link_reach_at_mid": 0.42,  # m: distance base -> marker at mid-run (elbow bent)
    "encoder_resolution": 2 * np.pi / 2**18,  # rad per count at the joint (2.4e-5 rad)
    "velocity_delay_s": 0.0,  # serial link delay of the velocities (not stated)
    "image_size": (640, 480),  # the mvBlueFox-120a's VGA frames
    "supersample": 2,  # rendering's anti-aliasing (2 x 2 samples per pixel)
}
"""The twin's layout and sensors. A camera velocity sent at a frame is the mean over the
preceding camera period (the backward difference of the quantised encoder angles over
1/30 s, through eq. (4.5)): an effective delay of half a period (16.7 ms), plus
`velocity_delay_s`."""

UNITS = {"cm": 0.01, "m": 1.0}
"""The two readings of the thesis' $A$: its velocity entries in cm/s or in m/s (the thesis
never states the unit; the PUMA's Table 4-1 is in cm). The value converts to m/s."""


@dataclass(frozen=True)
class TestbedRun:
    """One experiment set on the twin (NumPy arrays; positions in metres, camera frame).

    **Fields:**

    - `set_name`, `units` (`"cm"` or `"m"`), `duration`, `feasible` (False when the PUMA
      cannot follow the set's camera velocities: `reason` says why and when).
    - `ts` (N,) 1 kHz; `position` (N, 3) the truth $R_{cam}^{-1}(r_{obj} - r_{cam})$ from
      forward kinematics; `estimate` (N, 3) the UIO from tracked pixels; `estimate_ideal`
      (N, 3) the UIO from the exact projections of the marker's centre.
    - `frame_ts` (F,); `frame_index` (F,) their 1 kHz samples; `pixels` (F, 2) the tracked
      marker centre (NaN where lost); `pixels_true` (F, 2) its exact projection;
      `velocity_true` (F, 6), `velocity_measured` (F, 6): the camera's $[v_c, \\omega]$
      (m/s, rad/s, camera frame), exact and from the encoders.
    - `q_puma` (N, 6), `q_arm` (N, 2) or `None`: the robots' joint angles.
    - `rms` (3,) the RMS error over the second half at 1 kHz; `rms_frames` (3,) at the
      camera samples only; `rms_ideal` (3,) at 1 kHz from ideal pixels; `tracking_rms_px`
      the tracked centre's RMS distance to its projection (px).
    - `result` the UIO's result name (from tracked pixels; the RMS fields are NaN when a
      run did not succeed, e.g. `diverged`: the depth estimate became negative); `frames`
      (F, H, W) uint8 when kept, else `None`.
    """

    set_name: str
    units: str
    duration: float
    feasible: bool
    reason: str
    ts: np.ndarray
    position: np.ndarray
    estimate: np.ndarray
    estimate_ideal: np.ndarray
    frame_ts: np.ndarray
    frame_index: np.ndarray
    pixels: np.ndarray
    pixels_true: np.ndarray
    velocity_true: np.ndarray
    velocity_measured: np.ndarray
    q_puma: np.ndarray
    q_arm: np.ndarray | None
    rms: np.ndarray
    rms_frames: np.ndarray
    rms_ideal: np.ndarray
    tracking_rms_px: float
    result: str
    frames: np.ndarray | None


def _testbed_motion(s: ThesisSet, units: str, ts, vp_amplitude):
    """The camera's commanded body velocity u(t) (m/s, rad/s) and the marker's velocity in
    the camera frame v_p(t) (m/s) of a set, under a unit reading."""
    scale = UNITS[units]
    amp = s.vp_amplitude if vp_amplitude is None else tuple(vp_amplitude)
    return _TestbedTwist(s, scale), _MarkerVelocity(jnp.asarray(amp, float), scale)


# Modules rather than closures: the compiled integrations are reused by every testbed run
# of a set (and, for the marker, of any amplitude).


class _TestbedTwist(eqx.Module):
    s: ThesisSet = eqx.field(static=True)
    scale: float = eqx.field(static=True)

    def __call__(self, t):
        u_set, _ = _velocities(self.s, t)  # A's numbers, in the reading's unit
        scale = self.scale
        return u_set * jnp.array([scale, scale, scale, 1.0, 1.0, 1.0])


class _InPlane(eqx.Module):
    """(v_px, -v_py): the marker's velocity in the planar frame of `planar_path`."""

    v_p: Callable

    def __call__(self, t):
        return self.v_p(t)[:2] * jnp.array([1.0, -1.0])


class _MarkerVelocity(eqx.Module):
    amp: Array
    scale: float = eqx.field(static=True)

    def __call__(self, t):
        amp = self.amp
        return self.scale * jnp.stack(
            [amp[0] * jnp.sin(0.5 * t), amp[1] * jnp.cos(0.3 * t), jnp.zeros_like(t)]
        )


def testbed(
    set_name: str,
    *,
    units: str = "cm",
    duration: float = 30.0,
    rate_hz: int = 1000,
    camera_hz: int = 30,
    vp_amplitude=None,
    Kc_true=KC_REFINED,
    Kc_observer=KC_REFINED,
    track: bool = True,
    keep_frames: bool = False,
    seed: int = 0,
    marker: str = "DICT_4X4_50",
) -> TestbedRun:
    """Run one thesis set on the twin of its testbed, end to end.

    1. The PUMA 560 (Table 4-1, `visjax.kinematics.puma560` with the camera as its tool)
       follows the set's camera velocities: the $v_{cx}, v_{cy}, \\omega_z$ of its $A$ (and
       the sinusoids of `SETS` for the time-varying sets), read in `units`, by integrating
       the inverse velocity kinematics (4.6) forwards and backwards from a downward-looking
       posture at mid-run (`TESTBED`). A singular configuration (the arm out of reach) ends
       the set as infeasible.
    2. The marker: static on the table (Experiment I), or on the two-link robot
       (Experiment II), whose joints follow, by its inverse kinematics, a path with the
       velocity `vp_amplitude` $\\cdot [\\sin 0.5t, \\cos 0.3t]$ in the camera frame (default
       the set's `vp_amplitude`, in the reading's unit per s; $v_{pz} = 0$, Assumption
       3.1). It is placed where its image path strays least from the image centre (the
       thesis' Figs. 5-3/5-4 show the point inside the image throughout; a rule for
       visibility, fixed before any error was computed). The two-link robot out of reach
       ends the set as infeasible.
    3. Truth at `rate_hz`: $r_{obj/cam} = R_{cam}^{-1}(r_{obj} - r_{cam})$ (section 5.1) from
       both robots' forward kinematics.
    4. At `camera_hz`: the camera's view rendered with `Kc_true` (a textured table and the
       ArUco marker, `visjax.frontend.render_planes`); the marker found by ArUco
       detection, its corners tracked by KLT with a forward-backward check and refined
       on each frame, re-detected when lost (`visjax.frontend.track_marker`); the point
       is the diagonals' intersection (the exact image of the marker's centre). The
       camera velocities from the encoders (`TESTBED`).
    5. The UIO (3.5) with the set's gains at `rate_hz` on the held frames, in the reading's
       length unit, with `Kc_observer`; once from tracked pixels, once from exact ones.

    `track=False` skips rendering and tracking (the tracked pixels are then the exact ones).
    `marker` the marker's dictionary: an ArUco one (default `"DICT_4X4_50"`, 6 cm), or an
    AprilTag family (`"36h11"`, `visjax.frontend.TAG_FAMILIES`: the tag 0 of that family,
    the same side), drawn, detected and tracked the same way.
    """
    import cv2  # noqa: F401  (the frontend needs OpenCV; fail early and clearly)

    if set_name not in SETS:
        raise ValueError(f"unknown set {set_name!r}; expected one of {list(SETS)}.")
    if units not in UNITS:
        raise ValueError(f"`units` must be 'cm' or 'm'; got {units!r}.")
    s = SETS[set_name]
    cfg = TESTBED
    ts = sample_times(duration, rate_hz)
    ts_np = np.asarray(ts)
    n = ts.shape[0]
    t_mid = float(ts_np[n // 2])
    u_fn, vp_fn = _testbed_motion(s, units, ts, vp_amplitude)

    # 1. the PUMA: a downward-looking camera (optical axis S6 along -Z, x along +X) at
    # mid-run; integrate (4.6) forwards and backwards from there
    chain = puma560(cfg["tool"])
    R_mid = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    p_mid = np.array([*cfg["camera_mid_xy"], cfg["table_z"] + cfg["camera_height"]])
    q_mid = chain.solve_pose(R_mid, p_mid, jnp.array(cfg["q_guess"])).q
    # one camera period before t = 0 too, so that the encoders have a history at frame 0
    window = max(1, rate_hz // camera_hz)
    pre = -jnp.arange(window, 0, -1, dtype=ts.dtype) / rate_hz
    ts_all = jnp.concatenate([pre, ts])
    mid = window + n // 2
    after, before = ts_all[mid:], ts_all[: mid + 1][::-1]
    fwd = follow_tool_twist(chain, q_mid, u_fn, after)
    bwd = follow_tool_twist(chain, q_mid, u_fn, before)
    q_all = np.concatenate([np.asarray(bwd.q)[::-1][:-1], np.asarray(fwd.q)])
    q = q_all[window:]
    feasible, reason = True, ""
    for part, direction in ((fwd, "after"), (bwd, "before")):
        if part.result != RESULTS.successful:
            k = int(part.failed_sample)
            t_fail = float(np.asarray(part.ts)[k])
            feasible = False
            reason += (
                f"the PUMA 560 cannot follow the camera velocities {direction} mid-run: "
                f"{result_names(part.result)} at t = {t_fail:.3f} s. "
            )
    T = np.asarray(jax.vmap(chain.forward)(jnp.asarray(np.nan_to_num(q))))
    R_cam = T[:, :3, :3]
    p_cam = np.einsum("nij,j->ni", R_cam, np.asarray(cfg["tool"])) + T[:, :3, 3]

    # 2. the marker: a first placement centres its image path on average (a point at p is
    # seen at R^T (p - p_cam) - o from the image centre's ray o, camera frame, at the
    # table's depth; the mean of that over the run is zero for p = mean(p_cam + R o - c),
    # c the marker's own displacement), then the largest excursion is minimised
    w, h = cfg["image_size"]
    Kt = np.asarray(Kc_true, float)
    depth = cfg["camera_height"] - (cfg["marker_height"] if s.moving else 0.0)
    o = np.array(
        [(w / 2 - Kt[0, 2]) / Kt[0, 0] * depth, (h / 2 - Kt[1, 2]) / Kt[1, 1] * depth, 0.0]
    )
    followed = np.all(np.isfinite(q), axis=1)
    q_arm = None
    if s.moving:
        # v_p in the camera frame; the camera turns at -w_z about Z (S6 = -Z), so the path in
        # the plane is planar_path with (v_px, -v_py) at the rate -w_z (as for the camera),
        # whose heading at mid-run is 0 (x along +X): the planar frame is F's X-Y
        wz = float(np.asarray(u_fn(jnp.zeros(())))[5])
        _, c = planar_path(_InPlane(vp_fn), -wz, ts, t_mid)
        c = np.concatenate([np.asarray(c), np.zeros((n, 1))], axis=1)
    else:
        c = np.zeros((n, 3))
    centre = np.mean((p_cam + R_cam @ o - c)[followed], axis=0)
    z_marker = cfg["table_z"] + (cfg["marker_height"] if s.moving else 0.0)
    p_ref = np.array([centre[0], centre[1], z_marker])
    # then minimise the path's largest excursion from the image centre (a convex function
    # of the marker's position on the table: a coarse-to-fine grid search)
    first = hold_indices(n, rate_hz, camera_hz)[1]  # the 1 kHz sample of each frame
    frame_k = first[followed[first]]
    p_ref = _centre_in_view(p_ref, R_cam[frame_k], p_cam[frame_k] - c[frame_k], Kt, (w, h))
    if s.moving:
        arm = TwoLinkArm(*cfg["two_link_lengths"])
        l1, l2 = cfg["two_link_lengths"]
        base = p_ref[:2] + np.array([0.0, cfg["two_link_reach_at_mid"]])  # beside the marker
        rel = p_ref[:2] + c[:, :2] - base
        dist = np.linalg.norm(rel, axis=1)
        if feasible and not np.all((dist < l1 + l2 - 1e-3) & (dist > abs(l1 - l2) + 1e-3)):
            k = int(np.argmax(~((dist < l1 + l2 - 1e-3) & (dist > abs(l1 - l2) + 1e-3))))
            feasible = False
            reason += (
                f"the two-link robot cannot follow the marker's path: out of reach at "
                f"t = {ts_np[k]:.3f} s. "
            )
        # an infeasible set is not run: reachable stand-in positions keep the (unused)
        # inverse kinematics from raising
        rel = np.where(feasible, rel, np.array([l1, l2]) * 0.5 + np.array([0.1, 0.0]))
        q_arm = np.asarray(jax.vmap(lambda p: arm.inverse(p, elbow=1))(jnp.asarray(rel)))
        p_xy = base + np.asarray(jax.vmap(arm.forward)(jnp.asarray(q_arm)))
        p_obj = np.concatenate([p_xy, np.full((n, 1), z_marker)], axis=1)
        yaw = q_arm.sum(axis=1)  # the marker turns with the end effector
    else:
        p_obj = np.broadcast_to(p_ref, (n, 3)).copy()
        yaw = np.zeros(n)
    position = np.einsum("nji,nj->ni", R_cam, p_obj - p_cam)  # section 5.1, in m

    # 3. the camera: frames, the exact projection of the marker's centre, the encoders
    cam = position[first]
    pixels_true = (cam[:, :2] / cam[:, 2:]) @ Kt[:2, :2].T + Kt[:2, 2]
    u_true = np.asarray(jax.vmap(u_fn)(ts))
    u_enc = np.asarray(
        encoder_twist(
            chain,
            jnp.asarray(np.nan_to_num(q_all)),
            float(rate_hz),
            resolution=cfg["encoder_resolution"],
            window=window,
        )
    )[window:]
    delay = int(round(cfg["velocity_delay_s"] * rate_hz))
    velocity_measured = u_enc[np.maximum(first - delay, 0)]

    frames = None
    pixels = pixels_true.copy()
    tracking_rms = 0.0
    if track and feasible:
        table_tex = textured_table((1000, 1000), seed=seed)
        table = Plane(
            table_tex,
            0.002,
            _pose_matrix(np.eye(3), np.array([p_ref[0] - 1.0, p_ref[1] - 1.0, cfg["table_z"]])),
        )
        marker_tex, marker_corners = fiducial_marker(0, dictionary=marker)
        side_px = marker_corners[1, 0] - marker_corners[0, 0]
        scale = cfg["marker_side"] / side_px
        centre_tex = marker_corners.mean(axis=0)
        frames = np.zeros((len(first), h, w), np.uint8)
        for i, k in enumerate(first):
            # the marker's frame: its centre at p_obj, turned by yaw about Z, its texture's
            # rows along -Y so that the downward-looking camera sees it unmirrored
            c_, s_ = np.cos(yaw[k]), np.sin(yaw[k])
            Rm = np.array([[c_, s_, 0.0], [s_, -c_, 0.0], [0.0, 0.0, -1.0]])
            origin = p_obj[k] - Rm @ np.array([*((centre_tex + 0.5) * scale), 0.0])
            marker_plane = Plane(marker_tex, scale, _pose_matrix(Rm, origin))
            frames[i] = render_planes(
                [table, marker_plane],
                Kt,
                R_cam[k],
                p_cam[k],
                (h, w),
                supersample=cfg["supersample"],
            )
        tracks = track_marker(frames, fps=camera_hz, marker_id=0, dictionary=marker)
        pixels = tracks.pixels[:, 4]  # the centre: the diagonals' intersection
        err = np.linalg.norm(pixels - pixels_true, axis=1)
        tracking_rms = float(np.sqrt(np.nanmean(err**2)))
        if not keep_frames:
            frames = None

    # 4. the UIO, in the reading's length unit
    to_unit = 1.0 / UNITS[units]
    vel_obs = velocity_measured * np.array([to_unit] * 3 + [1.0] * 3)
    frame_ts = ts_np[first]
    # the same 1 m initial depth guess in either reading (in the m reading the observer's
    # length unit is the metre, so its "cm" argument is a number of metres)
    obs = observer(set_name, x3_guess_cm=100.0 if units == "cm" else 1.0)

    def estimate_from(px):
        stream = moving_point_stream(
            frame_ts, px, vel_obs, jnp.asarray(Kc_observer, float), dropped="hold", throw=False
        )
        sol = run(obs, stream, dt=1.0 / rate_hz, throw=False)
        est = np.asarray(sol.outputs.position) / to_unit
        return est, result_names(sol.result)

    nan3 = np.full(3, np.nan)
    if feasible:
        estimate, result = estimate_from(pixels)
        if track:
            estimate_ideal, result_ideal = estimate_from(pixels_true)
        else:  # the tracked pixels are the exact ones
            estimate_ideal, result_ideal = estimate, result
        m = estimate.shape[0]
        steady = ts_np[:m] >= duration / 2
        rms = np.sqrt(np.mean((estimate - position[:m])[steady] ** 2, axis=0))
        rms_ideal = np.sqrt(np.mean((estimate_ideal - position[:m])[steady] ** 2, axis=0))
        at_frames = first[(first < m) & (ts_np[first] >= duration / 2)]
        rms_frames = np.sqrt(np.mean((estimate[at_frames] - position[at_frames]) ** 2, axis=0))
        # a run that stopped (the depth estimate left its valid set, `result` says so) has a
        # frozen estimate: its errors are not reported as numbers
        if result != "successful":
            rms = rms_frames = nan3
        if result_ideal != "successful":
            rms_ideal = nan3
    else:
        estimate = estimate_ideal = np.full((n, 3), np.nan)
        rms = rms_ideal = rms_frames = nan3
        result = "not_run"
    return TestbedRun(
        set_name=set_name,
        units=units,
        duration=float(duration),
        feasible=feasible,
        reason=reason.strip(),
        ts=ts_np,
        position=position,
        estimate=estimate,
        estimate_ideal=estimate_ideal,
        frame_ts=frame_ts,
        frame_index=np.asarray(first),
        pixels=pixels,
        pixels_true=pixels_true,
        velocity_true=u_true[first],
        velocity_measured=velocity_measured,
        q_puma=q,
        q_arm=q_arm,
        rms=rms,
        rms_frames=rms_frames,
        rms_ideal=rms_ideal,
        tracking_rms_px=tracking_rms,
        result=result,
        frames=frames,
    )


def _centre_in_view(p0, R_cam, p_cam, K, size):
    """The horizontal position of a point near `p0` whose image through cameras
    `(R_cam, p_cam)` (F, 3, 3), (F, 3) strays least from the image centre (the largest of
    |u - W/2| / (W/2) and |v - H/2| / (H/2) over the frames)."""
    w, h = size
    best = np.asarray(p0, float)
    for span, step in ((0.4, 0.02), (0.02, 0.001)):
        g = np.arange(-span, span + step / 2, step)
        cand = best[None, :] + np.stack(
            [*(x.ravel() for x in np.meshgrid(g, g)), np.zeros(g.size**2)], axis=1
        )
        cam = np.einsum("fji,gfj->gfi", R_cam, cand[:, None, :] - p_cam[None])
        with np.errstate(divide="ignore", invalid="ignore"):
            u = K[0, 0] * cam[..., 0] / cam[..., 2] + K[0, 2]
            v = K[1, 1] * cam[..., 1] / cam[..., 2] + K[1, 2]
        cost = np.maximum(np.abs(u - w / 2) / (w / 2), np.abs(v - h / 2) / (h / 2))
        cost = np.where(cam[..., 2] > 0, cost, np.inf).max(axis=1)
        best = cand[int(np.argmin(cost))]
    return best


def _pose_matrix(R, p):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


# --------------------------------------------------------------------------------------
# The reproductions that `visjax moving_point`, `visjax testbed` and `visjax reproduce` print
# and write (`visjax.report`).

TABLE_5_1 = {"toolbox": (0.0121, 0.0349, 0.0958), "least_squares": (0.0119, 0.0179, 0.0800)}
"""Table 5-1 (set I.2): the RMS position error (m, x y z) with the toolbox $K_c$ and with
the least-squares $K_c$ of section 2.3."""
TABLE_5_2 = {"toolbox": (0.0172, 0.0248, 0.0548), "least_squares": (0.0172, 0.0170, 0.0519)}
"""Table 5-2 (set II.1), as Table 5-1."""

VPY_AMPLITUDES = (0.0, 0.05, 0.2, 0.5, 1.0, 2.0)
"""The sensitivity study's amplitudes of the second unknown input $v_{py}$ (in the unit
reading's length per second), fixed before any run."""


def set_names(sets=None) -> list[str]:
    """The thesis' sets asked for (all by default), checked by name."""
    names = list(SETS) if not sets else list(sets)
    for name in names:
        if name not in SETS:
            raise ValueError(f"unknown set {name!r}; choose from {list(SETS)}")
    return names


def table_lines(per_set: dict, names, who: str) -> list[str]:
    """Tables 5-3 and 5-4 as printed lines: per set and axis, `who`'s RMS (or
    "infeasible") and the thesis' in brackets."""
    lines = []
    for group, label in (("I.", "Table 5-3 (static point)"), ("II.", "Table 5-4 (moving point)")):
        in_group = [n for n in names if n.startswith(group)]
        if not in_group:
            continue
        lines += [
            "",
            f"{label}: {who} (thesis)",
            f"{'':<4}" + "".join(f"{n:>20}" for n in in_group),
        ]
        for i, axis in enumerate("xyz"):
            cells = []
            for n in in_group:
                rms = per_set[n]["rms"]
                value = f"{rms[i]:.4f}" if rms is not None else "infeasible"
                cells.append(f"{value:>11} ({per_set[n]['thesis_rms'][i]:.4f})")
            lines.append(f"{axis:<4}" + "".join(cells))
    return lines


def moving_point_reproduction(
    sets=None,
    duration: float = 30.0,
    noise_px: float = 0.1,
    *,
    seed: int = 0,
    seeds: int = 1,
    quiet=True,
    write=None,
    max_hours: float = 24.0,
) -> Reproduction:
    """The UIO on the simulated analogues of the sets (`moving_point_experiment`), as `visjax
    structure` reports it: per set the RMS position error beside the thesis' Tables
    5-3/5-4, `sets.parquet` (one row per set and axis), per set `estimate_<set>.npz` (`t`,
    `position`, `estimate`) and the figures `structure_<set>` (like Figs. 5-7/5-8) and
    `camera_velocity_<set>` (like Figs. 5-5/5-6), each written as soon as its set is done.
    With `seeds` > 1, the noise seeds `seed, ..., seed + seeds - 1`: each set's `rms` is
    their median (each seed's in `rms_seeds`), `estimate` has a leading seed axis and the
    figures show the median error and its 10-90 % band."""
    import functools

    from tqdm import tqdm

    check_seeds(seeds, noise_px)
    names = set_names(sets)
    per_set = {}
    bar = tqdm(names, desc="moving_point", unit="set", disable=quiet)
    clock = SeedClock(len(names) * seeds, max_hours, "moving_point", bar)
    for name in bar:
        runs = []
        for i in range(seeds):
            runs.append(moving_point_experiment(name, duration, noise_px, seed=seed + i))
            clock.tick()
        r = runs[0]
        rms = [[float(x) for x in run.rms] for run in runs]
        per_set[name] = {"rms": rms[0] if seeds == 1 else median(rms)}
        if seeds > 1:
            per_set[name]["rms_seeds"] = rms
        per_set[name]["thesis_rms"] = list(SETS[name].thesis_rms)
        if write is None:
            continue
        estimate = np.asarray(r.estimate) if seeds == 1 else np.stack([x.estimate for x in runs])
        kind = "moving" if SETS[name].moving else "static"
        arrays = dict(t=np.asarray(r.ts), position=np.asarray(r.position), estimate=estimate)
        title = (
            f"unknown input observer (Jang's thesis), set {name} ({kind} point), simulated: "
            f"pixel noise {noise_px:g} px, camera 30 Hz, observer 1 kHz"
        )
        figures = {
            f"structure_{name}": functools.partial(
                plot_moving_point, r.ts, r.position, estimate, title=title
            ),
            f"camera_velocity_{name}": functools.partial(
                plot_camera_velocity,
                r.frame_ts,
                r.camera_velocity,
                title=f"Jang's thesis, set {name}: camera velocity (simulated analogue)",
            ),
        }
        write(Outputs(arrays={f"estimate_{name}.npz": arrays}, figures=figures))
    body = {"duration_s": duration, "noise_px": noise_px, "sets": per_set}
    if seeds > 1:
        body["seeds"] = seeds
    if write is not None:
        import pandas as pd

        rows = [
            {
                "set": name,
                "axis": axis,
                "rms_m": per_set[name]["rms"][i],
                "thesis_rms_m": per_set[name]["thesis_rms"][i],
            }
            for name in names
            for i, axis in enumerate("xyz")
        ]
        write(Outputs(tables={"sets": pd.DataFrame(rows)}))
    lines = [
        f"Unknown input observer (Jang's thesis, eq. 3.5), simulated analogues: {duration:g} s, "
        f"pixel noise {noise_px:g} px, RMS position error over the second half (m)"
    ] + table_lines(per_set, names, "visjax")
    return Reproduction(body, lines, settings={"sets": names}, seed=seed if noise_px > 0 else None)


def testbed_record(run: TestbedRun) -> dict:
    """One set's entry in the testbed's summary."""
    return {
        "rms": floats(run.rms),
        "thesis_rms": list(SETS[run.set_name].thesis_rms),
        "tracking_rms_px": float(run.tracking_rms_px) if run.feasible else None,
        "units": run.units,
        "rms_frames": floats(run.rms_frames),
        "rms_ideal_pixels": floats(run.rms_ideal),
        "feasible": bool(run.feasible),
        "reason": run.reason,
        "result": run.result,
        "duration_s": run.duration,
        "scoring": "RMS over the second half of the run: `rms` at every 1 kHz sample, "
        "`rms_frames` at the 30 Hz camera samples only, `rms_ideal_pixels` at 1 kHz from "
        "the exact projections instead of the tracked pixels",
    }


def testbed_video(run: TestbedRun, path, fps: float = 30.0) -> None:
    """The rendered frames of a set with the tracked point (green circle) and the estimate
    projected through the true camera (red cross) drawn on them, as an MP4."""

    K = np.asarray(KC_REFINED, float)
    est = np.asarray(run.estimate)[np.minimum(run.frame_index, run.estimate.shape[0] - 1)]
    in_front = np.all(np.isfinite(est), axis=-1) & (est[:, 2] > 0)
    z = np.where(in_front, est[:, 2], 1.0)
    projected = (est[:, :2] / z[:, None]) @ K[:2, :2].T + K[:2, 2]
    projected = np.where(in_front[:, None], projected, np.nan)
    captions = [f"{run.set_name}  t = {t:5.2f} s" for t in np.asarray(run.frame_ts)]
    write_video(path, annotate_frames(run.frames, run.pixels, projected, captions), fps)


_TESTBED_ARRAYS = (
    "ts",
    "position",
    "estimate",
    "estimate_ideal",
    "frame_ts",
    "frame_index",
    "pixels",
    "pixels_true",
    "velocity_true",
    "velocity_measured",
    "q_puma",
)


def testbed_reproduction(
    sets=None,
    units: str = "cm",
    duration: float = 30.0,
    *,
    seed: int = 0,
    video: bool = True,
    studies: bool = True,
    quiet=True,
    write=None,
) -> Reproduction:
    """Chapters 4-5 on the testbed twin (`testbed`), as `visjax testbed` reports it: each set
    end to end, Tables 5-3/5-4 beside the thesis', per set the figure `testbed_<set>`, its
    arrays `testbed_<set>.npz` and (with `video`) the MP4 `testbed_<set>.mp4`, written as
    soon as the set is done; `tables` (Parquet and CSV, one row per set and axis); with
    `studies`, `testbed_studies`."""
    import functools

    from tqdm import tqdm

    names = set_names(sets)
    if units not in UNITS:
        raise ValueError(f"`units` must be one of {list(UNITS)}; got {units!r}")
    per_set, runs = {}, {}
    for name in tqdm(names, desc="testbed", unit="set", disable=quiet):
        keep = write is not None and video
        r = testbed(name, units=units, duration=duration, keep_frames=keep, seed=seed)
        per_set[name] = testbed_record(r)
        if write is not None:
            kind = "moving" if SETS[name].moving else "static"
            arrays = {k: np.asarray(getattr(r, k)) for k in _TESTBED_ARRAYS}
            if r.q_arm is not None:
                arrays["q_arm"] = np.asarray(r.q_arm)
            title = (
                f"Jang's thesis, set {name} ({kind} point) on the testbed twin: A read in "
                f"{units}/s, camera 30 Hz, observer 1 kHz"
            )
            figures = {f"testbed_{name}": functools.partial(plot_testbed, r, title=title)}
            videos = {}
            if keep and r.frames is not None:
                videos[f"testbed_{name}.mp4"] = functools.partial(testbed_video, r)
            write(
                Outputs(
                    arrays={f"testbed_{name}.npz": arrays},
                    figures=figures if r.feasible else {},
                    videos=videos,
                )
            )
        runs[name] = r.__class__(**{**r.__dict__, "frames": None})
    lines = [
        f"UIO (Jang's thesis, eq. 3.5) on the testbed twin: A read in {units}/s, "
        f"{duration:g} s, RMS position error over the second half (m), at 1 kHz"
    ] + table_lines(per_set, names, "twin")
    lines += [f"{n}: {per_set[n]['reason']}" for n in names if not per_set[n]["feasible"]]
    if studies:
        lines += testbed_studies(runs, names, units, duration, seed, quiet=quiet, write=write)
    if write is not None:
        import pandas as pd

        def cell(e, key, i):
            return e[key][i] if e[key] else None

        rows = [
            {
                "set": name,
                "table": "5-3" if name.startswith("I.") else "5-4",
                "axis": axis,
                "rms_m": cell(per_set[name], "rms", i),
                "rms_frames_m": cell(per_set[name], "rms_frames", i),
                "rms_ideal_pixels_m": cell(per_set[name], "rms_ideal_pixels", i),
                "thesis_rms_m": per_set[name]["thesis_rms"][i],
                "feasible": per_set[name]["feasible"],
            }
            for name in names
            for i, axis in enumerate("xyz")
        ]
        write(Outputs(tables={"tables": pd.DataFrame(rows)}, csv=("tables",)))
    body = {"units": units, "duration_s": duration, "sets": per_set}
    return Reproduction(body, lines, settings={"sets": names}, seed=seed)


def testbed_studies(runs, names, units, duration, seed, *, quiet=True, write=None) -> list[str]:
    """Section 2.3's least squares from set I.1's data with Tables 5-1/5-2 redone
    (`calibration.json`), and the sensitivity of the moving sets to the amplitude of
    $v_{py}$ (exact pixels, so that only $v_{py}$ varies; `sensitivity`, Parquet and CSV).
    **Returns:** the printed lines."""
    from tqdm import tqdm

    lines = []
    base = runs.get("I.1")
    if base is not None and base.feasible:
        cam = base.position[base.frame_index]
        m = cam[:, :2] / cam[:, 2:]
        ok = np.all(np.isfinite(base.pixels), axis=1)
        theta = np.asarray(camera_matrix_lstsq(m[ok], base.pixels[ok]).theta)
        K_ls = np.asarray(camera_matrix(theta))
        tables = {}
        for set_name, table, thesis in (
            ("I.2", "table_5_1", TABLE_5_1),
            ("II.1", "table_5_2", TABLE_5_2),
        ):
            row = {"set": set_name, "thesis": {k: list(v) for k, v in thesis.items()}}
            for label, K in (("toolbox", KC_TOOLBOX), ("least_squares", K_ls)):
                r = testbed(set_name, units=units, duration=duration, Kc_observer=K, seed=seed)
                row[label] = [float(x) for x in r.rms] if r.feasible else None
            tables[table] = row
        calibration = {
            "theta_least_squares": [float(x) for x in theta],
            "Kc_least_squares": K_ls.tolist(),
            "Kc_true": np.asarray(KC_REFINED).tolist(),
            "Kc_toolbox": np.asarray(KC_TOOLBOX).tolist(),
            "Kc_thesis_least_squares": np.asarray(KC_REFINED).tolist(),
            "frames_used": int(ok.sum()),
            **tables,
            "note": "the twin renders with the thesis' least-squares Kc as the true camera; "
            "the observer is given the toolbox Kc or the least squares of section 2.3 from "
            "set I.1's tracked pixels and the forward-kinematics truth",
        }
        true = ", ".join(f"{x:.2f}" for x in camera_matrix_to_theta(KC_REFINED))
        lines += [
            "",
            "section 2.3 least squares from set I.1 (twin): [f, af, cx, cy] = "
            + ", ".join(f"{x:.2f}" for x in theta)
            + f"  (true {true})",
        ]
        for table, row in tables.items():
            for label in ("toolbox", "least_squares"):
                v = row[label]
                cells = ", ".join(f"{x:.4f}" for x in v) if v else "infeasible"
                th = ", ".join(f"{x:.4f}" for x in row["thesis"][label])
                lines.append(f"{table} ({row['set']}), {label} Kc: {cells}   (thesis {th})")
        if write is not None:
            write(Outputs(json={"calibration.json": calibration}))
    moving = [n for n in names if SETS[n].moving]
    rows = []
    for name in tqdm(moving, desc="v_py sensitivity", unit="set", disable=quiet or not moving):
        for a in VPY_AMPLITUDES:
            r = testbed(
                name,
                units=units,
                duration=duration,
                vp_amplitude=(SETS[name].vp_amplitude[0], a),
                track=False,
                seed=seed,
            )
            rms = r.rms if r.feasible else np.full(3, np.nan)
            rows += [
                {
                    "set": name, f"v_py_amplitude_{units}_s": a, "axis": axis,
                    "rms_m": float(rms[i]), "feasible": bool(r.feasible), "result": r.result,
                }
                for i, axis in enumerate("xyz")
            ]  # fmt: skip
    if rows:
        import pandas as pd

        table = pd.DataFrame(rows)
        wide = table.pivot(index=["set", f"v_py_amplitude_{units}_s"], columns="axis")["rms_m"]
        lines += ["", f"sensitivity to v_py (amplitude in {units}/s; exact pixels), RMS (m):"]
        printed = (
            wide.add_prefix("rms_")
            .reset_index()
            .to_string(index=False, float_format=lambda x: f"{x:.4f}")
        )
        lines += printed.splitlines()
        if write is not None:
            write(Outputs(tables={"sensitivity": table}, csv=("sensitivity",)))
    return lines


def camera_matrix_to_theta(K) -> list[float]:
    """$[f, \\alpha f, c_x, c_y]$ of a camera matrix, the parameters of section 2.3."""
    K = np.asarray(K, float)
    return [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]


def reproduce_moving_point(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    sets=None,
    duration: float | None = None,
    noise: float = 0.1,
    seed: int = 0,
    seeds: int = 1,
    max_hours: float = 24.0,
) -> list[dict]:
    """The UIO on the simulated analogues of the seven sets (`moving_point_reproduction`),
    registered as the reproduction `moving_point` (what `visjax moving_point` runs):
    `summary.json` (kind `moving_point`), `sets.parquet`, per set `estimate_<set>.npz`,
    `structure_<set>.<format>` and `camera_velocity_<set>.<format>` into `out`.
    `duration` per set: 30 s, 20 with `quick`. **Returns:** its rows: the mean RMS of the
    static sets (I.x) and of the moving ones (II.x) against the thesis' Tables 5-3/5-4."""
    duration = (20.0 if quick else 30.0) if duration is None else duration
    settings = dict(sets=sets, duration=duration, noise=noise, seed=seed, seeds=seeds)
    summary = write_report(
        "moving_point",
        settings,
        out,
        formats,
        lambda write: moving_point_reproduction(
            sets,
            duration,
            noise,
            seed=seed,
            seeds=seeds,
            quiet=quiet,
            write=write,
            max_hours=max_hours,
        ),  # fmt: skip
    )
    return moving_point_rows(summary)


def moving_point_rows(summary: dict) -> list[dict]:
    """The rows of `visjax reproduce`'s table from a `moving_point` summary: per set, the
    axis furthest from the thesis (the largest ratio either way of its RMS to the thesis'
    Tables 5-3/5-4), its RMS against the thesis'. One row per set, never an average over
    sets: a set that misses the thesis (II.3's x, 2.5 times it) shows as itself."""
    rows = []
    for name, e in summary["sets"].items():
        thesis = np.asarray(e["thesis_rms"], float)
        if e.get("rms") is None:  # a run that did not succeed: no number
            i, rms = int(np.argmax(thesis)), np.full(3, np.nan)
        else:
            rms = np.asarray(e["rms"], float)
            with np.errstate(divide="ignore", invalid="ignore"):
                i = int(np.nanargmax(np.abs(np.log(rms / thesis))))
        rows.append(
            reproduction_row(
                f"Jang's thesis, UIO, set {name}: RMS {'xyz'[i]} (the axis furthest from "
                "the thesis)", None if np.isnan(rms[i]) else float(rms[i]), float(thesis[i]),
                "published", "m",
            )
        )  # fmt: skip
    return rows


def reproduce_testbed(
    out=None,
    *,
    quick: bool = False,
    quiet: bool = False,
    formats=("png",),
    sets=None,
    units: str = "cm",
    duration: float | None = None,
    seed: int = 0,
    video: bool = True,
    studies: bool | None = None,
) -> list[dict]:
    """Chapters 4-5 on the testbed twin (`testbed_reproduction`), registered as the
    reproduction `testbed` (what `visjax testbed` runs): `summary.json` (kind `testbed`),
    `tables.parquet/.csv`, `testbed_<set>.<format>/.mp4/.npz`, and with `studies`
    `calibration.json` and `sensitivity.parquet/.csv` into `out`. With `quick`: sets I.1
    and II.1, 10 s each, no studies (else every set, 30 s, the studies). **Returns:** its
    rows: each set's worst-axis RMS against the thesis'."""
    import time

    if quick:
        sets = ["I.1", "II.1"] if sets is None else sets
    duration = (10.0 if quick else 30.0) if duration is None else duration
    studies = (not quick) if studies is None else studies
    settings = dict(
        sets=sets, units=units, duration=duration, seed=seed, video=video, studies=studies
    )
    started = time.time()
    summary = write_report(
        "testbed",
        settings,
        out,
        formats,
        lambda write: testbed_reproduction(
            sets,
            units,
            duration,
            seed=seed,
            video=video,
            studies=studies,
            quiet=quiet,
            write=write,
        ),  # fmt: skip
    )
    if not quiet:
        print(f"({time.time() - started:.0f} s)")
    return testbed_rows(summary)


def testbed_rows(summary: dict) -> list[dict]:
    """The rows of `visjax reproduce`'s table from a `testbed` summary: each set's
    worst-axis RMS against the thesis'."""
    rows = []
    for name, e in summary["sets"].items():
        rms = e["rms"]
        rows.append(
            reproduction_row(
                f"Jang's thesis, testbed twin set {name}: worst-axis RMS"
                + ("" if rms is not None else " (infeasible)"),
                max(rms) if rms is not None else None,
                float(max(e["thesis_rms"])),
                "published",
                "m",
            )
        )
    return rows


RENAMED = {
    "structure_experiment": "moving_point_experiment",
    "structure_reproduction": "moving_point_reproduction",
    "StructureRun": "MovingPointRun",
}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""
__getattr__ = renamed("visjax.papers.jang", RENAMED, globals())
