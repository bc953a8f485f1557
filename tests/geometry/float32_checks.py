"""Geometry in float32, run by `test_float32.py` in a process with x64 off (JAX's default).

Prints one JSON object of measured errors; the test asserts the tolerances. Not a test
module itself (pytest does not collect it).
"""

import json
import sys

import jax
import jax.numpy as jnp
import numpy as np

from visjax import RESULTS
from visjax.geometry import (
    L_omega,
    camera_matrix_lstsq,
    decompose_homography,
    decompose_homography_known_normal,
    euclidean_reconstruction,
    find_homography,
    pixel_to_normalized,
    project,
    so3_exp,
    so3_log,
)
from visjax.sim import random_planar_scenes


def f32(x):
    return np.asarray(x, np.float32)


def main() -> dict:
    assert not jax.config.jax_enable_x64, "run with x64 off"
    out = {"dtypes": []}

    # camera
    A62 = f32([[1268.16, 0.0, 257.49], [0.0, 1267.5, 253.1], [0.0, 0.0, 1.0]])
    X = f32([[0.1, -0.2, 2.0]])
    p = project(X, A62).pixels
    out["camera_round_trip"] = float(np.max(np.abs(pixel_to_normalized(p, A62) - X[:, :2] / 2)))
    out["dtypes"].append(str(p.dtype))

    # homography
    sc = random_planar_scenes(100, 4, seed=11)
    G = jax.jit(jax.vmap(lambda a, b: find_homography(a, b).G))(f32(sc.p_ref), f32(sc.p_cur))
    rel = np.max(np.abs(np.asarray(G) - sc.G_n), axis=(-2, -1)) / np.max(np.abs(sc.G_n), (-2, -1))
    out["homography_rel"] = float(np.max(rel))
    out["dtypes"].append(str(G.dtype))

    # decomposition
    sc = random_planar_scenes(100, 4, seed=21)
    R, t, n = jax.jit(jax.vmap(lambda H: decompose_homography(H)))(f32(sc.H))
    recomposed = R + t[..., :, None] * n[..., None, :]
    out["decomposition_recomposed"] = float(np.max(np.abs(recomposed - sc.H[:, None])))
    known = jax.jit(jax.vmap(decompose_homography_known_normal))  # compiled once
    Rk, xk = known(f32(sc.H), f32(sc.n_star))
    out["known_normal_R"] = float(np.max(np.abs(Rk - sc.R_bar)))
    out["known_normal_x"] = float(np.max(np.abs(xk - sc.x_h)))
    out["dtypes"] += [str(R.dtype), str(Rk.dtype)]
    # any scale of H: version 1 returned NaN for H scaled by 1e10 or 1e-10 in float32
    out["known_normal_scaled"] = 0.0
    for k in (1e10, 1e-10, 1e15, 1e-15):
        Rk, xk = known(f32(k * sc.H), f32(sc.n_star))
        out["known_normal_scaled"] = max(
            out["known_normal_scaled"],
            float(np.max(np.abs(Rk - sc.R_bar))),
            float(np.max(np.abs(xk - sc.x_h))),
        )

    # reconstruction, general and known-normal paths
    sc = random_planar_scenes(100, 4, seed=31)
    prior = sc.n_star + 0.005 * np.random.default_rng(1).normal(size=sc.n_star.shape)
    for name, rec in (
        (
            "reconstruction_general",
            jax.jit(jax.vmap(euclidean_reconstruction))(
                f32(sc.p_ref), f32(sc.p_cur), f32(sc.A), f32(prior)
            ),
        ),
        (
            "reconstruction_known",
            jax.jit(jax.vmap(lambda a, b, c, d: euclidean_reconstruction(a, b, c, n_star=d)))(
                f32(sc.p_ref), f32(sc.p_cur), f32(sc.A), f32(sc.n_star)
            ),
        ),
    ):
        out[name] = max(
            float(np.max(np.abs(rec.R_bar - sc.R_bar))),
            float(np.max(np.abs(rec.x_h - sc.x_h))),
            float(np.max(np.abs(rec.n_star - sc.n_star))),
            float(np.max(np.abs(rec.alpha / sc.alpha - 1))),
            float(np.max(np.abs(rec.H - sc.H))),
        )
        out["dtypes"].append(str(rec.R_bar.dtype))

    # SO(3)
    rng = np.random.default_rng(5)
    u = rng.normal(size=(50, 3))
    omegas = f32(u / np.linalg.norm(u, axis=1, keepdims=True) * rng.uniform(0, np.pi, 50)[:, None])
    Rs = jax.jit(jax.vmap(so3_exp))(omegas)
    back = jax.jit(jax.vmap(so3_log))(Rs).omega
    out["so3_round_trip"] = float(np.max(np.abs(back - omegas)))
    out["so3_grad_at_identity_finite"] = bool(
        np.all(
            np.isfinite(
                jax.jit(jax.jacrev(lambda R: so3_log(R).omega))(jnp.eye(3, dtype=jnp.float32))
            )
        )
    )
    out["dtypes"] += [str(Rs.dtype), str(back.dtype), str(jax.jit(jax.vmap(L_omega))(omegas).dtype)]
    # pixels near 4e5 under a pure translation: version 1 reported g33 = 0 (the wrong cause)
    rng = np.random.default_rng(4)
    big = f32(4e5 + rng.uniform(-300, 300, (4, 2)))
    r = find_homography(big, big + f32([5.0, -3.0]), throw=False).result
    out["large_pixels_successful"] = bool(r == RESULTS.successful)

    # camera least squares: an axis with no variation is detected in float32 too, and the
    # centred solve is accurate on offset, narrow data
    m = f32(np.random.default_rng(0).uniform(-0.3, 0.3, (50, 2)))
    p = m * f32([550.0, 730.0]) + f32([300.0, 330.0])
    flat = m.copy()
    flat[:, 1] = 0.25
    try:
        camera_matrix_lstsq(flat, p)
        out["lstsq_flat_axis_detected"] = False
    except RuntimeError:
        out["lstsq_flat_axis_detected"] = True
    narrow = f32(0.5 + 1e-2 * m)
    theta = camera_matrix_lstsq(narrow, narrow * f32(550.0) + f32(300.0)).theta
    out["lstsq_narrow_rel"] = float(np.max(np.abs(np.asarray(theta[:2]) / 550.0 - 1.0)))
    return out


if __name__ == "__main__":
    json.dump(main(), sys.stdout)
