"""Figures for a paper. Matplotlib is imported lazily, with the Agg backend when writing files.

Conventions, shared by every `plot_*` function:

- **Files.** With `path`, the figure is saved once per entry of `formats` (any of `"png"`,
  `"pdf"`, `"svg"`; default `("png",)`) at `pathlib.Path(path).with_suffix("." + fmt)`:
  `path=out / "velocity.png", formats=("png", "pdf", "svg")` writes `velocity.png`,
  `velocity.pdf` and `velocity.svg`. A format outside these raises a `ValueError` naming it
  before anything is drawn or written. PNG at 300 dpi; PDF and SVG are vector (fonts
  embedded as TrueType, no creation date, so that reruns give the same files). Long
  trajectories are decimated to at most `max_points` samples per line (default 2000), and a
  line of more than 5000 points (a larger `max_points`) is rasterised inside the vector file,
  so that a figure stays a small file. The function returns the `Figure` (closed once saved).
- **Size.** A single-column figure is 3.5 in wide, a double-column one 7.16 in (IEEE
  columns), heights in proportion; text is 8 pt (the title 9 pt, wrapped to the width),
  set per figure through `matplotlib.rc_context`: the global `rcParams` are never changed.
- **Truth and estimate.** The truth is drawn on top (higher zorder), black, dashed and thin;
  the estimate solid, in colour, underneath, so that a noisy estimate never hides the truth.
  Lines carry a `gid` (`"truth"`, `"estimate"`, `"measured"`, `"error"`) for whoever
  post-processes them.
- **Coinciding lines** (components identically zero, two methods with the same result) are
  drawn in interleaved dashes of their colours, so that none hides another; the legend
  keeps each one's own solid line.
- **Legends** never cover data: one figure legend below the panels (or above a panel, outside
  its axes).
- **Axes.** Every axis that shows data is labelled with its unit in brackets: `time [s]`,
  `error [mm]`, `[deg]`, `[-]` for a dimensionless quantity; panels stacked on a shared time
  axis carry `time [s]` on the bottom one. A caller's label with its unit in trailing
  parentheses, `"... (m)"`, is shown as `"... [m]"`. Quantities of different units are never
  on one axis (the geometry figure: degrees and relative errors on separate panels).
- **Spread over seeds.** The functions that draw estimation errors (`plot_velocity`,
  `plot_moving_point`, `plot_feature_estimates`, `plot_static_points`, and `plot_comparison`'s
  `errors`) take estimates with an extra leading seed axis, (S, N, d) instead of (N, d): then
  each line is the median over the S seeds, with the 10-90 % band over seeds shaded in its
  colour; the truth may be (N, d) (the same for every seed) or (S, N, d).
- **Titles** name the method by its authors ("Chitrakaran et al.", "Jang's thesis",
  "Nath et al."). Figures for a paper are usually better without a title (`title=None`): the caption
  says it.
"""

import contextlib
import difflib
import pathlib
import re
import textwrap
import warnings

import numpy as np

FORMATS = ("png", "pdf", "svg")
"""The file formats `formats=` accepts."""
SINGLE_COLUMN = 3.5
"""Width of a single-column figure [in]."""
DOUBLE_COLUMN = 7.16
"""Width of a double-column figure [in]."""
DPI = 300
"""Resolution of the PNG files [dots per inch]."""
BAND = (10.0, 90.0)
"""Percentiles of the shaded band over seeds."""
RASTER_POINTS = 5000
"""Lines of more points than this are rasterised in PDF/SVG files."""

_STYLE = {
    "font.size": 8,
    "axes.titlesize": 8,
    "axes.labelsize": 8,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 8,
    "figure.titlesize": 9,
    "lines.linewidth": 1.0,
    "lines.markersize": 3.5,
    "axes.linewidth": 0.6,
    "xtick.major.width": 0.6,
    "ytick.major.width": 0.6,
    "xtick.minor.width": 0.4,
    "ytick.minor.width": 0.4,
    "grid.linewidth": 0.4,
    "legend.frameon": False,
    "legend.handlelength": 2.2,
    "savefig.dpi": DPI,
    "pdf.fonttype": 42,
    "ps.fonttype": 42,
    "figure.constrained_layout.use": True,
    "figure.constrained_layout.h_pad": 0.03,
    "figure.constrained_layout.w_pad": 0.03,
}
_TRUTH = {"color": "k", "ls": "--", "lw": 0.8, "zorder": 3.0, "gid": "truth"}
_ESTIMATE_LW = 1.0
_ZERO = {"color": "0.6", "lw": 0.5, "zorder": 1.0}
_METADATA = {"png": {"Software": None}, "pdf": {"CreationDate": None}, "svg": {"Date": None}}

DOF_LABELS = (
    ("$v_x$", "m/s"),
    ("$v_y$", "m/s"),
    ("$v_z$", "m/s"),
    ("$\\omega_x$", "rad/s"),
    ("$\\omega_y$", "rad/s"),
    ("$\\omega_z$", "rad/s"),
)


# ---------------------------------------------------------------------------------------------
# helpers


def figure_formats(formats) -> tuple:
    """The requested figure formats (names, or one comma-separated string: `"png,pdf"`),
    lower-case, each once. **Raises:** `ValueError` naming the first one not in `FORMATS`,
    or for none."""
    if isinstance(formats, str):
        formats = [f.strip() for f in formats.split(",") if f.strip()]
    out = []
    for fmt in formats:
        name = str(fmt).lower().lstrip(".")
        if name not in FORMATS:
            close = difflib.get_close_matches(name, FORMATS, n=1)  # as `_util.did_you_mean`
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ValueError(
                f"unknown figure format {fmt!r}{hint}; choose from {', '.join(FORMATS)}"
            )
        if name not in out:
            out.append(name)
    if not out:
        raise ValueError(f"`formats` is empty; give at least one of {list(FORMATS)}")
    return tuple(out)


def _pyplot(path):
    """matplotlib.pyplot, with the file backend when the figure goes to a file."""
    import matplotlib

    if path is not None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


@contextlib.contextmanager
def _style():
    """The paper style, for one figure (a context manager). Everything it sets is restored
    on exit except `interactive`: pyplot turns that on when the first figure of a Jupyter
    kernel selects its inline backend, and restoring it would hide every later figure."""
    import matplotlib

    with matplotlib.rc_context(_STYLE):
        yield
        interactive = matplotlib.rcParams["interactive"]
    matplotlib.rcParams["interactive"] = interactive


def _subplots(plt, nrows, ncols, width, height, **kwargs):
    """A figure of `width` x `height` inches and its axes (always 2-d)."""
    return plt.subplots(nrows, ncols, figsize=(width, height), squeeze=False, **kwargs)


