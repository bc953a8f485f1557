"""Figures. Matplotlib is imported lazily, with the Agg backend when writing files."""

import numpy as np


def _pyplot(path):
    """matplotlib.pyplot, with the file backend when the figure goes to a file."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _finish(fig, title, path):
    import matplotlib.pyplot as plt

    if title:
        fig.suptitle(title)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


DOF_LABELS = (
    ("$v_x$", "m/s"),
    ("$v_y$", "m/s"),
    ("$v_z$", "m/s"),
    ("$\\omega_x$", "rad/s"),
    ("$\\omega_y$", "rad/s"),
    ("$\\omega_z$", "rad/s"),
)


def plot_velocity(ts, velocity, estimate, *, title=None, path=None, max_points=2000):
    """Like Fig. 2 of Chitrakaran et al.: per DOF, true and estimated velocity (left), error
    (right); with `velocity=None` (no truth), the estimate alone."""
    plt = _pyplot(path)

    ts, estimate = np.asarray(ts), np.asarray(estimate)
    step = max(1, len(ts) // max_points)
    t, e = ts[::step], estimate[::step]
    truth = velocity is not None
    cols = 2 if truth else 1
    fig, axes = plt.subplots(6, cols, figsize=(11 if truth else 6, 12), sharex=True, squeeze=False)
    for i, (name, unit) in enumerate(DOF_LABELS):
        ax = axes[i, 0]
        ax.plot(t, e[:, i], "C1-", lw=0.8, label="estimate $J^{-1}\\hat\\kappa$")
        ax.set_ylabel(f"{name} [{unit}]")
        if truth:
            v = np.asarray(velocity)[::step]
            ax.plot(t, v[:, i], "k--", lw=1.2, label="true")
            axes[i, 1].plot(t, v[:, i] - e[:, i], "C0-", lw=0.8)
            axes[i, 1].set_ylabel(f"error {name} [{unit}]")
            axes[i, 1].axhline(0.0, color="0.7", lw=0.5)
    axes[0, 0].legend(fontsize=8, loc="upper right")
    axes[0, 0].set_title("velocity")
    axes[-1, 0].set_xlabel("time [s]")
    if truth:
        axes[0, 1].set_title("velocity error $v - \\hat v$")
        axes[-1, 1].set_xlabel("time [s]")
    return _finish(fig, title, path)


def plot_structure(ts, position, estimate, *, title=None, path=None):
    """Like Figs. 5-7 and 5-8 of Jang's thesis: actual (dashed) and estimated (solid) position
    of the point in the camera frame (left), and the estimation error (right), in metres;
    with `position=None` (no truth), the estimate alone."""
    plt = _pyplot(path)

    ts, estimate = np.asarray(ts), np.asarray(estimate)
    truth = position is not None
    cols = 2 if truth else 1
    fig, axes = plt.subplots(3, cols, figsize=(10 if truth else 6, 7), sharex=True, squeeze=False)
    for i, name in enumerate("XYZ"):
        axes[i, 0].plot(ts, estimate[:, i], "C0-", lw=1.0, label="estimated")
        axes[i, 0].set_ylabel(f"{name} [m]")
        if truth:
            position = np.asarray(position)
            axes[i, 0].plot(ts, position[:, i], "k--", lw=1.2, label="actual")
            axes[i, 1].plot(ts, estimate[:, i] - position[:, i], "C3-", lw=0.8)
            axes[i, 1].axhline(0.0, color="0.7", lw=0.5)
            axes[i, 1].set_ylabel(f"error {name} [m]")
    axes[0, 0].legend(fontsize=8)
    axes[0, 0].set_title("position of the point (camera frame)")
    axes[-1, 0].set_xlabel("time [s]")
    if truth:
        axes[0, 1].set_title("estimation error")
        axes[-1, 1].set_xlabel("time [s]")
        # the transient of the depth dwarfs the steady state: zoom the error axes on it
        half = ts >= ts[-1] / 2
        for i in range(3):
            err = estimate[half, i] - position[half, i]
            lim = 4 * max(np.nanmax(np.abs(err)), 1e-4)
            axes[i, 1].set_ylim(-lim, lim)
    return _finish(fig, title, path)


def plot_testbed(run, *, title=None, path=None):
    """Like Figs. 5-5 to 5-8 of Jang's thesis for one set on the testbed twin: the camera's
    angular and linear velocities (from the encoders, solid; commanded, dashed), the
    marker's actual (dashed, drawn on top) and estimated (solid) position in the camera
    frame, and the estimation error (from tracked pixels; from exact pixels, thin)."""
    plt = _pyplot(path)
    ft = np.asarray(run.frame_ts)
    ts = np.asarray(run.ts)
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    names = ("x", "y", "z")
    for i in range(3):
        axes[0, 0].plot(
            ft,
            run.velocity_measured[:, 3 + i],
            f"C{i}-",
            lw=1.0,
            label=f"$\\omega_{names[i]}$ (encoders)",
        )
        axes[0, 0].plot(ft, run.velocity_true[:, 3 + i], f"C{i}--", lw=1.0)
        axes[0, 1].plot(
            ft,
            run.velocity_measured[:, i],
            f"C{i}-",
            lw=1.0,
            label=f"$v_{{c{names[i]}}}$ (encoders)",
        )
        axes[0, 1].plot(ft, run.velocity_true[:, i], f"C{i}--", lw=1.0)
    axes[0, 0].set_title("camera angular velocity (Fig. 5-5)")
    axes[0, 0].set_ylabel("rad/s")
    axes[0, 1].set_title("camera linear velocity (Fig. 5-6)")
    axes[0, 1].set_ylabel("m/s")
    m = run.estimate.shape[0]
    for i in range(3):
        axes[1, 0].plot(
            ts[:m], run.estimate[:, i], f"C{i}-", lw=1.0, label=f"{names[i].upper()} estimated"
        )
        axes[1, 0].plot(ts[:m], run.position[:m, i], "k--", lw=1.0, zorder=5)
        axes[1, 1].plot(
            ts[:m],
            run.estimate[:, i] - run.position[:m, i],
            f"C{i}-",
            lw=1.0,
            label=f"{names[i].upper()} (tracked pixels)",
        )
        axes[1, 1].plot(ts[:m], run.estimate_ideal[:, i] - run.position[:m, i], f"C{i}:", lw=0.8)
    axes[1, 0].set_title("actual (dashed) and estimated (solid) position (Fig. 5-7)")
    axes[1, 0].set_ylabel("m")
    axes[1, 1].set_title("estimation error (Fig. 5-8); dotted: exact pixels")
    axes[1, 1].set_ylabel("m")
    half = ts[:m] >= ts[m - 1] / 2
    err = run.estimate[half] - run.position[:m][half]
    if np.isfinite(err).any():
        lim = 4 * max(float(np.nanmax(np.abs(err))), 1e-4)
        axes[1, 1].set_ylim(-lim, lim)
    for ax in axes.ravel():
        ax.legend(fontsize=7, loc="upper right", framealpha=0.6)
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    return _finish(fig, title, path)


def plot_euclidean(run, *, title=None, path=None):
    """Seed 004: each unknown feature's estimated world coordinates against the truth, the
    prediction errors of both laws (log scale), and the PE measure of eq. (49)."""
    plt = _pyplot(path)
    ts = np.asarray(run.ts)
    est, true = np.asarray(run.omega_s), np.asarray(run.omega_true)
    n = true.shape[0]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    for c, name in enumerate("xyz"):
        ax = axes[0, c]
        for i in range(n):
            ax.plot(ts, est[:, i, c], f"C{i}-", lw=1.0, label=f"feature {i + 1}")
            ax.axhline(true[i, c], color=f"C{i}", ls="--", lw=0.8)
        ax.set_title(f"$\\hat\\omega_{{s,{name}}}$ (solid) vs truth (dashed)")
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"{name} [m]")
    axes[0, 0].legend(fontsize=7)
    err = np.linalg.norm(est - true[None], axis=-1)
    axes[1, 0].semilogy(ts, np.maximum(err, 1e-9))
    axes[1, 0].set_title("position error per feature [m]")
    axes[1, 1].semilogy(
        ts, np.maximum(np.nanmax(np.asarray(run.p_tilde_c), 1), 1e-9), label="known (camera law)"
    )
    axes[1, 1].semilogy(
        ts,
        np.maximum(np.nanmax(np.asarray(run.p_tilde_s), 1), 1e-9),
        label="unknown (structure law)",
    )
    axes[1, 1].set_title("max prediction error [px]")
    axes[1, 1].legend(fontsize=8)
    axes[1, 2].plot(ts, np.asarray(run.pe))
    axes[1, 2].set_title("PE measure of eq. (49), sliding window")
    for ax in axes[1]:
        ax.set_xlabel("time [s]")
    return _finish(fig, title, path)


def plot_feature_estimates(ts, estimate, truth=None, *, title=None, path=None):
    """Nath et al. on a user's data: each unknown feature's estimated world coordinates
    (solid; the truth dashed, on top, when known) and, with the truth, the position error
    per feature on a log axis."""
    plt = _pyplot(path)
    ts, est = np.asarray(ts), np.asarray(estimate)
    n = est.shape[1]
    rows = 2 if truth is not None else 1
    fig, axes = plt.subplots(rows, 3, figsize=(13, 3.6 * rows), squeeze=False)
    for c, name in enumerate("xyz"):
        ax = axes[0, c]
        for i in range(n):
            ax.plot(ts, est[:, i, c], f"C{i % 10}-", lw=1.0, label=f"unknown {i + 1}")
            if truth is not None:
                ax.axhline(np.asarray(truth)[i, c], color=f"C{i % 10}", ls="--", lw=0.9)
        ax.set_xlabel("time [s]")
        ax.set_ylabel(f"world {name} [m]")
    axes[0, 0].legend(fontsize=7)
    if truth is not None:
        err = np.linalg.norm(est - np.asarray(truth)[None], axis=-1)
        axes[1, 0].semilogy(ts, np.maximum(err, 1e-9))
        axes[1, 0].set_xlabel("time [s]")
        axes[1, 0].set_ylabel("position error [m]")
        axes[1, 1].axis("off")
        axes[1, 2].axis("off")
    return _finish(fig, title, path)


def plot_geometry(scenes, ours, errors, *, title=None, path=None):
    """Chitrakaran et al., section 3: scene 0's pixels with the recovered homography's
    transfer (left), and every scene's errors against ground truth, visjax and OpenCV."""
    plt = _pyplot(path)
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.5))
    p_ref, p_cur, A = scenes.p_ref[0], scenes.p_cur[0], scenes.A[0]
    q = np.c_[p_ref, np.ones(len(p_ref))] @ (A @ ours["H"][0] @ np.linalg.inv(A)).T
    ax0.plot(*p_ref.T, "o", mfc="none", label="reference $p_i^*$")
    ax0.plot(*p_cur.T, "s", mfc="none", label="current $p_i$")
    ax0.plot(*(q[:, :2] / q[:, 2:]).T, "k+", ms=12, label="$A H A^{-1} p_i^*$ (visjax)")
    ax0.set_xlim(0, 640)
    ax0.set_ylim(480, 0)
    ax0.set_aspect("equal")
    ax0.set_title("scene 0: pixels")
    ax0.set_xlabel("u [px]")
    ax0.set_ylabel("v [px]")
    ax0.legend(fontsize=8)
    floor = 1e-17
    for who, marker in (("visjax", "o"), ("opencv", "x")):
        e = errors[who]
        ax1.semilogy(
            np.maximum(e["R_bar_deg"], floor), marker, ms=4, label=f"{who}: $\\bar R$ [deg]"
        )
        ax1.semilogy(
            np.maximum(e["alpha_rel"], floor),
            marker,
            ms=4,
            mfc="none",
            label=f"{who}: $\\alpha_i$ [rel]",
        )
    ax1.set_xlabel("scene")
    ax1.set_title("errors against ground truth")
    ax1.legend(fontsize=8)
    return _finish(fig, title, path)


