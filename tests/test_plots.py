"""The figures (`visjax.plots`) on small synthetic arrays: files per format, units on every
axis, paper sizes and fonts, truth on top of the estimate, legends outside the data, the
band over seeds."""

import re
from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.text import Text  # noqa: E402
from matplotlib.ticker import FixedLocator  # noqa: E402

from tests.helpers import outside_canvas  # noqa: E402
from visjax import plots, studies  # noqa: E402

N, S = 120, 4
UNIT = re.compile(r"\[[^\]]+\]")


def _trajectory(n=N, d=6, seeds=None, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 2.0, n)
    truth = np.stack([np.sin(t * (k + 1)) for k in range(d)], axis=-1)
    shape = (n, d) if seeds is None else (seeds, n, d)
    return t, truth, truth + 0.05 * rng.normal(size=shape)


def _velocity(seeds=None, truth=True, **kw):
    t, v, est = _trajectory(seeds=seeds)
    return plots.plot_velocity(t, v if truth else None, est, **kw)


def _structure(seeds=None, truth=True, **kw):
    t, p, est = _trajectory(d=3, seeds=seeds)
    return plots.plot_moving_point(t, p + 2.0 if truth else None, est + 2.0, **kw)


def _camera_velocity(**kw):
    t, v, _ = _trajectory()
    return plots.plot_camera_velocity(t, v, **kw)


def _testbed(**kw):
    t, p, est = _trajectory(d=3)
    ft = t[::4]
    v = _trajectory(n=len(ft))[1]
    run = SimpleNamespace(
        frame_ts=ft,
        ts=t,
        velocity_true=v,
        velocity_measured=v + 0.01,
        position=p,
        estimate=est,
        estimate_ideal=p + 0.001,
    )
    return plots.plot_testbed(run, **kw)


def _euclidean_run(seeds=None, n=3, m=4):
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 2.0, N)
    true = rng.normal(size=(n, 3))
    lead = () if seeds is None else (seeds,)
    decay = np.exp(-2 * t)[:, None, None]
    est = (
        true + decay * rng.normal(size=lead + (1, n, 3)) + 1e-3 * rng.normal(size=lead + (N, n, 3))
    )
    return SimpleNamespace(
        ts=t,
        omega_s=est,
        omega_true=true,
        p_tilde_c=np.abs(rng.normal(size=lead + (N, m))),
        p_tilde_s=np.abs(rng.normal(size=lead + (N, n))),
        pe=rng.uniform(size=lead + (N, n)),
    )


def _euclidean(seeds=None, **kw):
    return plots.plot_static_points(_euclidean_run(seeds), **kw)


def _features(seeds=None, truth=True, **kw):
    r = _euclidean_run(seeds)
    return plots.plot_feature_estimates(r.ts, r.omega_s, r.omega_true if truth else None, **kw)


def _geometry(**kw):
    rng = np.random.default_rng(2)
    scenes = 5
    A = np.tile(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), (scenes, 1, 1))
    p_ref = rng.uniform(50, 400, size=(scenes, 4, 2))
    H = np.tile(np.eye(3), (scenes, 1, 1))
    sc = SimpleNamespace(p_ref=p_ref, p_cur=p_ref + 5.0, A=A)
    errors = {
        who: {"R_bar_deg": rng.uniform(0, 1e-9, scenes), "alpha_rel": np.zeros(scenes)}
        for who in ("visjax", "opencv")
    }
    return plots.plot_geometry(sc, {"H": H}, errors, **kw)


def _records(methods=("observer", "batch", "ekf")):
    rng = np.random.default_rng(3)
    return [
        {
            "method": m,
            "seed": s,
            "result": "diverged" if (m == "ekf" and s == 0) else "successful",
            "latency_s_per_sample": float(rng.uniform(1e-6, 1e-4)),
            "err": float(rng.uniform(1e-3, 1e-2)),
        }
        for m in methods
        for s in range(S)
    ]


def _comparison(seeds=None, **kw):
    if seeds is None:
        kw.setdefault("label", "final position error (m)")
        return plots.plot_comparison(_records(), lambda r: r["err"], **kw)
    t, truth, _ = _trajectory(d=3)
    errors = {m: _trajectory(d=3, seeds=seeds, seed=i)[2] - truth for i, m in enumerate("ab")}
    return plots.plot_comparison(
        _records(("a", "b")),
        lambda r: r["err"],
        label="final position error [m]",
        ts=t,
        errors=errors,
        error_label="position error [m]",
        **kw,
    )