def _unit_label(label: str) -> str:
    """`"... (m)"` -> `"... [m]"`: a trailing parenthesised unit shown in brackets."""
    label = str(label)
    if "[" in label:
        return label
    match = re.fullmatch(r"(.*\S)\s*\(([^()]+)\)\s*", label)
    if match:
        return f"{match.group(1)} [{match.group(2)}]"
    return label


def _finish(fig, title, path, formats):
    """Title, fixed tick label sizes, then save once per format and close."""
    import matplotlib.pyplot as plt

    if title:
        chars = max(30, int(fig.get_figwidth() * 13))
        # a number and its unit stay on one line
        text = re.sub(r"(\d) (?=[^\W\d])", "\\1\u00a0", str(title))
        fig.suptitle(textwrap.fill(text, chars), fontsize=_STYLE["figure.titlesize"])
    _interleave_coincident(fig)
    for ax in fig.axes:
        # ticks are made at draw time: keep their size when drawn outside the rc_context
        ax.tick_params(labelsize=_STYLE["xtick.labelsize"])
        _fit_label(ax.yaxis.label, ax.get_position().height * fig.get_figheight())
        _fit_label(ax.xaxis.label, ax.get_position().width * fig.get_figwidth())
    if path is not None:
        base = pathlib.Path(path)
        for fmt in formats:
            fig.savefig(base.with_suffix("." + fmt), format=fmt, dpi=DPI, metadata=_METADATA[fmt])
        plt.close(fig)
    return fig


_DASH = 4.0  # points: one colour's dash in a group of coinciding lines


def _interleave_coincident(fig) -> None:
    """Solid lines of one axes that coincide (the same times, values within 1e-3 of the
    axes' range at every point) would hide all but the last drawn: each group is redrawn
    in interleaved dashes, one dash of each colour in turn. The truth (dashed already)
    and reference lines (two points) are left as they are."""
    for ax in fig.axes:
        lines = [
            ln
            for ln in ax.get_lines()
            if ln.get_gid() != "truth" and ln.get_linestyle() == "-" and np.size(ln.get_xdata()) > 2
        ]
        if len(lines) < 2:
            continue
        data = [(np.asarray(ln.get_xdata(), float), np.asarray(ln.get_ydata(), float))
                for ln in lines]  # fmt: skip
        values = np.concatenate([y[np.isfinite(y)] for _, y in data])
        if values.size == 0:
            continue
        tol = 1e-3 * max(float(np.ptp(values)), float(np.max(np.abs(values))), 1e-300)
        groups: list[list[int]] = []
        for i, (x, y) in enumerate(data):
            for group in groups:
                x0, y0 = data[group[0]]
                if (
                    x.shape == x0.shape
                    and np.array_equal(x, x0)
                    and y.shape == y0.shape
                    and np.allclose(y, y0, rtol=0.0, atol=tol, equal_nan=True)
                ):
                    group.append(i)
                    break
            else:
                groups.append([i])
        for group in groups:
            k = len(group)
            for j, i in enumerate(group if k > 1 else ()):
                lines[i].set_linestyle((j * _DASH, (_DASH, (k - 1) * _DASH)))


def _fit_label(text, inches: float) -> None:
    """Wrap an axis label onto as many lines as fit `inches` of the axes' side (about
    4.4 pt a character at 8 pt), its unit in brackets kept whole: a label longer than its
    axes would reach off the canvas."""
    label = text.get_text()
    chars = max(12, int(inches * 72 / 4.4))
    if "\n" in label or len(label) <= chars:
        return
    kept = re.sub(r"\[[^\]]*\]", lambda m: m.group(0).replace(" ", "\u00a0"), label)
    text.set_text(textwrap.fill(kept, chars, break_long_words=False).replace("\u00a0", " "))


def _legend(fig, handles, labels=None, ncol=None):
    """A figure legend below the panels (outside every axes)."""
    if labels is None:
        labels = [h.get_label() for h in handles]
    ncol = max(1, min(ncol or 4, len(handles)))
    # matplotlib fills the columns first: reorder so that the entries read by rows
    order = [k for c in range(ncol) for k in range(c, len(handles), ncol)]
    handles, labels = [handles[k] for k in order], [labels[k] for k in order]
    return fig.legend(handles, labels, loc="outside lower center", ncol=ncol)


