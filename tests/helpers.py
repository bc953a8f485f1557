"""Shared test helpers: tree comparison, finite differences, the outputs' schema check and
the testbed's checks."""

import json
import re

import jax
import numpy as np
import pandas as pd

from visjax import __version__
from visjax.io import ARRAYS, TABLES, read_summary


def tree_allclose(a, b, *, rtol=1e-12, atol=0.0) -> bool:
    """Whether two pytrees have the same structure and allclose leaves."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    if ta != tb:
        return False
    return all(np.allclose(x, y, rtol=rtol, atol=atol, equal_nan=False) for x, y in zip(la, lb))


_BATCHED: dict = {}


def central_difference(f, x, h, *args):
    """Central finite-difference Jacobian of `f(x, *args)` with respect to `x`, all
    perturbations in one vmapped call (`args` held fixed: pass the constants as `args`, not
    in a new closure, and one compiled program serves every point)."""
    x = np.asarray(x, dtype=np.float64)
    E = np.eye(x.size).reshape((x.size,) + x.shape) * h
    fb = _BATCHED.get((f, len(args)))
    if fb is None:  # compiled once per function (and shape), not once per call
        fb = _BATCHED[(f, len(args))] = jax.jit(jax.vmap(f, (0,) + (None,) * len(args)))
    d = (np.asarray(fb(x + E, *args)) - np.asarray(fb(x - E, *args))) / (2 * h)  # (x.size, *out)
    return np.moveaxis(d, 0, -1).reshape(d.shape[1:] + x.shape)


class without_jaxtyping:
    """The user's view: jaxtyping's runtime checks (on in CI's shape-checked run of the
    unit suite) off inside the block, so that the library's own `ValueError` for a wrong
    shape is what is tested."""

    def __enter__(self):
        import jaxtyping

        jaxtyping.config.update("jaxtyping_disable", True)

    def __exit__(self, *exc):
        import jaxtyping

        jaxtyping.config.update("jaxtyping_disable", False)
        return False


def euclidean_scene_file(path, duration: float, rate_hz: float):
    """The project's scene of Nath et al. (`papers.nath.scenario`) written as a
    `StaticPointsData` file at `path`, with its nominal camera and true features."""
    import jax.numpy as jnp
    import numpy as np

    from visjax.io import StaticPointsData
    from visjax.papers import nath

    sc = nath.scenario(duration, rate_hz)
    A0, R0, x0 = nath.nominal_camera()
    return StaticPointsData(
        t=np.asarray(sc.ts),
        pixels=np.asarray(jnp.concatenate([sc.p_c, sc.p_s], 1)),
        platform_R=np.asarray(sc.R_b),
        platform_x=np.asarray(sc.x_b),
        known_features=np.asarray(sc.omega_c),
        A_nominal=np.asarray(A0),
        R_c_nominal=np.asarray(R0),
        x_c_nominal=np.asarray(x0),
        features=np.asarray(sc.omega_s),
    ).save(path)


MAGIC = {".png": b"\x89PNG", ".pdf": b"%PDF", ".svg": b"<?xml"}


def _schema_columns(relative: str):
    """The documented columns of a table, by its folder and name."""
    for name, columns in TABLES.items():
        if name == relative or name.replace("reproduce ", "") == relative:
            return columns
    return None


def _schema_arrays(relative: str):
    for name, arrays in ARRAYS.items():
        pattern = name.replace("<set>", "")
        if name == relative or (
            "<set>" in name and relative.startswith(pattern.split("_")[0] + "_")
        ):
            return {k.rstrip("?"): k.endswith("?") for k in arrays}
    return None


def check_outputs(results) -> dict:
    """Every file under `results` loads (pandas, NumPy) and follows its documented schema;
    returns the summaries' kinds by path."""
    files = sorted(p for p in results.rglob("*") if p.is_file())
    kinds = {}
    for path in files:
        rel = path.relative_to(results).as_posix()
        suffix = path.suffix
        if path.name == "summary.json":
            series = read_summary(path)  # pandas, checked against its schema
            assert series["visjax_version"] == __version__
            assert isinstance(series["settings"], dict) and series["wall_time_s"] > 0
            kinds[rel] = series["kind"]
        elif suffix == ".json":
            assert isinstance(json.loads(path.read_text()), dict), rel
        elif suffix == ".parquet":
            table = pd.read_parquet(path)
            assert len(table) > 0, rel
            columns = _schema_columns(rel)
            if columns is not None:
                assert list(table.columns) == list(columns), rel
                for column, kind in columns.items():
                    if kind == "float":
                        assert pd.api.types.is_float_dtype(table[column]), (rel, column)
                    elif kind == "int":
                        assert pd.api.types.is_integer_dtype(table[column]), (rel, column)
        elif suffix == ".csv":
            assert len(pd.read_csv(path)) > 0, rel
        elif suffix == ".npz":
            with np.load(path) as data:
                expected = _schema_arrays(rel)
                if expected is not None:
                    required = {k for k, optional in expected.items() if not optional}
                    assert required <= set(data.files) <= set(expected), (rel, data.files)
                t = data["t"] if "t" in data.files else data["ts"]
                assert t.ndim == 1 and np.all(np.diff(t) > 0), rel
                for key in data.files:
                    if data[key].dtype.kind == "f" and data[key].shape[:1] == t.shape:
                        assert data[key].shape[0] == t.shape[0], (rel, key)
        elif suffix in MAGIC:
            assert path.read_bytes()[:5].startswith(MAGIC[suffix]), rel
        elif suffix == ".mp4":
            assert path.stat().st_size > 1000, rel
        else:
            raise AssertionError(f"an output with no documented format: {rel}")
    return kinds


