"""The testbed of Jang's thesis as a digital twin (chapters 4-5): the PUMA 560 carrying
the camera, the two-link robot carrying the marker, rendered frames tracked by KLT, the
joint encoders' velocities, and the error sources of the thesis' hardware as options
(`testbed`, `ERROR_SOURCES`, `testbed_error_budget`)."""

from collections.abc import Callable
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from ..._results import RESULTS, result_names
from ...estimators import moving_point_stream, run
from ...frontend import (
    Plane,
    annotate_frames,
    fiducial_marker,
    render_planes,
    textured_table,
    track_marker,
    write_video,
)
from ...geometry import DISTORTION_LENGTHS, distort_pixels
from ...kinematics import TwoLinkArm, puma560
from ...sim import encoder_twist, follow_tool_twist, hold_indices, planar_path, sample_times
from .._reproduction import floats
from ._scene import KC_REFINED, KC_TOOLBOX, SETS, ThesisSet, _velocities, observer

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
      marker centre (NaN where lost); `pixels_true` (F, 2) its exact pinhole projection;
      `velocity_true` (F, 6), `velocity_measured` (F, 6): the camera's $[v_c, \\omega]$
      (m/s, rad/s, camera frame), exact and from the encoders (`time_offset_s` earlier).
    - `q_puma` (N, 6), `q_arm` (N, 2) or `None`: the robots' joint angles.
    - `rms` (3,) the RMS error over the second half at 1 kHz; `rms_frames` (3,) at the
      camera samples only; `rms_ideal` (3,) at 1 kHz from ideal pixels; `tracking_rms_px`
      the tracked centre's RMS distance to its projection (px; through the lens, with
      `dist`: the tracker's error alone).
    - `result` the UIO's result name (from tracked pixels; the RMS fields are NaN when a
      run did not succeed, e.g. `diverged`: the depth estimate became negative), or
      `not_run` (infeasible), `marker_never_found`, `marker_found_late` (first found in
      the scored second half: the observer starts at the first frame the marker is found
      in, the estimates are NaN before it); `frames` (F, H, W) uint8 when kept, else
      `None`; `Kc_true` (3, 3) and `dist` (or `None`) the camera that rendered them.
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
    Kc_true: np.ndarray | None = None
    dist: np.ndarray | None = None


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
    dist=None,
    time_offset_s: float | None = None,
    image_noise: float = 0.0,
    blur_px: float = 0.0,
    encoder_resolution=None,
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

    The error sources of the thesis' hardware that the twin leaves out by default (each
    set in `ERROR_SOURCES` with its value and what it rests on; `testbed_error_budget`):

    - `dist`: OpenCV's distortion coefficients of the true lens. The frames are rendered
      through it (`render_planes(dist=...)`); the tracker and the observer ignore it, as
      the thesis' chain does (it names no undistortion). `pixels_true` stays the pinhole
      projection the observer needs; `tracking_rms_px` is measured against the lens'
      image of the centre, so that it is the tracker's error alone.
    - `Kc_true` against `Kc_observer`: the camera's calibration error.
    - `time_offset_s`: how much earlier than its frame the camera velocity paired with it
      was measured (the encoders' twist at the frame's time minus this offset, rounded to
      a whole sample of `rate_hz`: 1/60 s is 17 ms at 1 kHz; default
      `TESTBED["velocity_delay_s"]`, 0).
    - `image_noise`: the standard deviation of additive Gaussian noise on each rendered
      frame (grey levels of 255; drawn from `seed`); `blur_px`: a Gaussian blur of that
      standard deviation (pixels) before the noise (defocus, the lens' softness).
    - `encoder_resolution`: rad per count at the joints, one number or one per joint
      (default `TESTBED["encoder_resolution"]`).
    """
    import cv2  # noqa: F401  (the frontend needs OpenCV; fail early and clearly)

    if set_name not in SETS:
        raise ValueError(f"unknown set {set_name!r}; expected one of {list(SETS)}.")
    if units not in UNITS:
        raise ValueError(f"`units` must be 'cm' or 'm'; got {units!r}.")
    s = SETS[set_name]
    cfg = TESTBED
    offset = cfg["velocity_delay_s"] if time_offset_s is None else time_offset_s
    resolution = cfg["encoder_resolution"] if encoder_resolution is None else encoder_resolution
    resolution = np.asarray(resolution, float)
    if resolution.shape not in ((), (6,)) or not np.all(np.isfinite(resolution) & (resolution > 0)):
        raise ValueError(
            "`encoder_resolution` must be one positive number or six (rad per count, one "
            f"per joint); got {encoder_resolution!r}."
        )
    for name, value in (("time_offset_s", offset), ("image_noise", image_noise),
                        ("blur_px", blur_px)):  # fmt: skip
        if not (np.isscalar(value) and np.isfinite(value) and value >= 0):
            raise ValueError(f"`{name}` must be a finite number >= 0; got {value!r}.")
    if 0 < offset < 0.5 / rate_hz:
        raise ValueError(
            f"`time_offset_s` = {offset!r} rounds to no sample at {rate_hz} Hz: give 0 or at "
            f"least {0.5 / rate_hz:g} s."
        )
    if dist is not None:
        dist = np.asarray(dist, float)
        if dist.shape not in {(k,) for k in DISTORTION_LENGTHS} or not np.isfinite(dist).all():
            raise ValueError(
                "`dist` must hold 4, 5, 8, 12 or 14 finite coefficients (OpenCV's order); "
                f"got {dist.tolist()!r}."
            )
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
    delay = int(round(offset * rate_hz))  # the camera-to-encoder offset, in samples
    history = window + delay  # the samples before t = 0 the encoders need
    pre = -jnp.arange(history, 0, -1, dtype=ts.dtype) / rate_hz
    ts_all = jnp.concatenate([pre, ts])
    mid = history + n // 2
    after, before = ts_all[mid:], ts_all[: mid + 1][::-1]
    fwd = follow_tool_twist(chain, q_mid, u_fn, after)
    bwd = follow_tool_twist(chain, q_mid, u_fn, before)
    q_all = np.concatenate([np.asarray(bwd.q)[::-1][:-1], np.asarray(fwd.q)])
    q = q_all[history:]
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
        reach = np.linalg.norm(rel, axis=1)
        if feasible and not np.all((reach < l1 + l2 - 1e-3) & (reach > abs(l1 - l2) + 1e-3)):
            k = int(np.argmax(~((reach < l1 + l2 - 1e-3) & (reach > abs(l1 - l2) + 1e-3))))
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
            resolution=jnp.asarray(resolution),
            window=window,
        )
    )
    velocity_measured = u_enc[history + first - delay]  # the twist `offset` before the frame

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
        noise_rng = np.random.default_rng([seed, 1])  # the texture's seed, its own stream
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
                dist=dist,
            )
            frames[i] = _degrade(frames[i], blur_px, image_noise, noise_rng)
        tracks = track_marker(frames, fps=camera_hz, marker_id=0, dictionary=marker)
        pixels = tracks.pixels[:, 4]  # the centre: the diagonals' intersection
        seen = pixels_true if dist is None else np.asarray(distort_pixels(pixels_true, Kt, dist))
        err = np.linalg.norm(pixels - seen, axis=1)
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
        # the observer starts at the first frame the marker is found in (blur or noise can
        # hide it at first); NaN before that
        found = np.flatnonzero(np.all(np.isfinite(px), axis=1))
        if found.size == 0:
            return np.full((first[-1] + 1, 3), np.nan), "marker_never_found"
        k0 = int(found[0])
        stream = moving_point_stream(
            frame_ts[k0:],
            px[k0:],
            vel_obs[k0:],
            jnp.asarray(Kc_observer, float),
            dropped="hold",
            throw=False,
        )
        sol = run(obs, stream, dt=1.0 / rate_hz, throw=False)
        est = np.asarray(sol.outputs.position) / to_unit
        est = np.concatenate([np.full((first[k0], 3), np.nan), est])
        if frame_ts[k0] >= duration / 2:  # nothing to score
            return est, "marker_found_late"
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
        Kc_true=Kt,
        dist=dist,
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


def _degrade(frame, blur_px, noise, rng):
    """A rendered frame blurred (Gaussian, standard deviation `blur_px`) and with additive
    Gaussian noise of standard deviation `noise` grey levels, rounded back to uint8."""
    import cv2

    if blur_px > 0:
        frame = cv2.GaussianBlur(frame, (0, 0), blur_px)
    if noise > 0:
        noisy = frame.astype(float) + rng.normal(0.0, noise, frame.shape)
        frame = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
    return frame


def _pose_matrix(R, p):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


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
    projected through the true camera and lens (red cross) drawn on them, as an MP4."""

    K = np.asarray(KC_REFINED if run.Kc_true is None else run.Kc_true, float)
    est = np.asarray(run.estimate)[np.minimum(run.frame_index, run.estimate.shape[0] - 1)]
    in_front = np.all(np.isfinite(est), axis=-1) & (est[:, 2] > 0)
    z = np.where(in_front, est[:, 2], 1.0)
    projected = (est[:, :2] / z[:, None]) @ K[:2, :2].T + K[:2, 2]
    if run.dist is not None:
        projected = np.asarray(distort_pixels(projected, K, run.dist))
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


# --------------------------------------------------------------------------------------
# The error budget: what the thesis' hardware had and the twin leaves out by default.

PUMA560_COUNTS_PER_DEGREE = (173.92, 239.59, 149.18, 211.21, 199.79, 106.51)
"""Encoder counts per degree of the PUMA 560's six joints, as a laboratory driving a PUMA
560's servo boards directly reported them (S. Graves, "Puma 560 encoders->degrees",
comp.robotics, 4 October 1990; joint 6 with the board's divide-by-two bit). Joints 1, 3,
4 and 5 are 1,000 counts per motor revolution times the gear ratios of Armstrong, Khatib
and Burdick, *The Explicit Dynamic Model and Inertial Parameters of the PUMA 560 Arm*
(1986): 62.6111, 53.7063, 76.0364, 71.923. Not from the thesis, which states no
resolution."""


@dataclass(frozen=True)
class ErrorSource:
    """An error source of the thesis' hardware that the twin leaves out by default.

    **Fields:** `name`; `options` the keyword arguments of `testbed` that turn it on;
    `value` in words; `basis` `"thesis"` (its value is the thesis' own), `"literature"`
    (a published value, not the thesis') or `"assumption"`; `rests_on` the text it rests
    on; `other` other readings, `((label, options), ...)`, shown beside it."""

    name: str
    options: dict
    value: str
    basis: str
    rests_on: str
    other: tuple = ()


ERROR_SOURCES = {
    "lens_distortion": ErrorSource(
        "lens_distortion",
        {"dist": (-0.3, 0.0, 0.0, 0.0)},
        "k1 = -0.3 (barrel: 1 px at 100 px from the principal point along x, 35 to 81 px "
        "at the image's corners)",
        "assumption",
        "the camera was calibrated with Bouguet's toolbox (section 5.1), which estimates "
        "distortion, but the thesis gives only Kc and names no undistortion; -0.3 is the "
        "lens of visjax's distortion test, for a lens 60 degrees across as Kc's is",
        (("k1 = -0.1", {"dist": (-0.1, 0.0, 0.0, 0.0)}),),
    ),
    "calibration": ErrorSource(
        "calibration",
        {"Kc_true": KC_TOOLBOX, "Kc_observer": KC_REFINED},
        "the camera is the toolbox's Kc, the observer uses the least-squares Kc (the two "
        "differ by 9 and 12 px in focal length, 14.5 px in c_y)",
        "thesis",
        "Kc (toolbox) and the optimized Kc of section 5.1, 'used for the entire "
        "experiments': how far apart the thesis' own two calibrations are (reversed: the "
        "camera is the least-squares Kc, the observer uses the toolbox's, as Tables 5-1/5-2)",
        (("reversed", {"Kc_true": KC_REFINED, "Kc_observer": KC_TOOLBOX}),),
    ),
    "time_offset": ErrorSource(
        "time_offset",
        {"time_offset_s": 1.0 / 60.0},
        "the velocity paired with a frame is 16.7 ms older than the frame (the mean age of "
        "the latest of a 30 Hz stream not synchronised with the camera; 17 ms at 1 kHz)",
        "assumption",
        "'the camera velocities computed on the PUMA-workstation are transmitted to the "
        "main-workstation via serial communication at 30 Hz' (section 5.1); no "
        "synchronisation is stated (33.3 ms: the oldest such velocity)",
        (("33.3 ms", {"time_offset_s": 1.0 / 30.0}),),
    ),
    "detection": ErrorSource(
        "detection",
        {"image_noise": 2.0, "blur_px": 1.0},
        "Gaussian image noise of 2 grey levels and a Gaussian blur of 1 px",
        "assumption",
        "the thesis shows its tracked images (Figs. 5-3/5-4) but states no noise or focus",
        (("5 grey levels, 2 px", {"image_noise": 5.0, "blur_px": 2.0}),),
    ),
    "encoders": ErrorSource(
        "encoders",
        {"encoder_resolution": tuple(np.pi / 180.0 / np.asarray(PUMA560_COUNTS_PER_DEGREE))},
        "the PUMA 560's encoders: 1.0e-4, 7.3e-5, 1.2e-4, 8.3e-5, 8.7e-5, 1.6e-4 rad per "
        "count (the twin's default is 2.4e-5 rad at every joint)",
        "literature",
        "`PUMA560_COUNTS_PER_DEGREE`; the thesis states no resolution ('the forward "
        "velocity kinematics are used to obtain the position and velocity of the camera', "
        "section 5.1)",
    ),
}
"""The error sources of the thesis' hardware that `testbed` leaves out unless asked
(`ErrorSource`: each one's options, value and what it rests on). None is chosen to match
the thesis' errors: each value was fixed before any run of the budget."""


def testbed_error_budget(
    sets=("I.1", "II.1"),
    *,
    units: str = "cm",
    duration: float = 30.0,
    seed: int = 0,
    sources=None,
    other_readings: bool = True,
    quiet: bool = True,
):
    """The twin's error with each of the hardware's error sources (`ERROR_SOURCES`) alone
    and with all of them together, beside the thesis' measured error (Tables 5-3/5-4).

    Per set, `testbed` runs with no source (the twin as it is), each source alone at its
    stated value, all together, and (with `other_readings`) each source's other readings
    alone. `sources` the names to include (default all).

    **Returns:** a `pandas.DataFrame`, one row per set, configuration and axis: `set`,
    `sources` (`"none"`, a source's name or `"all"`), `reading` (`"stated"` or the other
    reading's label), `axis`, `rms_m` (NaN when the run did not succeed), `thesis_rms_m`,
    `tracking_rms_px`, `result`."""
    import pandas as pd
    from tqdm import tqdm

    names = list(ERROR_SOURCES) if sources is None else list(sources)
    for name in names:
        if name not in ERROR_SOURCES:
            raise ValueError(f"unknown error source {name!r}; choose from {list(ERROR_SOURCES)}")
    together = {}
    for name in names:
        together.update(ERROR_SOURCES[name].options)
    runs = [("none", "stated", {})]
    runs += [(name, "stated", ERROR_SOURCES[name].options) for name in names]
    runs += [("all", "stated", together)] if len(names) > 1 else []
    if other_readings:
        runs += [(name, label, o) for name in names for label, o in ERROR_SOURCES[name].other]
    rows = []
    todo = [(s, r) for s in sets for r in runs]
    for set_name, (source, reading, options) in tqdm(
        todo, desc="error budget", unit="run", disable=quiet
    ):
        r = testbed(set_name, units=units, duration=duration, seed=seed, **options)
        rms = r.rms if r.feasible else np.full(3, np.nan)
        rows += [
            {
                "set": set_name, "sources": source, "reading": reading, "axis": axis,
                "rms_m": float(rms[i]), "thesis_rms_m": float(SETS[set_name].thesis_rms[i]),
                "tracking_rms_px": float(r.tracking_rms_px) if r.feasible else np.nan,
                "result": r.result,
            }
            for i, axis in enumerate("xyz")
        ]  # fmt: skip
    return pd.DataFrame(rows)


def error_budget_lines(table) -> list[str]:
    """`testbed_error_budget`'s table as printed lines: per set, one line per
    configuration with the RMS of x, y, z (mm) and the tracking error, then the thesis'."""
    lines = []
    for set_name, part in table.groupby("set", sort=False):
        lines += ["", f"error budget, set {set_name}: RMS over the second half (mm)"]
        lines.append(f"{'sources':<58}{'x':>8}{'y':>8}{'z':>8}{'track px':>10}")
        for (source, reading), one in part.groupby(["sources", "reading"], sort=False):
            rms = one.set_index("axis")["rms_m"] * 1e3
            label = source if reading == "stated" else f"{source} ({reading})"
            cells = "".join(f"{rms[a]:>8.1f}" for a in "xyz")
            lines.append(f"{label[:57]:<58}{cells}{one['tracking_rms_px'].iloc[0]:>10.3f}")
        thesis = part[part["sources"] == "none"].set_index("axis")["thesis_rms_m"] * 1e3
        lines.append(f"{'the thesis (measured on the hardware)':<58}"
                     + "".join(f"{thesis[a]:>8.1f}" for a in "xyz"))  # fmt: skip
    return lines