def _stride(n: int, max_points) -> int:
    """The step that keeps at most `max_points` of `n` samples."""
    if max_points is None or max_points <= 0:
        return 1
    return max(1, -(-int(n) // int(max_points)))


def _decimate(a, step: int, axis: int):
    """Every `step`-th sample along `axis` (the time axis)."""
    a = np.asarray(a)
    if step == 1:
        return a
    return np.take(a, np.arange(0, a.shape[axis], step), axis=axis)


def _stacked(x, ndim: int, name: str):
    """`x` as floats and whether it has a leading seed axis (one more dimension than `ndim`)."""
    x = np.asarray(x, dtype=float)
    if x.ndim == ndim:
        return x, False
    if x.ndim == ndim + 1:
        return x, True
    raise ValueError(
        f"`{name}` must have {ndim} dimensions, or {ndim + 1} with a leading seed axis; "
        f"got shape {x.shape}"
    )


def _quantiles(y):
    """(low, median, high) over the leading seed axis of `y` (S, N), NaNs ignored."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns: NaN, no warning
        lo, med, hi = np.nanpercentile(y, (BAND[0], 50.0, BAND[1]), axis=0)
    return lo, med, hi


def _median(y):
    """The median over a leading seed axis, or `y` itself when it has none."""
    y = np.asarray(y, dtype=float)
    return _quantiles(y)[1] if y.ndim >= 2 else y


def _series(
    ax, t, y, color, *, label=None, gid="estimate", ls="-", lw=_ESTIMATE_LW, zorder=2.0, floor=None
):
    """A line of `y` (N,) against `t`; for `y` (S, N), the median over seeds and the shaded
    10-90 % band (a `PolyCollection` under the line). `floor` clips for log axes."""
    y = np.asarray(y, dtype=float)
    if y.ndim == 2:
        lo, y, hi = _quantiles(y)
        if floor is not None:
            lo, hi = np.maximum(lo, floor), np.maximum(hi, floor)
        ax.fill_between(
            t, lo, hi, color=color, alpha=0.25, lw=0, zorder=zorder - 0.5, gid=f"{gid}-band"
        )
    if floor is not None:
        y = np.maximum(y, floor)
    (line,) = ax.plot(
        t,
        y,
        color=color,
        ls=ls,
        lw=lw,
        zorder=zorder,
        label=label,
        gid=gid,
        rasterized=len(t) > RASTER_POINTS,
    )
    return line


def _truth(ax, t, y, label="truth"):
    """The truth: black, dashed, thin, on top of the estimates."""
    (line,) = ax.plot(t, y, label=label, rasterized=len(t) > RASTER_POINTS, **_TRUTH)
    return line


def _truth_level(ax, value, label="truth"):
    """A constant truth (a horizontal line), styled as `_truth`."""
    return ax.axhline(value, label=label, **_TRUTH)


def _band_handle(seeds: int, color="0.5"):
    """A legend entry for the band over seeds."""
    from matplotlib.patches import Patch

    return Patch(
        color=color, alpha=0.25, lw=0, label=f"{BAND[0]:g}-{BAND[1]:g} % over {seeds} seeds"
    )


def _proxy(**kwargs):
    """A legend entry without data."""
    from matplotlib.lines import Line2D

    return Line2D([], [], **kwargs)


def _zoom_on_second_half(ax, t, err, seed_axis=True):
    """Show the steady state (the second half) and the transient on one error axis: linear
    within +-4 times the second half's largest value (shaded), logarithmic beyond it (a
    symlog scale), so that the transient is shown, not clipped, and does not dwarf the
    steady state. `err` (N,), (S, N) with `seed_axis` (then of the 10-90 % band), or (N, d)
    without (all d components)."""
    err = np.asarray(err, dtype=float)
    if err.ndim == 2 and seed_axis:
        lo, _, hi = _quantiles(err)
        err = np.stack([lo, hi], axis=-1)
    if len(t) == 0:
        return
    part = np.abs(err[t >= t[-1] / 2])
    if not np.isfinite(part).any():
        return
    lim = 4 * max(float(np.nanmax(part)), 1e-4)
    whole = float(np.nanmax(np.abs(err))) if np.isfinite(err).any() else lim
    if whole > lim:  # a transient beyond the steady state's range: logarithmic there
        ax.set_yscale("symlog", linthresh=lim, linscale=2.0)
        ax.axhspan(-lim, lim, color="0.93", zorder=0, lw=0)
    else:
        ax.set_ylim(-lim, lim)


# ---------------------------------------------------------------------------------------------
# Chitrakaran et al.: velocity of a moving object seen by a fixed camera


def plot_velocity(
    ts, velocity, estimate, *, title=None, path=None, max_points=2000, formats=("png",)
):
    """Like Fig. 2 of Chitrakaran et al.: per DOF, true and estimated velocity (left), error
    $v - \\hat v$ (right); with `velocity=None` (no truth), the estimate alone (single
    column).

    **Arguments:** `ts` (N,) [s]; `velocity` (N, 6) or `None`, the truth
    $[v_e, \\omega_e]$ [m/s, rad/s]; `estimate` (N, 6), or (S, N, 6) over S seeds (then the
    median and the 10-90 % band over seeds; the truth may then be (N, 6) or (S, N, 6));
    `max_points` samples per line at most (decimated); `title`, `path`, `formats` as in the
    module's docstring. **Returns:** the `Figure`."""
    formats = figure_formats(formats)
    ts = np.asarray(ts, dtype=float)
    est, seeds = _stacked(estimate, 2, "estimate")
    step = _stride(len(ts), max_points)
    t, e = ts[::step], _decimate(est, step, -2)
    truth = None if velocity is None else _decimate(np.asarray(velocity, float), step, -2)
    plt = _pyplot(path)
    with _style():
        cols = 1 if truth is None else 2
        width = SINGLE_COLUMN if truth is None else DOUBLE_COLUMN
        fig, axes = _subplots(plt, 6, cols, width, 6.6, sharex=True)
        handles = []
        for i, (name, unit) in enumerate(DOF_LABELS):
            ax = axes[i, 0]
            est_line = _series(ax, t, e[..., i], "C0", label="estimate $\\hat v$")
            ax.set_ylabel(f"{name} [{unit}]")
            if truth is not None:
                true_line = _truth(ax, t, _median(truth[..., i]), label="truth $v$")
                err_line = _series(
                    axes[i, 1],
                    t,
                    truth[..., i] - e[..., i],
                    "C3",
                    gid="error",
                    lw=0.8,
                    label="error $v - \\hat v$",
                )
                axes[i, 1].axhline(0.0, **_ZERO)
                axes[i, 1].set_ylabel(f"error {name} [{unit}]")
            if i == 0:
                handles = [est_line] + ([true_line, err_line] if truth is not None else [])
        axes[0, 0].set_title("velocity")
        axes[-1, 0].set_xlabel("time [s]")
        if truth is not None:
            axes[0, 1].set_title("estimation error $v - \\hat v$")
            axes[-1, 1].set_xlabel("time [s]")
        if seeds:
            handles.append(_band_handle(est.shape[0]))
        _legend(fig, handles)
        return _finish(fig, title, path, formats)


# ---------------------------------------------------------------------------------------------
# Jang's thesis: structure of a moving point seen by a moving camera


def plot_moving_point(
    ts,
    position,
    estimate,
    *,
    weak=None,
    title=None,
    path=None,
    max_points=2000,
    formats=("png",),
):
    """Like Figs. 5-7 and 5-8 of Jang's thesis: actual (black, dashed, on top) and estimated
    (solid) position of the point in the camera frame [m] (left), and the estimation error
    $\\hat X - X$ [mm] (right: linear over the steady state of the second half, shaded,
    logarithmic beyond it, so that the transient shows); with
    `position=None` (no truth), the estimate alone (single column).

    **Arguments:** `ts` (N,) [s]; `position` (N, 3) or `None`, the truth [m]; `estimate`
    (N, 3), or (S, N, 3) over S seeds (then the median and the 10-90 % band over seeds; the
    truth may then be (N, 3) or (S, N, 3)); `weak` (N,) bool or `None`: where the depth is
    weakly observable (shaded in every panel, e.g. `jang.weak_parallax`); `max_points`,
    `title`, `path`, `formats` as in the module's docstring. **Returns:** the `Figure`."""
    formats = figure_formats(formats)
    ts = np.asarray(ts, dtype=float)
    est, seeds = _stacked(estimate, 2, "estimate")
    step = _stride(len(ts), max_points)
    t, e = ts[::step], _decimate(est, step, -2)
    truth = None if position is None else _decimate(np.asarray(position, float), step, -2)
    plt = _pyplot(path)
    with _style():
        cols = 1 if truth is None else 2
        width = SINGLE_COLUMN if truth is None else DOUBLE_COLUMN
        fig, axes = _subplots(plt, 3, cols, width, 4.4, sharex=True)
        handles = []
        for i, name in enumerate("XYZ"):
            ax = axes[i, 0]
            est_line = _series(ax, t, e[..., i], "C0", label="estimated")
            ax.set_ylabel(f"{name} [m]")
            if truth is not None:
                true_line = _truth(ax, t, _median(truth[..., i]), label="actual")
                err = 1e3 * (e[..., i] - truth[..., i])
                err_line = _series(axes[i, 1], t, err, "C3", gid="error", lw=0.8, label="error")
                axes[i, 1].axhline(0.0, **_ZERO)
                axes[i, 1].set_ylabel(f"error {name} [mm]")
                _zoom_on_second_half(axes[i, 1], t, err)
            if i == 0:
                handles = [est_line] + ([true_line, err_line] if truth is not None else [])
        axes[0, 0].set_title("position of the point (camera frame)")
        axes[-1, 0].set_xlabel("time [s]")
        if truth is not None:
            axes[0, 1].set_title("estimation error (linear within the grey band)")
            axes[-1, 1].set_xlabel("time [s]")
        if seeds:
            handles.append(_band_handle(est.shape[0]))
        if weak is not None and _shade_spans(axes.ravel(), ts, np.asarray(weak, bool)):
            handles.append(_weak_handle())
        _legend(fig, handles)
        return _finish(fig, title, path, formats)


_WEAK = {"color": "C1", "alpha": 0.15, "lw": 0}


def _weak_handle():
    from matplotlib.patches import Patch

    return Patch(label="depth weakly observable", **_WEAK)


def _shade_spans(axes, ts, mask) -> bool:
    """Shade the stretches of `ts` where `mask` holds, in every axes; whether any."""
    if mask.shape != ts.shape:
        raise ValueError(f"`weak` must have the shape of `ts`, {ts.shape}; got {mask.shape}.")
    edges = np.flatnonzero(np.diff(np.r_[0, mask.astype(np.int8), 0]))
    for start, stop in zip(edges[::2], edges[1::2]):
        for ax in axes:
            ax.axvspan(ts[start], ts[stop - 1], zorder=0.5, **_WEAK)
    return edges.size > 0


def plot_camera_velocity(ts, v_c, *, title=None, path=None, formats=("png",), max_points=2000):
    """Like Figs. 5-5/5-6, 5-9/5-10, ... of Jang's thesis ("Camera angular velocity",
    "Camera linear velocity"): the camera's angular velocity [rad/s] (top) and linear
    velocity [m/s] (bottom), x, y and z, against time.

    **Arguments:** `ts` (N,) [s]; `v_c` (N, 6) $= [v_c, \\omega_c]$ in the camera frame,
    linear first (as `camera_velocity` of the structure data format); `max_points`, `title`,
    `path`, `formats` as in the module's docstring. **Returns:** the `Figure`
    (single column)."""
    formats = figure_formats(formats)
    ts = np.asarray(ts, dtype=float)
    v = np.asarray(v_c, dtype=float)
    if v.ndim != 2 or v.shape[1] != 6 or v.shape[0] != ts.shape[0]:
        raise ValueError(f"`v_c` must be (N, 6) with N = len(ts) = {len(ts)}; got {v.shape}")
    step = _stride(len(ts), max_points)
    t, v = ts[::step], v[::step]
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 2, 1, SINGLE_COLUMN, 3.6, sharex=True)
        top, bottom = axes[0, 0], axes[1, 0]
        for i, name in enumerate("xyz"):
            _series(top, t, v[:, 3 + i], f"C{i}", label=f"$\\omega_{{c{name}}}$", gid="velocity")
            _series(bottom, t, v[:, i], f"C{i}", label=f"$v_{{c{name}}}$", gid="velocity")
        top.set_ylabel("angular velocity [rad/s]")
        bottom.set_ylabel("linear velocity [m/s]")
        bottom.set_xlabel("time [s]")
        for ax in (top, bottom):
            ax.axhline(0.0, **_ZERO)
            # above the panel, outside it: the thesis' panel title is its y label here
            ax.legend(
                loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3, borderaxespad=0.2, fontsize=8
            )
        return _finish(fig, title, path, formats)