def _sweep(**kw):
    rng = np.random.default_rng(4)
    K, rho = np.meshgrid([0.5, 1.0, 2.0], [0.5, 1.0, 2.0])
    mean = rng.uniform(1e-3, 1e-2, K.size)
    summary = pd.DataFrame(
        {
            "K": K.ravel(),
            "rho": rho.ravel(),
            "rms_mean": mean,
            "rms_min": mean * 0.8,
            "rms_max": mean * 1.2,
            "n_failed": np.r_[1, np.zeros(K.size - 1, int)],
        }
    )
    return plots.plot_sweep(
        summary,
        "rms",
        ["K", "rho"],
        best={"params": {"K": 1.0, "rho": 2.0}, "metric": 2e-3},
        paper={"params": {"K": 1.0, "rho": 1.0}, "metric": 5e-3},
        **{"label": "worst-axis RMS (m)", **kw},
    )


def _tune(**kw):
    history = [{"step": i, "loss": 1.0 / (i + 1)} for i in range(10)]
    return plots.plot_tune_history(history, **{"label": "training RMS (m)", **kw})


def _transient(**kw):
    t = np.linspace(0.0, 2.0, N)
    ideal = (1 + 5 * t) * np.exp(-5 * t)
    measured = {"planar": ideal + 0.02 * t * np.exp(-5 * t), "spherical": ideal * 1.01}
    return plots.plot_transient(t, measured, ideal, **kw)


def _budget_table(failed=True):
    """A synthetic error budget: two sets, no source, two sources, all, one other reading
    (which did not succeed in the second set when `failed`)."""
    configs = [("none", "stated"), ("a", "stated"), ("b", "stated"), ("all", "stated"),
               ("a", "other")]  # fmt: skip
    rows = []
    for j, set_name in enumerate(("I.1", "II.1")):
        for k, (source, reading) in enumerate(configs):
            bad = failed and j == 1 and k == 4
            rows += [
                {"set": set_name, "sources": source, "reading": reading, "axis": axis,
                 "rms_m": np.nan if bad else 1e-3 * (1 + k + i + 2 * j),
                 "thesis_rms_m": 0.01 * (i + 1), "tracking_rms_px": 0.03,
                 "result": "diverged" if bad else "successful"}
                for i, axis in enumerate("xyz")
            ]  # fmt: skip
    return pd.DataFrame(rows)


def _error_budget(**kw):
    return plots.plot_error_budget(_budget_table(), **kw)


def test_error_budget_bars_are_the_tables_values():
    """Each bar is its row's RMS in mm (a failed run: no bar, its result written instead);
    the thesis' RMS of each axis a dashed line of that axis' colour."""
    table = _budget_table()
    fig = _error_budget()
    try:
        for ax, set_name in zip(fig.axes, ("I.1", "II.1"), strict=True):
            part = table[table["set"] == set_name]
            widths = sorted(1e3 * part["rms_m"].dropna())
            bars = sorted(p.get_width() for p in ax.patches if np.isfinite(p.get_width()))
            np.testing.assert_allclose(bars, widths, rtol=1e-12)
            levels = sorted(ln.get_xdata()[0] for ln in ax.get_lines())
            np.testing.assert_allclose(levels, [10.0, 20.0, 30.0])
        texts = [t.get_text().strip() for t in fig.axes[1].texts]
        assert texts == ["diverged"] and not fig.axes[0].texts
        labels = [t.get_text() for t in fig.axes[0].get_yticklabels()]
        assert labels == ["none", "a", "b", "all", "a (other)"]
    finally:
        plt.close(fig)


def _noise_study(**kw):
    by = [studies.Comparison(_records()).statistics("err", resamples=200, seed=i) for i in range(3)]
    stats = {"metric": "err", "noise_levels": [0.1, 0.5, 1.0], "by_noise": by}
    return plots.plot_noise_study(stats, **{"label": "final position error (m)", **kw})


