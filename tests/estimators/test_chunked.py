"""The runner's preprocessing fused with the time loop (`Stream.measure`, in chunks).

The same arithmetic as preparing every measurement first (`Stream.measured()`): equal
results to round-off, at the sample times and on a finer grid with held samples, with
dropped frames, saved every few steps, reduced in the loop, and differentiated under both
adjoints; and XLA's own buffer assignment shows that its memory does not grow with the
trajectory.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from visjax import RESULTS
from visjax.estimators import (
    CheckpointAdjoint,
    DirectAdjoint,
    SaveAt,
    Stream,
    VelocityEstimator,
    WindowRMS,
    fixed_camera,
    run,
    velocity_stream,
)
from visjax.papers.chitrakaran import K_EQ63, RHO_EQ63, section6_scenario

EST = VelocityEstimator(K=K_EQ63, rho=RHO_EQ63)


def _with_chunk(stream, chunk):
    return Stream(
        ts=stream.ts,
        ys=stream.ys,
        truth=stream.truth,
        present=stream.present,
        measure=stream.measure,
        chunk=chunk,
    )


@pytest.fixture(scope="module")
def streams():
    sc = section6_scenario(0.3, 1000.0)
    noisy = sc.pixels + 0.05 * jax.random.normal(jax.random.key(1), sc.pixels.shape)
    camera = fixed_camera(noisy, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star)
    stream = velocity_stream(sc.ts, noisy, camera, truth=sc.velocity, chunk=64)  # fmt: skip
    return stream, stream.measured()


def _close(a, b, tol=1e-10):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=0, atol=tol)


@pytest.mark.parametrize(
    "every, unroll",
    [(1, 1), pytest.param(7, 8, marks=pytest.mark.slow)],  # the unit tier's time
)
def test_chunked_equals_prepared(streams, every, unroll):
    """300 steps in chunks of 64 (4 full chunks and a tail of 44), saved every step and
    every 7 (chunks rounded to whole saving periods), with a reducer, the fused run's loop
    unrolled or not: equal to 1e-10."""
    lazy, eager = streams
    reducer = WindowRMS(0.1, 0.3, field="v_hat")
    kw = dict(saveat=SaveAt(every=every, diagnostics=True), reducer=reducer)
    a, b = run(EST, lazy, unroll=unroll, **kw), run(EST, eager, **kw)
    assert a.outputs.v_hat.shape == b.outputs.v_hat.shape == (len(range(0, 300, every)), 6)
    _close(
        (a.ts, a.outputs, a.diagnostics, a.final_state),
        (b.ts, b.outputs, b.diagnostics, b.final_state),
    )
    _close(a.summary.rms, b.summary.rms)
    assert a.result == RESULTS.successful


@pytest.mark.slow
def test_held_samples_and_dropped_frames():
    """Frames at 100 Hz under a 1 ms step (10 steps per frame, chunks of 64 steps that
    straddle frames), with dropped frames held over: equal to the prepared stream."""
    sc = section6_scenario(0.5, 100.0)
    pixels = sc.pixels.at[jnp.array([7, 8, 23])].set(jnp.nan)
    camera = fixed_camera(
        pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star, dropped="hold"
    )
    lazy = velocity_stream(sc.ts, pixels, camera, dropped="hold", chunk=64)  # fmt: skip
    assert not bool(lazy.present[8]) and bool(lazy.present[9])
    eager = lazy.measured()
    a = run(EST, lazy, dt=1e-3, saveat=SaveAt(every=3))
    b = run(EST, eager, dt=1e-3, saveat=SaveAt(every=3))
    assert a.outputs.v_hat.shape == (len(range(0, 491, 3)), 6)
    _close((a.ts, a.outputs, a.final_state), (b.ts, b.outputs, b.final_state))


@pytest.mark.slow
def test_gradient_under_both_adjoints(streams):
    """d(windowed RMS)/dK through the chunked stream under CheckpointAdjoint (its blocks
    are the chunks) and DirectAdjoint equals that of the prepared stream."""
    lazy, eager = streams
    reducer = WindowRMS(0.1, 0.3, field="v_hat")

    def loss(K, stream, adjoint):
        sol = run(
            VelocityEstimator(K=K, rho=EST.rho), stream, saveat=SaveAt(outputs=False),
            reducer=reducer, adjoint=adjoint,
        )  # fmt: skip
        return jnp.sum(sol.summary.rms)

    g = jax.grad(loss)
    ref = g(EST.K, eager, DirectAdjoint())
    assert np.all(np.isfinite(ref)) and np.max(np.abs(ref)) > 0
    for adjoint in (DirectAdjoint(), CheckpointAdjoint(), CheckpointAdjoint(steps=50)):
        np.testing.assert_allclose(g(EST.K, lazy, adjoint), ref, rtol=1e-9, atol=1e-12)


def test_a_bad_frame_stops_the_run_at_its_index(streams):
    lazy, _ = streams
    bad = Stream(ts=lazy.ts, ys=lazy.ys.at[150, 1, 0].set(jnp.nan), measure=lazy.measure, chunk=64)
    sol = run(EST, bad, saveat=SaveAt(outputs=False), throw=False)
    assert sol.result == RESULTS.nonfinite_measurement
    assert int(sol.failed_sample) == 150


def _temp_bytes(seconds, prepared):
    """XLA's temporary buffers of pixels -> stream -> run (nothing saved), compiled."""
    sc = section6_scenario(seconds, 1000.0)

    def f(pixels):
        camera = fixed_camera(
            pixels, sc.A, sc.R_star, sc.s[0], n_star=sc.n_star, z1_star=sc.z1_star, throw=False
        )
        stream = velocity_stream(sc.ts, pixels, camera, throw=False, chunk=128)  # fmt: skip
        if prepared:
            stream = stream.measured()
        return run(EST, stream, saveat=SaveAt(outputs=False), throw=False).final_state

    compiled = jax.jit(f).lower(sc.pixels).compile()
    return compiled.memory_analysis().temp_size_in_bytes