def plot_testbed(run, *, title=None, path=None, max_points=2000, formats=("png",)):
    """Like Figs. 5-5 to 5-8 of Jang's thesis for one set on the testbed twin: the camera's
    angular and linear velocities (from the encoders, solid, in colour; the exact ones black,
    dashed, on top), the marker's actual (black, dashed, on top) and estimated (solid)
    position in the camera frame, and the estimation error [mm] (from tracked pixels, solid;
    from exact pixels, dotted).

    **Arguments:** `run` a `visjax.papers.jang.TestbedRun` (`frame_ts`, `velocity_true`,
    `velocity_measured`, `ts`, `position`, `estimate`, `estimate_ideal`); `max_points`,
    `title`, `path`, `formats` as in the module's docstring. **Returns:** the `Figure`
    (double column)."""
    formats = figure_formats(formats)
    ft = np.asarray(run.frame_ts, dtype=float)
    ts = np.asarray(run.ts, dtype=float)
    est = np.asarray(run.estimate, dtype=float)
    m = est.shape[0]
    fstep = _stride(len(ft), max_points)
    step = _stride(m, max_points)
    ft = ft[::fstep]
    v_meas = np.asarray(run.velocity_measured, float)[::fstep]
    v_true = np.asarray(run.velocity_true, float)[::fstep]
    t = ts[:m][::step]
    est = est[::step]
    pos = np.asarray(run.position, float)[:m][::step]
    ideal = np.asarray(run.estimate_ideal, float)[:m][::step]
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 2, 2, DOUBLE_COLUMN, 4.6, sharex=True)
        for i in range(3):
            color = f"C{i}"
            _series(axes[0, 0], ft, v_meas[:, 3 + i], color, ls="-.", gid="measured")
            _truth(axes[0, 0], ft, v_true[:, 3 + i])
            _series(axes[0, 1], ft, v_meas[:, i], color, ls="-.", gid="measured")
            _truth(axes[0, 1], ft, v_true[:, i])
            _series(axes[1, 0], t, est[:, i], color)
            _truth(axes[1, 0], t, pos[:, i])
            _series(axes[1, 1], t, 1e3 * (est[:, i] - pos[:, i]), color, gid="error")
            _series(
                axes[1, 1], t, 1e3 * (ideal[:, i] - pos[:, i]), color, gid="error", ls=":", lw=0.8
            )
        axes[1, 1].axhline(0.0, **_ZERO)
        axes[0, 0].set_title("camera angular velocity (Fig. 5-5)")
        axes[0, 0].set_ylabel("$\\omega_c$ [rad/s]")
        axes[0, 1].set_title("camera linear velocity (Fig. 5-6)")
        axes[0, 1].set_ylabel("$v_c$ [m/s]")
        axes[1, 0].set_title("position of the marker (Fig. 5-7)")
        axes[1, 0].set_ylabel("position [m]")
        axes[1, 1].set_title("estimation error (Fig. 5-8)")
        axes[1, 1].set_ylabel("error [mm]")
        _zoom_on_second_half(axes[1, 1], t, 1e3 * (est - pos), seed_axis=False)
        for ax in axes[1]:
            ax.set_xlabel("time [s]")
        handles = [_proxy(color=f"C{i}", lw=_ESTIMATE_LW, label="xyz"[i]) for i in range(3)]
        handles += [  # one meaning per line style
            _proxy(color="0.3", lw=_ESTIMATE_LW, ls="-.", label="measured by the encoders"),
            _proxy(color="0.3", lw=_ESTIMATE_LW, label="estimate from tracked pixels"),
            _proxy(color="k", ls="--", lw=_TRUTH["lw"], label="truth (exact velocity, position)"),
            _proxy(color="0.3", ls=":", lw=0.8, label="error from exact pixels"),
        ]
        _legend(fig, handles, ncol=3)
        return _finish(fig, title, path, formats)