FIGURES = {
    "transient": _transient,
    "noise_study": _noise_study,
    "velocity": _velocity,
    "velocity_no_truth": lambda **kw: _velocity(truth=False, **kw),
    "structure": _structure,
    "structure_no_truth": lambda **kw: _structure(truth=False, **kw),
    "camera_velocity": _camera_velocity,
    "testbed": _testbed,
    "euclidean": _euclidean,
    "feature_estimates": _features,
    "feature_estimates_no_truth": lambda **kw: _features(truth=False, **kw),
    "geometry": _geometry,
    "comparison": _comparison,
    "sweep": _sweep,
    "tune_history": _tune,
    "error_budget": _error_budget,
}
FUNCTIONS = (  # one case per plot function
    "transient",
    "noise_study",
    "velocity",
    "structure",
    "camera_velocity",
    "testbed",
    "euclidean",
    "feature_estimates",
    "geometry",
    "comparison",
    "sweep",
    "tune_history",
    "error_budget",
)
TRUTH_FIGURES = ("velocity", "structure", "testbed", "euclidean", "feature_estimates")
SEED_FIGURES = {
    "velocity": _velocity,
    "velocity_no_truth": lambda **kw: _velocity(truth=False, **kw),
    "structure": _structure,
    "euclidean": _euclidean,
    "feature_estimates": _features,
    "comparison": _comparison,
}


def test_every_plot_function_is_exercised():
    public = {name for name in dir(plots) if name.startswith("plot_")}
    used = {
        "plot_velocity",
        "plot_moving_point",
        "plot_camera_velocity",
        "plot_testbed",
        "plot_static_points",
        "plot_feature_estimates",
        "plot_geometry",
        "plot_comparison",
        "plot_sweep",
        "plot_tune_history",
        "plot_transient",
        "plot_noise_study",
        "plot_error_budget",
    }
    assert public == used


def test_noise_study_draws_the_medians_their_intervals_and_the_failure_rate():
    fig = _noise_study()
    try:
        fig.canvas.draw()
        _check_paper_figure(fig, "noise_study")
        left, right = fig.axes[:2]
        stats = studies.Comparison(_records()).statistics("err", resamples=200, seed=0)
        line = left.get_lines()[0]  # the first method's medians at the three levels
        np.testing.assert_allclose(line.get_xdata(), [0.1, 0.5, 1.0])
        assert line.get_ydata()[0] == stats["methods"]["observer"]["median"]
        ekf = right.get_lines()[-1].get_ydata()  # the EKF failed on seed 0 of S
        np.testing.assert_allclose(ekf[0], 100 / S)
    finally:
        plt.close(fig)


def _shows_data(ax):
    lines = [ln for ln in ax.get_lines() if len(np.atleast_1d(ln.get_xdata())) > 1]
    return bool(lines or ax.collections or ax.images)


def _categorical(axis):
    """Ticks at fixed places labelled with names (not numbers): an `ax.xaxis` or `ax.yaxis`."""
    names = [t.get_text() for t in axis.get_ticklabels()]
    return isinstance(axis.get_major_locator(), FixedLocator) and any(
        re.search("[A-Za-z]", n) and not n.startswith("$") for n in names
    )


def _x_label_with_unit(ax):
    """The axes' own x label, or that of an axes sharing its x axis (stacked panels)."""
    siblings = ax.get_shared_x_axes().get_siblings(ax)
    labels = [a.get_xlabel() for a in siblings if a.get_xlabel()]
    return labels[0] if labels else ""


# the longest of the registered problems' headline labels: the commands' figures carry these
LABELS = [
    "worst-axis RMS over the window (m/s, rad/s)",
    "RMS of |H_hat H^-1 - I| over the second half (-)",
]


@pytest.mark.parametrize("label", LABELS)
@pytest.mark.parametrize("name", ["sweep", "tune_history", "comparison", "noise_study"])
def test_the_commands_figures_keep_every_label_on_the_canvas(name, label):
    """The study commands' figures with each problem's own metric label (the longest
    labels a figure carries): no label, tick or legend entry is clipped by the canvas."""
    fig = FIGURES[name](label=label, title=f"a problem's title, {label}")
    try:
        assert not outside_canvas(fig), outside_canvas(fig)
    finally:
        plt.close(fig)