def twin_kinematics_residual(run, v_p):
    """max |dr/dt - (2.5)| at the camera samples: r the truth in the camera frame, u the
    camera's commanded velocities, v_p the marker's velocity in the camera frame (m/s)."""
    r, dt = run.position, run.ts[1] - run.ts[0]
    k = run.frame_index[1:-1]
    r_dot = (r[k + 1] - r[k - 1]) / (2 * dt)
    X, Y, Z = r[k].T
    u = run.velocity_true[1:-1]
    vcx, vcy, vcz, wx, wy, wz = u.T
    vp = v_p(run.ts[k])
    model = np.stack(
        [
            vp[:, 0] - vcx + wz * Y - wy * Z,  # eq. (2.5)
            vp[:, 1] - vcy + wx * Z - wz * X,
            vp[:, 2] - vcz + wy * X - wx * Y,
        ],
        axis=1,
    )
    return np.abs(r_dot - model).max()


def check_testbed_tracking(r):
    """The testbed twin's marker tracked within 0.5 px and the UIO from tracked pixels within
    2x of the UIO from exact ones."""
    assert r.tracking_rms_px < 0.5
    assert np.all(np.isfinite(r.pixels))
    assert np.linalg.norm(r.rms) < 2 * np.linalg.norm(r.rms_ideal)
    assert np.all(np.isfinite(r.estimate)) and np.all(np.isfinite(r.rms_frames))


def innovation_ratios(problem, key, parameter: str, values, method: str = "estimator"):
    """`problem.innovation(...).ratio` of `method` on one draw (`key`), at each value of one
    parameter (the others at their defaults): value -> ratio."""
    inputs = problem.inputs(key)
    out = {}
    for value in values:
        params = problem.resolve({parameter: value})
        sol = problem.solve(method, params, inputs, outputs=True)
        out[value] = float(problem.innovation(method, params, sol, inputs).ratio)
    return out


def outside_canvas(fig, renderer=None) -> list[str]:
    """What of a figure reaches outside its canvas (one pixel of tolerance), which a
    saved file would clip: the drawn artists' tight box (ticks beyond the view limits are
    not drawn), per axes (named by its labels), figure legend and figure text."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = renderer or FigureCanvasAgg(fig).get_renderer()
    fig.draw(renderer)
    box = fig.bbox

    def out(e):
        return e.x0 < box.x0 - 1 or e.y0 < box.y0 - 1 or e.x1 > box.x1 + 1 or e.y1 > box.y1 + 1

    found = [
        f"axes {ax.get_ylabel() or ax.get_title()!r}"
        for ax in fig.axes
        if ax.get_visible() and out(ax.get_tightbbox(renderer))
    ]
    found += [f"legend {lg.get_texts()[0].get_text()!r}..." for lg in fig.legends
              if out(lg.get_window_extent(renderer))]  # fmt: skip
    texts = [t for t in fig.texts if t.get_visible() and t.get_text()]
    found += [f"text {t.get_text()!r}" for t in texts if out(t.get_window_extent(renderer))]
    return found


UNIT_LABEL = re.compile(r"\[[^\]]+\]")


def figure_faults(fig) -> list[str]:
    """What a reader of a saved figure would miss: whatever reaches off the canvas
    (`outside_canvas`), and an axes drawing data (lines of more than two points,
    collections, images) with no unit in brackets on its y label, or on its x label
    (its own, or that of an axes sharing its x axis; categorical axes, with text ticks,
    exempt)."""
    found = outside_canvas(fig)
    for ax in fig.axes:
        lines = [ln for ln in ax.get_lines() if np.size(ln.get_xdata()) > 2]
        if not ax.get_visible() or not (lines or ax.collections or ax.images):
            continue
        name = ax.get_title() or ax.get_ylabel() or "an axes"
        if not UNIT_LABEL.search(ax.get_ylabel()):
            found.append(f"{name!r}: y label {ax.get_ylabel()!r} without a unit")
        ticks = [t.get_text() for t in ax.get_xticklabels()]
        if any(re.search("[A-Za-z]", s) and not s.startswith("$") for s in ticks):
            continue
        shared = [a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)]
        if not any(UNIT_LABEL.search(s) for s in shared):
            found.append(f"{name!r}: x label {ax.get_xlabel()!r} without a unit")
    return found