# ---------------------------------------------------------------------------------------------
# Nath et al.: Euclidean positions from an uncalibrated moving camera


def plot_error_budget(table, *, title=None, path=None, formats=("png",)):
    """The testbed twin's error budget (`visjax.papers.jang.testbed_error_budget`): per set,
    one row of bars per configuration (no source, each source alone, all together, the
    other readings), the RMS of x, y, z in colour, and the thesis' measured RMS of each
    axis as a dashed line of the same colour. A run that did not succeed has no bar: its
    row says its result instead.

    **Arguments:** `table` the budget's `pandas.DataFrame` (`set`, `sources`, `reading`,
    `axis`, `rms_m`, `thesis_rms_m`, `result`); `title`, `path`, `formats` as in the
    module's docstring. **Returns:** the `Figure` (double column)."""
    formats = figure_formats(formats)
    sets = list(dict.fromkeys(table["set"]))
    configs = list(dict.fromkeys(zip(table["sources"], table["reading"], strict=True)))
    labels = [s if r == "stated" else f"{s} ({r})" for s, r in configs]
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 1, len(sets), DOUBLE_COLUMN, 1.0 + 0.26 * len(configs),
                              sharey=True)  # fmt: skip
        y = np.arange(len(configs))
        for ax, set_name in zip(axes[0], sets, strict=True):
            part = table[table["set"] == set_name]
            for i, axis in enumerate("xyz"):
                rows = part[part["axis"] == axis].set_index(["sources", "reading"])
                rms = np.array([float(rows.loc[c, "rms_m"]) if c in rows.index else np.nan
                                for c in configs])  # fmt: skip
                ax.barh(y + (i - 1) * 0.27, 1e3 * rms, height=0.27, color=f"C{i}", gid="error")
                thesis = float(rows["thesis_rms_m"].iloc[0])
                ax.axvline(1e3 * thesis, color=f"C{i}", ls="--", lw=0.8, gid="measured")
            failed = part.drop_duplicates(["sources", "reading"]).set_index(["sources", "reading"])
            for k, c in enumerate(configs):
                if c in failed.index and failed.loc[c, "result"] != "successful":
                    ax.text(0.0, k, f" {failed.loc[c, 'result']}", va="center")
            ax.set_title(f"set {set_name}")
            ax.set_xlabel("RMS error, second half [mm]")
        axes[0, 0].set_yticks(y, labels)
        axes[0, 0].invert_yaxis()
        handles = [_proxy(color=f"C{i}", lw=4, label="xyz"[i]) for i in range(3)]
        handles.append(_proxy(color="0.3", ls="--", lw=0.8, label="the thesis' measured RMS"))
        _legend(fig, handles, ncol=4)
        return _finish(fig, title, path, formats)


def _feature_errors(est, truth):
    """Position error norm per feature [m], (..., N, n), for `est` (..., N, n, 3) and the
    truth (n, 3) or (S, n, 3)."""
    truth = np.asarray(truth, dtype=float)
    if truth.ndim == 3:
        truth = truth[:, None]
    return np.linalg.norm(est - truth, axis=-1)


def plot_static_points(run, *, title=None, path=None, max_points=2000, formats=("png",)):
    """Nath et al. on their simulation: each unknown feature's estimated world coordinates
    (solid, one colour per feature) against the truth (black, dashed, on top), the position
    error per feature [m] and the largest prediction error of both laws [px] (log axes), and
    the PE measure of eq. (49) [-].

    **Arguments:** `run` a `visjax.papers.nath.StaticPointsRun` (`ts` (N,), `omega_s`
    (N, n, 3), `omega_true` (n, 3), `p_tilde_c` (N, m), `p_tilde_s` (N, n), `pe` (N, n)), or
    one whose arrays have a leading seed axis (S, ...) (`omega_true` (n, 3) or (S, n, 3)):
    then the median and the 10-90 % band over seeds. `max_points`, `title`, `path`, `formats`
    as in the module's docstring. **Returns:** the `Figure` (double column)."""
    formats = figure_formats(formats)
    ts = np.asarray(run.ts, dtype=float)
    if ts.ndim == 2:  # stacked runs: the same time grid for every seed
        ts = ts[0]
    est, seeds = _stacked(run.omega_s, 3, "omega_s")
    true = np.asarray(run.omega_true, dtype=float)
    step = _stride(len(ts), max_points)
    t = ts[::step]
    err = _decimate(_feature_errors(est, true), step, -2)
    est = _decimate(est, step, -3)
    p_c = _decimate(np.nanmax(np.asarray(run.p_tilde_c, float), axis=-1), step, -1)
    p_s = _decimate(np.nanmax(np.asarray(run.p_tilde_s, float), axis=-1), step, -1)
    pe = _decimate(np.asarray(run.pe, float), step, -2)
    true_shown = _median(true) if true.ndim == 3 else true
    n = est.shape[-2]
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 2, 3, DOUBLE_COLUMN, 4.4, sharex=True)
        for c, name in enumerate("xyz"):
            ax = axes[0, c]
            for i in range(n):
                _series(ax, t, est[..., i, c], f"C{i % 8}", label=f"feature {i + 1}")
                _truth_level(ax, true_shown[i, c])
            ax.set_ylabel(f"world {name} [m]")
        for i in range(n):
            _series(axes[1, 0], t, err[..., i], f"C{i % 8}", gid="error", floor=1e-9)
            _series(axes[1, 2], t, pe[..., i], f"C{i % 8}", gid="pe")
        axes[1, 0].set_yscale("log")
        axes[1, 0].set_ylabel("position error [m]")
        law_c = _series(
            axes[1, 1], t, p_c, "0.15", gid="error", floor=1e-9, label="camera law (known)"
        )
        law_s = _series(
            axes[1, 1], t, p_s, "0.6", gid="error", floor=1e-9, label="structure law (unknown)"
        )
        axes[1, 1].set_yscale("log")
        axes[1, 1].set_ylabel("max. prediction error [px]")
        axes[1, 2].set_ylabel("PE measure, eq. (49) [-]")
        for ax in axes[1]:
            ax.set_xlabel("time [s]")
        handles = [
            _proxy(color=f"C{i % 8}", lw=_ESTIMATE_LW, label=f"feature {i + 1}") for i in range(n)
        ]
        handles += [
            _proxy(color="k", ls="--", lw=_TRUTH["lw"], label="truth"),
            law_c,
            law_s,
        ]
        if seeds:
            handles.append(_band_handle(est.shape[0]))
        _legend(fig, handles, ncol=4)
        return _finish(fig, title, path, formats)