def _check_paper_figure(fig, name):
    """The width of a paper column; 8-9 pt text; every axes with data labelled with units
    (x: its own label or that of the panel sharing its time axis; categorical axes exempt);
    legends inside the figure and outside every axes. `fig` has been drawn."""
    assert fig.get_figwidth() <= 7.2
    assert fig.get_figwidth() in (plots.SINGLE_COLUMN, plots.DOUBLE_COLUMN)
    shown = [ax for ax in fig.axes if _shows_data(ax)]
    assert shown
    for ax in shown:
        names_y = any(_categorical(a.yaxis) for a in ax.get_shared_y_axes().get_siblings(ax))
        assert names_y or UNIT.search(ax.get_ylabel()), (name, ax.get_ylabel())
        if _categorical(ax.xaxis):
            continue  # method names: no quantity on x
        assert UNIT.search(_x_label_with_unit(ax)), (name, ax.get_title())
    for text in fig.findobj(Text):
        if text.get_text() and text.get_visible():
            assert 8 <= text.get_fontsize() <= 9, (name, text.get_text())
    renderer = FigureCanvasAgg(fig).get_renderer()  # a closed figure's canvas has none
    assert not outside_canvas(fig, renderer), (name, outside_canvas(fig, renderer))
    legends = list(fig.legends) + [ax.get_legend() for ax in fig.axes if ax.get_legend()]
    for legend in legends:
        box = legend.get_window_extent(renderer)
        assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1), name
        for ax in shown:
            assert not box.overlaps(ax.get_window_extent(renderer)), name


@pytest.mark.slow  # the unit tier's time: every figure at 300 dpi in three formats (the
# commands' tests write each figure once)
@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_saved_in_every_format_labelled_with_units_at_paper_size(name, tmp_path):
    """Each plot function: saved as png (300 dpi), pdf and svg, the style per figure
    (rcParams untouched), closed once saved, and `_check_paper_figure`."""
    import matplotlib as mpl

    rc = dict(mpl.rcParams)
    fig = FIGURES[name](path=tmp_path / "figure.png", formats=("png", "pdf", "svg"))
    assert isinstance(fig, matplotlib.figure.Figure)
    assert fig.number not in plt.get_fignums()  # closed once saved
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figure.pdf", "figure.png", "figure.svg"]
    for f in tmp_path.iterdir():
        assert f.stat().st_size > 0
    width_px = plt.imread(tmp_path / "figure.png").shape[1]
    assert abs(width_px - plots.DPI * fig.get_figwidth()) <= 2
    assert dict(mpl.rcParams) == rc
    _check_paper_figure(fig, name)