def plot_comparison(records, accuracy, *, label, title=None, path=None):
    """`visjax compare`: per method, the accuracy of every seed (left; a dot per seed, a bar
    at the median, flagged runs as red crosses at the top) and the latency per new sample
    (right), both on log axes. `accuracy(record) -> float` picks the headline number."""
    plt = _pyplot(path)
    methods = list(dict.fromkeys(r["method"] for r in records))
    fig, axes = plt.subplots(1, 2, figsize=(7.0, 3.0))
    for i, method in enumerate(methods):
        rows = [r for r in records if r["method"] == method]
        good = [accuracy(r) for r in rows if r["result"] == "successful"]
        good = [g for g in good if np.isfinite(g) and g > 0]
        if good:
            axes[0].plot([i] * len(good), good, "o", color="C0", alpha=0.6, ms=4)
            axes[0].hlines(np.median(good), i - 0.3, i + 0.3, color="k")
        failed = sum(r["result"] != "successful" for r in rows)
        if failed:
            axes[0].annotate(
                f"{failed} failed",
                (i, 1.0),
                xycoords=("data", "axes fraction"),
                ha="center",
                va="top",
                color="C3",
            )
        lat = [r["latency_s_per_sample"] for r in rows]
        axes[1].plot([i] * len(lat), lat, "o", color="C1", alpha=0.6, ms=4)
        axes[1].hlines(np.median(lat), i - 0.3, i + 0.3, color="k")
    for ax, ylabel in zip(axes, (label, "latency per new sample (s)")):
        ax.set_yscale("log")
        ax.set_xticks(range(len(methods)), methods, rotation=20)
        ax.set_ylabel(ylabel)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    return _finish(fig, title, path)