def plot_transient(ts, measured: dict, ideal, *, title=None, path=None, formats=("png",)):
    """Like the convergence claim of Spica and Robuffo Giordano (active structure from
    motion): the estimation error $z(t)/z(0)$ of each run (`measured`: label -> (N,), one
    colour each) against the assigned second-order response (`ideal` (N,), black, dashed)
    (left), and their difference (right).

    **Arguments:** `ts` (N,) [s]; `measured` label -> (N,); `ideal` (N,); `title`, `path`,
    `formats` as in the module's docstring. **Returns:** the `Figure` (double column)."""
    formats = figure_formats(formats)
    ts = np.asarray(ts, dtype=float)
    ideal = np.asarray(ideal, dtype=float)
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 1, 2, DOUBLE_COLUMN, 2.6)
        left, right = axes[0]
        handles = []
        for i, (label, z) in enumerate(measured.items()):
            z = np.asarray(z, dtype=float)
            (h,) = left.plot(ts, z, color=f"C{i % 10}", lw=_ESTIMATE_LW, label=label)
            right.plot(ts, z - ideal, color=f"C{i % 10}", lw=_ESTIMATE_LW)
            handles.append(h)
        (h,) = left.plot(ts, ideal, label="assigned response", **_TRUTH)
        handles.append(h)
        right.axhline(0.0, **_ZERO)
        left.set_ylabel("depth error $z(t)/z(0)$ [1]")
        right.set_ylabel("$z/z(0)$ - assigned [1]")
        for ax in (left, right):
            ax.set_xlabel("time [s]")
        _legend(fig, handles)
        return _finish(fig, title, path, formats)


def plot_feature_estimates(
    ts, estimate, truth=None, *, title=None, path=None, max_points=2000, formats=("png",)
):
    """Nath et al. on a user's data: each unknown feature's estimated world coordinates
    (solid, one colour per feature; the truth black, dashed, on top, when known) and, with the
    truth, the position error per feature [m] on a log axis.

    **Arguments:** `ts` (N,) [s]; `estimate` (N, n, 3) [m], or (S, N, n, 3) over S seeds
    (then the median and the 10-90 % band over seeds); `truth` (n, 3), (S, n, 3) or `None`;
    `max_points`, `title`, `path`, `formats` as in the module's docstring. **Returns:** the
    `Figure` (double column)."""
    formats = figure_formats(formats)
    ts = np.asarray(ts, dtype=float)
    est, seeds = _stacked(estimate, 3, "estimate")
    step = _stride(len(ts), max_points)
    t = ts[::step]
    err = None
    if truth is not None:
        truth = np.asarray(truth, dtype=float)
        err = _decimate(_feature_errors(est, truth), step, -2)
        true_shown = _median(truth) if truth.ndim == 3 else truth
    est = _decimate(est, step, -3)
    n = est.shape[-2]
    plt = _pyplot(path)
    with _style():
        if truth is None:
            fig, axes = _subplots(plt, 1, 3, DOUBLE_COLUMN, 2.4)
            coord_axes = list(axes[0])
        else:
            fig, axes = _subplots(plt, 2, 2, DOUBLE_COLUMN, 4.2)
            coord_axes = [axes[0, 0], axes[0, 1], axes[1, 0]]
        for c, (ax, name) in enumerate(zip(coord_axes, "xyz")):
            for i in range(n):
                _series(ax, t, est[..., i, c], f"C{i % 10}", label=f"unknown {i + 1}")
                if truth is not None:
                    _truth_level(ax, true_shown[i, c])
            ax.set_ylabel(f"world {name} [m]")
        if err is not None:
            ax = axes[1, 1]
            for i in range(n):
                _series(ax, t, err[..., i], f"C{i % 10}", gid="error", floor=1e-9)
            ax.set_yscale("log")
            ax.set_ylabel("position error [m]")
        for ax in axes.ravel():
            ax.set_xlabel("time [s]")
        handles = [
            _proxy(color=f"C{i % 10}", lw=_ESTIMATE_LW, label=f"unknown {i + 1}") for i in range(n)
        ]
        if truth is not None:
            handles.append(_proxy(color="k", ls="--", lw=_TRUTH["lw"], label="truth"))
        if seeds:
            handles.append(_band_handle(est.shape[0]))
        _legend(fig, handles, ncol=min(len(handles), 6))
        return _finish(fig, title, path, formats)


# ---------------------------------------------------------------------------------------------
# Chitrakaran et al., section 3: geometry


def plot_geometry(scenes, ours, errors, *, title=None, path=None, formats=("png",)):
    """Chitrakaran et al., section 3: scene 0's pixels with the recovered homography's
    transfer (left), and every scene's errors against ground truth, visjax's and OpenCV's, on
    separate log axes: the rotation $\\bar R$ [deg] (middle) and the largest relative error of
    the depth ratios $\\alpha_i$ [-] (right).

    **Arguments:** `scenes` (`visjax.sim.random_planar_scenes`: `p_ref`, `p_cur`, `A`);
    `ours` with `H` (S, 3, 3); `errors` `{"visjax": ..., "opencv": ...}`, each with
    `R_bar_deg` and `alpha_rel` per scene (`papers.chitrakaran.reconstruction_errors`);
    `title`, `path`, `formats` as in the module's docstring. **Returns:** the `Figure`
    (double column)."""
    formats = figure_formats(formats)
    p_ref = np.asarray(scenes.p_ref[0], float)
    p_cur = np.asarray(scenes.p_cur[0], float)
    A = np.asarray(scenes.A[0], float)
    H = np.asarray(ours["H"][0], float)
    q = np.c_[p_ref, np.ones(len(p_ref))] @ (A @ H @ np.linalg.inv(A)).T
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 1, 3, DOUBLE_COLUMN, 2.6)
        ax0, ax1, ax2 = axes[0]
        ref = ax0.plot(*p_ref.T, "o", color="C2", mfc="none", label="reference $p_i^*$")[0]
        cur = ax0.plot(*p_cur.T, "s", color="C3", mfc="none", label="current $p_i$")[0]
        tra = ax0.plot(
            *(q[:, :2] / q[:, 2:]).T, "k+", ms=7, zorder=3, label="$A H A^{-1} p_i^*$ (visjax)"
        )[0]
        pts = np.concatenate([p_ref, p_cur])
        ax0.set_xlim(0, max(640.0, float(np.nanmax(pts[:, 0])) + 10))
        ax0.set_ylim(max(480.0, float(np.nanmax(pts[:, 1])) + 10), 0)
        ax0.set_aspect("equal")
        ax0.set_title("scene 0: pixels")
        ax0.set_xlabel("u [px]")
        ax0.set_ylabel("v [px]")
        floor = 1e-17
        handles = [ref, cur, tra]
        for who, name, marker, color in (
            ("visjax", "visjax", "o", "C0"),
            ("opencv", "OpenCV", "x", "C1"),
        ):
            if who not in errors:
                continue
            e = errors[who]
            style = {"ls": "none", "marker": marker, "color": color, "label": name}
            if marker == "o":
                style["mfc"] = "none"
            r = np.maximum(np.asarray(e["R_bar_deg"], float), floor)
            a = np.maximum(np.asarray(e["alpha_rel"], float), floor)
            handles.append(ax1.plot(np.arange(len(r)), r, **style)[0])
            ax2.plot(np.arange(len(a)), a, **style)
        for ax, ylabel, what in (
            (ax1, "rotation error of $\\bar R$ [deg]", "rotation"),
            (ax2, "max. rel. error of $\\alpha_i$ [-]", "depth ratios"),
        ):
            ax.set_yscale("log")
            ax.set_xlabel("scene [-]")
            ax.set_ylabel(ylabel)
            ax.set_title(f"{what} vs ground truth")
            ax.grid(True, which="major", axis="y", alpha=0.3)
        _legend(fig, handles, ncol=len(handles))
        return _finish(fig, title, path, formats)