VARIANTS = {
    **{name: FIGURES[name] for name in set(FIGURES) - set(FUNCTIONS)},
    **{f"{name}_seeds": lambda f=f, **kw: f(seeds=S, **kw) for name, f in SEED_FIGURES.items()},
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_variants_labelled_with_units_at_paper_size(name):
    """Without the truth, and over seeds: the same checks, drawn on screen (no files)."""
    fig = VARIANTS[name]()
    try:
        fig.canvas.draw()
        _check_paper_figure(fig, name)
    finally:
        plt.close(fig)


def test_default_format_is_png_only(tmp_path):
    _tune(path=tmp_path / "tune.png")
    assert [p.name for p in tmp_path.iterdir()] == ["tune.png"]


@pytest.mark.parametrize("name", sorted(FIGURES))
def test_bad_format_raises_before_anything_is_written(name, tmp_path):
    before = plt.get_fignums()
    with pytest.raises(ValueError, match="jpg"):
        FIGURES[name](path=tmp_path / "figure.png", formats=("png", "jpg"))
    assert list(tmp_path.iterdir()) == []
    assert plt.get_fignums() == before  # nothing drawn either


@pytest.mark.parametrize("name", TRUTH_FIGURES)
def test_truth_is_dashed_black_thin_and_on_top(name):
    fig = FIGURES[name]()
    try:
        checked = 0
        for ax in fig.axes:
            truth = [ln for ln in ax.get_lines() if ln.get_gid() == "truth"]
            estimate = [ln for ln in ax.get_lines() if ln.get_gid() == "estimate"]
            if not (truth and estimate):
                continue
            for ln in truth:
                assert ln.get_linestyle() == "--"
                assert matplotlib.colors.to_hex(ln.get_color()) == "#000000"
                assert ln.get_linewidth() <= min(e.get_linewidth() for e in estimate)
                assert ln.get_zorder() > max(e.get_zorder() for e in estimate)
            for ln in estimate:
                assert ln.get_linestyle() == "-"
            checked += 1
        assert checked >= 1
    finally:
        plt.close(fig)


@pytest.mark.parametrize("name", sorted(SEED_FIGURES))
def test_seed_axis_draws_median_and_band(name):
    fig = SEED_FIGURES[name](seeds=S)
    try:
        bands = [c for ax in fig.axes for c in ax.collections if isinstance(c, PolyCollection)]
        assert bands
        texts = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
        assert any("10-90 %" in t and f"{S} seeds" in t for t in texts)
    finally:
        plt.close(fig)
    if name != "comparison":  # one seed: no band, as before
        fig = SEED_FIGURES[name]()
        try:
            assert not any(isinstance(c, PolyCollection) for ax in fig.axes for c in ax.collections)
        finally:
            plt.close(fig)


def test_band_is_the_10_90_percentiles_and_the_line_the_median():
    t, v, est = _trajectory(seeds=9)
    fig = plots.plot_velocity(t, v, est)
    try:
        ax = fig.axes[0]
        line = next(ln for ln in ax.get_lines() if ln.get_gid() == "estimate")
        np.testing.assert_allclose(line.get_ydata(), np.median(est[..., 0], axis=0))
        band = next(c for c in ax.collections if isinstance(c, PolyCollection))
        ys = band.get_paths()[0].vertices[:, 1]
        lo, hi = np.percentile(est[..., 0], (10, 90), axis=0)
        assert np.isclose(ys.min(), lo.min()) and np.isclose(ys.max(), hi.max())
    finally:
        plt.close(fig)


def test_long_trajectory_pdf_stays_small(tmp_path):
    t, v, est = _trajectory(n=10_000, seeds=8)
    plots.plot_velocity(t, v, est, path=tmp_path / "v.png", formats=("pdf",))
    assert (tmp_path / "v.pdf").stat().st_size < 2_000_000


def test_camera_velocity_linear_first_in_input_angular_on_top():
    t, v, _ = _trajectory()
    fig = plots.plot_camera_velocity(t, v, title="Jang's thesis, set I.1")
    try:
        top, bottom = fig.axes
        assert "rad/s" in top.get_ylabel() and "m/s" in bottom.get_ylabel()
        top_lines = [ln for ln in top.get_lines() if ln.get_gid() == "velocity"]
        bottom_lines = [ln for ln in bottom.get_lines() if ln.get_gid() == "velocity"]
        for i in range(3):
            np.testing.assert_allclose(top_lines[i].get_ydata(), v[:, 3 + i])
            np.testing.assert_allclose(bottom_lines[i].get_ydata(), v[:, i])
    finally:
        plt.close(fig)
    with pytest.raises(ValueError, match="N, 6"):
        plots.plot_camera_velocity(t, v[:, :3])


def test_lines_that_coincide_are_drawn_in_interleaved_dashes():
    """A set of constant velocities has components identically zero: their lines coincide,
    and each is drawn in dashes offset from the others' (every colour shows); a line of its
    own stays solid, and the legend keeps solid lines."""
    t = np.linspace(0.0, 2.0, N)
    v = np.zeros((N, 6))
    v[:, 0], v[:, 5] = 0.05, 0.1 * np.sin(t)  # v_cx, omega_cz; the four others are zero
    v[:, 1] = 1e-9 * np.sin(t)  # within 1e-3 of the range: drawn as coinciding
    fig = plots.plot_camera_velocity(t, v)
    try:
        top, bottom = fig.axes
        for ax, zero in ((top, [0, 1]), (bottom, [1, 2])):
            lines = [ln for ln in ax.get_lines() if ln.get_gid() == "velocity"]
            offsets = []
            for i, line in enumerate(lines):
                style = line.get_linestyle()
                if i in zero:
                    offset, pattern = line._unscaled_dash_pattern
                    assert tuple(pattern) == (plots._DASH, plots._DASH), style
                    offsets.append(offset)
                else:
                    assert style == "-"
            assert sorted(offsets) == [0.0, plots._DASH]
        legend_lines = [h for ax in fig.axes for h in ax.get_legend().get_lines()]
        assert {h.get_linestyle() for h in legend_lines} == {"-"}
    finally:
        plt.close(fig)


def test_geometry_degrees_and_relative_errors_on_separate_axes():
    fig = _geometry()
    try:
        ylabels = [ax.get_ylabel() for ax in fig.axes]
        assert sum("[deg]" in y for y in ylabels) == 1
        assert sum("[-]" in y for y in ylabels) == 1
        assert not any("[deg]" in y and "[-]" in y for y in ylabels)
    finally:
        plt.close(fig)


def test_unit_in_parentheses_becomes_brackets():
    assert plots._unit_label("worst-axis RMS, last half (m/s, rad/s)") == (
        "worst-axis RMS, last half [m/s, rad/s]"
    )
    assert plots._unit_label("error [mm]") == "error [mm]"
    assert plots.figure_formats("PDF") == ("pdf",)
    assert plots.figure_formats(" png, PDF,png") == ("png", "pdf")  # the command line's text
    with pytest.raises(ValueError, match="empty"):
        plots.figure_formats(())
    with pytest.raises(ValueError, match="unknown figure format 'jpeg'"):
        plots.figure_formats("png,jpeg")


def test_comparison_errors_need_a_label_with_ts():
    with pytest.raises(ValueError, match="error_label"):
        plots.plot_comparison(
            _records(), lambda r: r["err"], label="e [m]", errors={"a": np.zeros((2, 3))}
        )


def test_the_style_keeps_interactive_mode_set_inside_it():
    """pyplot turns `interactive` on when a kernel's first figure picks the inline backend;
    the style context must not undo that (later figures would not show), but restores the
    rest."""
    import matplotlib

    from visjax import plots

    before = matplotlib.rcParams["interactive"], matplotlib.rcParams["font.size"]
    try:
        matplotlib.rcParams["interactive"] = False
        with plots._style():
            matplotlib.rcParams["interactive"] = True
        assert matplotlib.rcParams["interactive"] is True
        assert matplotlib.rcParams["font.size"] == before[1]
    finally:
        matplotlib.rcParams["interactive"] = before[0]


def test_moving_point_error_shows_the_transient_and_the_steady_state():
    """An error that starts 100 times its steady state: the error axis is linear over the
    second half's range (shaded) and logarithmic beyond, and its limits hold the whole
    transient; without a transient the axis stays linear."""
    t = np.linspace(0.0, 2.0, N)
    truth = np.stack([np.sin(t), np.cos(t), 2.0 + 0 * t], axis=-1)
    wobble = 1e-3 * np.sin(40 * t)[:, None]
    for transient, scale in ((0.5 * np.exp(-10 * t)[:, None], "symlog"), (0.0, "linear")):
        fig = plots.plot_moving_point(t, truth, truth + wobble + transient)
        try:
            errors = [ax for ax in fig.axes if ax.get_ylabel().startswith("error")]
            assert len(errors) == 3 and all(ax.get_yscale() == scale for ax in errors)
            if scale == "symlog":
                low, high = errors[0].get_ylim()
                assert high >= 500.0 * 0.99  # mm: the largest transient error is inside
                assert errors[0].yaxis.get_transform().linthresh >= 4.0 * 0.99  # 4x 1 mm
        finally:
            plt.close(fig)


def test_weak_parallax_shades_where_the_depth_is_not_observable():
    """`jang.weak_parallax`: the camera's v_cy crossing zero with the unknown input in x
    (set II.3's D) is a weakly observable stretch around the crossing, and only there; a
    static point keeps v_cx's parallax. `plot_moving_point(weak=...)` shades it in every
    panel, with one legend entry."""
    from visjax.papers.jang import weak_parallax

    t = np.linspace(0.0, 20.0, 2001)
    position = np.c_[0.1 + 0 * t, 0.05 + 0 * t, 1.0 + 0 * t]
    velocity = np.zeros((t.size, 6))
    velocity[:, 0], velocity[:, 1] = 0.3, 0.4 * np.cos(2 * np.pi * t / 20.0)  # zero at 5, 15
    weak = weak_parallax(position, velocity, D=[1.0, 0.0, 0.0])
    edges = t[np.flatnonzero(np.diff(np.r_[0, weak.astype(int), 0]))]
    assert len(edges) == 4 and np.all(np.abs(edges - [5, 5, 15, 15]) < 0.4), edges
    assert not weak_parallax(position, velocity).any()  # static point: v_cx's parallax
    fig = plots.plot_moving_point(t, position, position + 1e-3, weak=weak)
    try:
        spans = [p for ax in fig.axes for p in ax.patches if p.get_label() != "_nolegend_"]
        assert len([p for p in fig.axes[0].patches]) == 2  # two stretches per panel
        labels = [t.get_text() for t in fig.legends[0].get_texts()]
        assert labels.count("depth weakly observable") == 1, (labels, len(spans))
    finally:
        plt.close(fig)