def plot_sweep(
    summary, metric, params, *, best=None, paper=None, label=None, title=None, path=None
):
    """`visjax sweep` and `visjax tune`: the metric against each parameter (log-log), one
    panel per parameter. Grey dots: every point's mean over seeds; the line: the best mean
    at each value of the parameter (over the other parameters), with the spread over seeds
    (min to max) as a band; points with a failed run as red crosses at the top; the best
    point (star) and the paper's gains (square) marked with their held-out metric.

    `summary` is `studies.summarise(table, metric)`; `best` and `paper` are dicts with
    `params` and `metric`."""
    plt = _pyplot(path)
    fig, axes = plt.subplots(1, len(params), figsize=(3.4 * len(params), 3.6), squeeze=False)
    mean = summary[f"{metric}_mean"].to_numpy(float)
    lo = summary[f"{metric}_min"].to_numpy(float)
    hi = summary[f"{metric}_max"].to_numpy(float)
    failed = summary["n_failed"].to_numpy() > 0
    for ax, p in zip(axes[0], params):
        x = summary[p].to_numpy(float)
        ok = ~failed & np.isfinite(mean) & (mean > 0)
        ax.plot(x[ok], mean[ok], ".", color="0.6", ms=4, label="mean over seeds")
        xs = np.unique(x[ok])
        if xs.size:
            pick = [np.flatnonzero(ok & (x == v))[np.argmin(mean[ok & (x == v)])] for v in xs]
            ax.plot(xs, mean[pick], "-", color="C0", label="best over the others")
            ax.fill_between(xs, lo[pick], hi[pick], color="C0", alpha=0.2, label="seed spread")
        if failed.any():
            ax.plot(
                x[failed],
                np.full(failed.sum(), 1.0),
                "x",
                color="C3",
                transform=ax.get_xaxis_transform(),
                label="a run failed",
            )
        for mark, style, name in ((best, "*", "best (held-out)"), (paper, "s", "paper (held-out)")):
            if mark is not None and p in mark["params"] and np.isfinite(mark["metric"]):
                ax.plot(
                    [mark["params"][p]],
                    [mark["metric"]],
                    style,
                    color="C1" if style == "*" else "k",
                    ms=10 if style == "*" else 6,
                    label=name,
                    zorder=5,
                )
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel(f"{p} (multiplier of the reference gain)")
        ax.set_ylabel(label or metric)
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=3, fontsize=7, frameon=False)
    if title:
        import textwrap

        fig.suptitle(textwrap.fill(title, 80), fontsize=9)
    fig.tight_layout(rect=(0, 0.16, 1, 1))
    if path is not None:
        fig.savefig(path, dpi=110)
        plt.close(fig)
    return fig


def plot_tune_history(history, *, label=None, title=None, path=None):
    """`visjax tune`: the training loss per optimiser step (log axis)."""
    plt = _pyplot(path)
    fig, ax = plt.subplots(figsize=(4.0, 3.0))
    steps = [h["step"] for h in history]
    loss = [h["loss"] for h in history]
    ax.plot(steps, loss, "o-", ms=3)
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel(label or "training loss")
    ax.grid(True, which="both", alpha=0.3)
    return _finish(fig, title, path)