# ---------------------------------------------------------------------------------------------
# studies: compare, sweep, tune


def plot_comparison(
    records,
    accuracy,
    *,
    label,
    title=None,
    path=None,
    formats=("png",),
    ts=None,
    errors=None,
    error_label=None,
):
    """`visjax compare`: per method (one colour each), the accuracy of every seed (left: a dot
    per seed, a black bar at the median, the 10-90 % band over seeds shaded; the number of
    failed runs under the method's name) and the latency per new sample (middle), both on log
    axes; with `errors`, the error against time per method (right: the median over seeds and
    the shaded 10-90 % band, log axis).

    **Arguments:** `records` (`visjax.studies.compare`); `accuracy(record) -> float` picks
    the headline number, `label` its axis label (a unit in brackets, or in trailing
    parentheses, shown in brackets); `ts` (N,) [s] and `errors` {method: (S, N, d) or
    (S, N)} (a single seed: (N, d) or (N,)): the estimation error of each seed, its norm over
    the last axis when it has d components; `error_label` its axis label, with its unit, e.g.
    `"position error [m]"` (required with `errors`); `title`, `path`, `formats` as in the
    module's docstring. **Returns:** the `Figure` (double column)."""
    formats = figure_formats(formats)
    series = {}
    if errors is not None:
        if ts is None or error_label is None:
            raise ValueError("`errors` needs `ts` and `error_label` (with its unit in brackets)")
        t = np.asarray(ts, dtype=float)
        for method, err in errors.items():
            err = np.asarray(err, dtype=float)
            if err.ndim == 3 or (err.ndim == 2 and err.shape[-1] != len(t)):
                err = np.linalg.norm(err, axis=-1)  # (S, N, d) -> (S, N); (N, d) -> (N,)
            if err.shape[-1] != len(t):
                raise ValueError(
                    f"errors[{method!r}] must be (S, N, d), (S, N), (N, d) or (N,) with N = "
                    f"len(ts) = {len(t)}; got {np.shape(errors[method])}"
                )
            series[method] = err
    methods = list(dict.fromkeys(r["method"] for r in records))
    for method in series:
        if method not in methods:
            methods.append(method)
    plt = _pyplot(path)
    with _style():
        panels = 3 if series else 2
        fig, axes = _subplots(plt, 1, panels, DOUBLE_COLUMN, 2.6)
        axes = axes[0]
        names = []
        for i, method in enumerate(methods):
            color = f"C{i % 10}"
            rows = [r for r in records if r["method"] == method]
            good = [accuracy(r) for r in rows if r["result"] == "successful"]
            good = np.asarray([g for g in good if g is not None and np.isfinite(g) and g > 0])
            if good.size:
                axes[0].plot([i] * good.size, good, "o", color=color, alpha=0.7, gid="accuracy")
                if good.size > 1:
                    lo, hi = np.percentile(good, BAND)
                    axes[0].fill_between(
                        [i - 0.3, i + 0.3],
                        lo,
                        hi,
                        color=color,
                        alpha=0.2,
                        lw=0,
                        gid="accuracy-band",
                    )
                axes[0].hlines(np.median(good), i - 0.3, i + 0.3, color="k", lw=1.0)
            failed = sum(r["result"] != "successful" for r in rows)
            names.append(f"{method}\n({failed} failed)" if failed else method)
            lat = [r["latency_s_per_sample"] for r in rows]
            if lat:
                axes[1].plot([i] * len(lat), lat, "o", color=color, alpha=0.7, gid="latency")
                axes[1].hlines(np.median(lat), i - 0.3, i + 0.3, color="k", lw=1.0)
        for ax, ylabel in zip(axes[:2], (_unit_label(label), "latency per new sample [s]")):
            ax.set_yscale("log")
            ax.set_xticks(range(len(methods)), names, rotation=30, ha="right")
            ax.set_xlim(-0.6, len(methods) - 0.4)
            ax.set_ylabel(ylabel)
            ax.grid(True, axis="y", which="major", alpha=0.3)
        if series:
            ax = axes[2]
            handles = []
            for i, method in enumerate(methods):
                if method in series:
                    handles.append(
                        _series(ax, t, series[method], f"C{i % 10}", label=method, floor=1e-12)
                    )
            ax.set_yscale("log")
            ax.set_xlabel("time [s]")
            ax.set_ylabel(_unit_label(error_label))
            ax.grid(True, axis="y", which="major", alpha=0.3)
            seeds = max((s.shape[0] for s in series.values() if s.ndim == 2), default=0)
            if seeds:
                handles.append(_band_handle(seeds))
            _legend(fig, handles, ncol=min(len(handles), 5))
        return _finish(fig, title, path, formats)