@pytest.mark.slow
def test_memory_does_not_grow_with_the_trajectory():
    """From pixels to the final state, 2 s against 6 s at 1 kHz: the chunked stream's
    temporary buffers grow by less than 32 bytes per step (the pixels themselves, the
    argument, are 64 bytes per sample); those of the stream prepared in full grow by its
    measurements (several hundred bytes per sample)."""
    per_step = {}
    for prepared in (False, True):
        short, long = _temp_bytes(2.0, prepared), _temp_bytes(6.0, prepared)
        per_step[prepared] = (long - short) / 4000
    assert per_step[False] < 32, per_step
    assert per_step[True] > 300, per_step


@pytest.mark.slow
def test_frame_measure_under_jit_vmap_grad(streams):
    """`FrameMeasure` is `velocity_measurements` with the scene's constants: equal values,
    and its gradient with respect to the pixels (jit of vmap of grad) matches central
    differences."""
    lazy, eager = streams
    m = lazy.measure
    frames = lazy.ys[100:104]
    ys = jax.jit(jax.vmap(m))(frames)
    np.testing.assert_allclose(ys.e, eager.ys.e[100:104], rtol=0, atol=1e-13)

    def f(p):
        return jnp.sum(m(p).e * jnp.arange(1.0, 7.0))

    g = jax.jit(jax.vmap(jax.grad(f)))(frames)
    h = 1e-5
    d = jnp.zeros_like(frames[0]).at[2, 1].set(h)
    fd = jax.vmap(lambda p: (f(p + d) - f(p - d)) / (2 * h))(frames)
    np.testing.assert_allclose(g[:, 2, 1], fd, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("n, batch", [(12, 4), (13, 4), (3, 8), (1, 1)])
def test_chunked_map_equals_vmap(n, batch):
    """`chunked_map` is `vmap` for any length (a last chunk overlapping the one before),
    under `jit` and `grad`; and its function is compiled once, not again for a remainder
    (as `lax.map(..., batch_size=...)` does)."""
    from visjax._util import chunked_map

    def f(x):
        return {"a": jnp.sinh(x[0]) * x[1], "b": jnp.stack([x[0], x[1] ** 2])}

    xs = jnp.linspace(-1.0, 2.0, 2 * n).reshape(n, 2)
    got = jax.jit(lambda xs: chunked_map(f, xs, batch))(xs)
    _close(got, jax.vmap(f)(xs), tol=1e-15)
    assert got["b"].shape == (n, 2)

    def loss(xs, m):
        return jnp.sum(m(xs)["a"] ** 2)

    g = jax.grad(loss)(xs, lambda xs: chunked_map(f, xs, batch))
    _close(g, jax.grad(loss)(xs, jax.vmap(f)), tol=1e-13)
    text = jax.jit(lambda xs: chunked_map(f, xs, batch)).lower(xs).as_text()
    assert text.count("sinh") == 1


def test_as_float_copies_a_writable_numpy_array(tmp_path):
    """`as_float` (every input of the library) takes NumPy arrays with `device_put`: the
    values and dtype are kept, integers become floats, and a writable array changed
    afterwards does not change the JAX array (a read-only memory map may be shared)."""
    from visjax._util import as_float

    a = np.arange(4096.0).reshape(512, 8)
    x = as_float(a)
    a[0, 0] = -1.0
    assert x.dtype == jnp.float64 and float(x[0, 0]) == 0.0
    np.testing.assert_array_equal(np.asarray(x)[1:], a[1:])
    assert as_float(np.arange(3)).dtype == jnp.float64
    np.save(tmp_path / "a.npy", a)
    m = as_float(np.load(tmp_path / "a.npy", mmap_mode="r"))
    np.testing.assert_array_equal(np.asarray(m), a)
