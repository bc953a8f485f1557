"""A problem's data are traced values, not compile-time constants (`DESIGN.md`, version 4):
a second data file of equal shapes reuses every compiled program, a noise level is a
`Parameter` (a noise sweep is one compiled program), and `jax.grad` reaches the data."""

import logging

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.example_data import velocity_example
from visjax import RESULTS, papers, studies
from visjax.papers import hamel, spica


class _Compiles(logging.Handler):
    """The programs XLA compiles while it is attached (`jax.log_compiles`)."""

    def __init__(self):
        super().__init__()
        self.names = []

    def emit(self, record):
        message = record.getMessage()
        if message.startswith("Compiling "):
            self.names.append(message.split(" ")[1])


class compiles:
    def __enter__(self):
        self.handler = _Compiles()
        self.logger = logging.getLogger("jax")
        self.logger.addHandler(self.handler)
        self.flag = jax.log_compiles(True)
        self.flag.__enter__()
        return self.handler.names

    def __exit__(self, *exc):
        self.flag.__exit__(*exc)
        self.logger.removeHandler(self.handler)


@pytest.fixture(scope="module")
def two_files(tmp_path_factory):
    """Two velocity data files of equal shapes (0.3 s at 1 kHz, 2% of the features out of
    view), different pixels, camera and known length (two seeds of the example scene)."""
    folder = tmp_path_factory.mktemp("traced")
    paths = [
        velocity_example(duration=0.3, seed=seed, noise_px=0.0).save(folder / f"{seed}.npz")
        for seed in (0, 1)
    ]
    return [papers.velocity_problem(data=p, noise_px=0.1) for p in paths]


def test_a_second_file_of_equal_shapes_compiles_nothing_new(two_files):
    first, second = two_files
    keys = jnp.arange(2)
    a = studies.evaluate(first, keys=keys)
    with compiles() as names:
        b = studies.evaluate(second, keys=keys)
        again = studies.evaluate(first, keys=keys)
    assert names == []
    assert (a.result == RESULTS.successful).all()
    assert (b.result == RESULTS.successful).all()
    # the second file's own numbers (its data are arguments, not the first's constants)
    assert not np.allclose(a.metrics["rms"], b.metrics["rms"], rtol=1e-3)
    np.testing.assert_array_equal(again.metrics["rms"], a.metrics["rms"])


def test_a_noise_sweep_is_one_compiled_program(two_files):
    """`noise_px` is a parameter: a sweep over four levels and two seeds is one vmapped
    program, another sweep over other levels compiles nothing, and each row equals the
    problem built at that level (`evaluate`, the same seed's draw)."""
    problem, _ = two_files
    levels = np.array([0.0, 0.05, 0.1, 0.3])
    with compiles() as names:
        table = studies.sweep(problem, {"noise_px": levels}, np.arange(2)).to_pandas()
    assert names.count("jit(one)") == 1  # the chunk's vmapped run
    with compiles() as names:
        studies.sweep(problem, {"noise_px": levels[::-1] * 2}, np.arange(2))
    assert names == []
    assert (table["result"] == "successful").all()
    worst = table.pivot(index="noise_px", columns="seed", values="rms_worst")
    assert (np.diff(worst.mean(axis=1).to_numpy()) > 0).all()  # more noise, more error
    # the row at 0.05 px is the problem built with 0.05 px
    built = papers.velocity_problem(data=problem.source, noise_px=0.05)
    with compiles() as names:
        ev = studies.evaluate(built, keys=jnp.arange(2))
    assert names == []
    np.testing.assert_allclose(worst.loc[0.05].to_numpy(), ev.metrics["rms_worst"], rtol=1e-12)
    with pytest.raises(ValueError, match="noise_px.*must not be negative"):
        studies.sweep(problem, {"noise_px": np.array([0.1, -0.1])}, np.arange(1))


@pytest.mark.slow
def test_the_gradient_reaches_the_intrinsics_and_a_reference_pixel():
    """`jax.grad` of the velocity problem's mean RMS (noise-free, 1 s of the paper's scene)
    with respect to the intrinsics `A` and the reference image's pixels matches central
    differences (the sign term's switching is unchanged at a step of 1e-6 relative)."""
    problem = papers.velocity_problem(duration=1.0, noise_px=0.0)

    def loss(A, reference):
        q = eqx.tree_at(
            lambda q: (q.A, q.reference_pixels),
            problem,
            (A, reference),
            is_leaf=lambda x: x is None,
        )
        return jnp.mean(studies.evaluate(q, keys=jnp.arange(1)).metrics["rms_worst"])

    A, reference = problem.A, problem.clean[0]
    grad_A, grad_ref = jax.grad(loss, argnums=(0, 1))(A, reference)
    for i, j in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        h = 1e-6 * abs(float(A[i, j]))
        fd = (loss(A.at[i, j].add(h), reference) - loss(A.at[i, j].add(-h), reference)) / (2 * h)
        assert float(grad_A[i, j]) == pytest.approx(float(fd), rel=1e-4)
        assert float(grad_A[i, j]) != 0.0
    for i, j in [(0, 0), (2, 1)]:
        h = 1e-4
        fd = (loss(A, reference.at[i, j].add(h)) - loss(A, reference.at[i, j].add(-h))) / (2 * h)
        assert float(grad_ref[i, j]) == pytest.approx(float(fd), rel=1e-4)
        assert float(grad_ref[i, j]) != 0.0


@pytest.mark.parametrize(
    "build",
    [
        lambda: papers.static_points_problem(noise_px=0.1, duration=2.0, rate_hz=20.0),
        lambda: papers.moving_point_problem(noise_px=0.1, duration=2.0),
        lambda: spica.point_depth_problem(noise_px=0.1, duration=0.2),
        lambda: hamel.homography_problem(noise_px=0.1, duration=0.2),
        lambda: hamel.homography_problem(noise_px=0.1, duration=0.2, variant="velocity_front_end"),
    ],
    ids=["static_points", "moving_point", "point_depth", "homography", "front_end"],
)
def test_the_noise_level_is_a_data_parameter(build):
    """`noise_px` is a non-negative `Parameter` (default the problem's level) that sets the
    problem's own field (`at`), traceably; it is not one of the gains."""
    problem = build()
    spec = problem.parameters()["noise_px"]
    assert spec.default == 0.1 and spec.nonnegative and not spec.positive
    assert "noise_px" not in problem.gains({})
    moved = problem.at({"noise_px": jnp.asarray(0.3)})
    assert float(getattr(moved, "base", moved).noise_px) == 0.3

    @jax.jit
    def spread(level):  # the draw's noise, traced through the problem
        q = problem.at({"noise_px": level})
        base = problem.at({"noise_px": jnp.asarray(0.0)})
        key = jax.random.key(0)
        pixels = [p.inputs(key) for p in (q, base)]
        pixels = [x["pixels"] if isinstance(x, dict) else x for x in pixels]
        return jnp.nanstd(pixels[0] - pixels[1])

    assert float(spread(jnp.asarray(0.5))) == pytest.approx(0.5, rel=0.1)
    with pytest.raises(ValueError, match="must not be negative"):
        studies.check_values(problem, {"noise_px": -1.0}, "test")