def plot_noise_study(stats, *, label, title=None, path=None, formats=("png",)):
    """`visjax compare --noise 0,0.1,...`, the figure of an estimation paper: per method
    (one colour each) the median of the headline metric over the successful seeds against
    the noise level, its 95% bootstrap interval as error bars (left, log axis), and its
    failure rate (right).

    **Arguments:** `stats` (`studies.Comparison.statistics` of a comparison over noise
    levels: `noise_levels`, `by_noise`); `label` the metric's axis label with its unit;
    `title`, `path`, `formats` as in the module's docstring. **Returns:** the `Figure`."""
    formats = figure_formats(formats)
    levels = np.asarray(stats["noise_levels"], float)
    methods = list(dict.fromkeys(m for s in stats["by_noise"] for m in s["methods"]))
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 1, 2, DOUBLE_COLUMN, 2.6)
        axes = axes[0]
        for i, method in enumerate(methods):
            rows = [s["methods"].get(method, {}) for s in stats["by_noise"]]

            def get(k, rows=rows):
                return np.array([np.nan if r.get(k) is None else r[k] for r in rows], float)

            med, lo, hi = get("median"), get("low"), get("high")
            err = np.vstack(
                [med - np.where(np.isfinite(lo), lo, med), np.where(np.isfinite(hi), hi, med) - med]
            )
            color = f"C{i % 10}"
            axes[0].errorbar(
                levels, med, yerr=err, fmt="o-", color=color, capsize=2, label=method, gid="median"
            )
            axes[1].plot(levels, 100 * get("failure_rate"), "o-", color=color, gid="failures")
        axes[0].set_yscale("log")
        axes[0].set_ylabel(_unit_label(label))
        axes[1].set_ylabel("failed runs [%]")
        axes[1].set_ylim(-3, 103)
        for ax in axes:
            ax.set_xlabel("pixel noise sigma [px]")
            ax.grid(True, which="major", alpha=0.3)
        _legend(fig, axes[0].get_legend_handles_labels()[0], ncol=min(len(methods), 5))
        return _finish(fig, title, path, formats)


def plot_sweep(
    summary,
    metric,
    params,
    *,
    best=None,
    paper=None,
    label=None,
    title=None,
    path=None,
    formats=("png",),
    units=None,
    paper_label="paper",
):
    """`visjax sweep` and `visjax tune`: the metric against each parameter (log-log), one
    panel per parameter. Grey dots: every point's mean over seeds; the line: the best mean
    at each value of the parameter (over the other parameters), with the spread over seeds
    (min to max) as a band; points with a failed run as red crosses at the top; the best
    point (star) and the paper's gains (square; `paper_label` names them, e.g.
    `"defaults"` where the defaults are not a paper's) marked with their held-out metric.

    `summary` is `studies.summarise(table, metric)`; `best` and `paper` are dicts with
    `params` and `metric`; `label` the metric's axis label, with its unit (in brackets, or in
    trailing parentheses, shown in brackets); `title`, `path`, `formats` as in the module's
    docstring; `units` name -> the parameter's unit (default: dimensionless, `-`).
    **Returns:** the `Figure` (single column for one parameter, else double)."""
    formats = figure_formats(formats)
    units = dict(units or {})
    plt = _pyplot(path)
    mean = summary[f"{metric}_mean"].to_numpy(float)
    lo = summary[f"{metric}_min"].to_numpy(float)
    hi = summary[f"{metric}_max"].to_numpy(float)
    failed = summary["n_failed"].to_numpy() > 0
    with _style():
        width = SINGLE_COLUMN if len(params) == 1 else DOUBLE_COLUMN
        fig, axes = _subplots(plt, 1, len(params), width, 2.9)
        seen = {}
        for ax, p in zip(axes[0], params):
            x = summary[p].to_numpy(float)
            ok = ~failed & np.isfinite(mean) & (mean > 0)
            ax.plot(x[ok], mean[ok], ".", color="0.6", ms=3, label="mean over seeds")
            xs = np.unique(x[ok])
            if xs.size:
                pick = [np.flatnonzero(ok & (x == v))[np.argmin(mean[ok & (x == v)])] for v in xs]
                ax.plot(xs, mean[pick], "-", color="C0", label="best over the others")
                ax.fill_between(
                    xs,
                    lo[pick],
                    hi[pick],
                    color="C0",
                    alpha=0.2,
                    lw=0,
                    label="spread over seeds (min-max)",
                )
            if failed.any():
                ax.plot(
                    x[failed],
                    np.full(failed.sum(), 1.0),
                    "x",
                    color="C3",
                    transform=ax.get_xaxis_transform(),
                    clip_on=False,
                    label="a run failed",
                )
            for mark, style, name in (
                (best, "*", "best (held-out)"),
                (paper, "s", f"{paper_label} (held-out)"),
            ):
                if (
                    mark is not None
                    and np.ndim(mark["params"].get(p)) == 0
                    and p in mark["params"]
                    and np.isfinite(mark["metric"])
                ):
                    ax.plot(
                        [mark["params"][p]],
                        [mark["metric"]],
                        style,
                        color="C1" if style == "*" else "k",
                        ms=8 if style == "*" else 5,
                        label=name,
                        zorder=5,
                    )
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(f"{p} [{units.get(p) or '-'}]")
            ax.set_ylabel(_unit_label(label or metric))
            ax.grid(True, which="major", alpha=0.3)
            for h, lab in zip(*ax.get_legend_handles_labels()):
                seen.setdefault(lab, h)
        if seen:
            _legend(fig, list(seen.values()), list(seen), ncol=3)
        return _finish(fig, title, path, formats)


def save_figure(fig, path, formats=("png",)):
    """Write a figure made elsewhere (a problem's `figure`) in every format of `formats`
    (the suffix of `path` is replaced by each), then close it."""
    return _finish(fig, None, path, figure_formats(formats))


def plot_tune_history(history, *, label=None, title=None, path=None, formats=("png",)):
    """`visjax tune`: the training loss per optimiser step (log axis). `label` the loss's
    axis label, with its unit (in brackets, or in trailing parentheses, shown in brackets;
    default `"training loss [-]"`); `title`, `path`, `formats` as in the module's docstring.
    **Returns:** the `Figure` (single column)."""
    formats = figure_formats(formats)
    plt = _pyplot(path)
    with _style():
        fig, axes = _subplots(plt, 1, 1, SINGLE_COLUMN, 2.4)
        ax = axes[0, 0]
        steps = [h["step"] for h in history]
        loss = [h["loss"] for h in history]
        ax.plot(steps, loss, "o-", ms=3, color="C0", gid="loss")
        ax.set_yscale("log")
        ax.set_xlabel("optimiser step [-]")
        ax.set_ylabel(_unit_label(label) if label else "training loss [-]")
        ax.grid(True, which="major", alpha=0.3)
        return _finish(fig, title, path, formats)


RENAMED = {"plot_structure": "plot_moving_point", "plot_euclidean": "plot_static_points"}
"""The names of visjax 0.3 (old -> new): still given, with a `FutureWarning`."""


def __getattr__(name: str):
    if name in RENAMED:  # this module imports no other visjax module: `_util.renamed` inline
        warnings.warn(
            f"visjax.plots.{name} is now visjax.plots.{RENAMED[name]}: the old name will go",
            FutureWarning,
            stacklevel=2,
        )
        return globals()[RENAMED[name]]
    raise AttributeError(f"module 'visjax.plots' has no attribute {name!r}")
