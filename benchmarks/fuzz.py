"""Fuzz the public geometry functions with well-posed, near-degenerate and invalid inputs.

Prints JSON: per function, dtype and kind of input, how many inputs came back
`correct` (successful and within tolerance of the truth), as a `clear_error` (a raised
error), as a `result_code` (a non-successful `visjax.RESULTS`, or NaN where the function's
docstring says NaN in gives NaN out), `silent_nonfinite` (reported successful with a NaN or
inf), or `silently_wrong` (reported successful, finite, and off the truth by more than the
tolerance). The aim: the last two are 0.

    python benchmarks/fuzz.py [--n 10000] [--dtype float64|float32] [--seed 0]

The test suite runs the same cases on a few hundred inputs (`tests/test_fuzz.py`).
"""

import argparse
import json
import os
import sys


def _setup(dtype: str):
    if dtype == "float32":
        os.environ["JAX_ENABLE_X64"] = "0"
    import jax

    jax.config.update("jax_enable_x64", dtype == "float64")


KINDS = ("well_posed", "near_degenerate", "invalid")
CATEGORIES = ("correct", "clear_error", "result_code", "silent_nonfinite", "silently_wrong")


def _counts():
    return {c: 0 for c in CATEGORIES}


def _classify(ok, finite, error, tol, counts):
    """Per element: `ok` the success flag, `finite` its outputs, `error` against truth."""
    import numpy as np

    ok, finite, error = (np.asarray(x) for x in (ok, finite, error))
    counts["result_code"] += int(np.sum(~ok))
    counts["silent_nonfinite"] += int(np.sum(ok & ~finite))
    good = ok & finite
    counts["silently_wrong"] += int(np.sum(good & ~(error <= tol)))
    counts["correct"] += int(np.sum(good & (error <= tol)))


def _nan_in_nan_out(counts, *outputs):
    """For a function with no error path, fed invalid input: every output entry NaN is the
    documented result (counted as a result code); anything finite is silently wrong."""
    import numpy as np

    n = outputs[0].shape[0]
    all_nan = np.all([np.all(np.isnan(np.reshape(o, (n, -1))), 1) for o in outputs], 0)
    counts["result_code"] += int(np.sum(all_nan))
    counts["silently_wrong"] += int(np.sum(~all_nan))


def _scenes(n, seed, kind, dtype):
    """Planar scenes (Chitrakaran et al., section 3) corrupted by `kind`."""
    import numpy as np

    from visjax.sim import random_planar_scenes

    sc = random_planar_scenes(n, 4, seed=seed)
    rng = np.random.default_rng(seed + 1)
    p_ref, p_cur, A = sc.p_ref.copy(), sc.p_cur.copy(), sc.A.copy()
    if kind == "near_degenerate":
        # point 2 moved to within 1e-4..1 px of the line through points 0 and 1, in both
        # images (the homography is still defined, barely)
        for p in (p_ref, p_cur):
            d = p[:, 1] - p[:, 0]
            t = rng.uniform(0.3, 0.7, n)[:, None]
            normal = np.stack([-d[:, 1], d[:, 0]], 1) / np.linalg.norm(d, axis=1, keepdims=True)
            off = 10.0 ** rng.uniform(-4, 0, n)[:, None]
            p[:, 2] = p[:, 0] + t * d + off * normal
    elif kind == "invalid":
        which = rng.integers(0, 4, n)
        i = np.arange(n)
        bad = rng.choice([np.nan, np.inf, -np.inf], n)
        p_cur[i[which == 0], rng.integers(0, 4), rng.integers(0, 2)] = bad[which == 0]
        p_ref[i[which == 1], rng.integers(0, 4), 0] = bad[which == 1]
        A[i[which == 2], 0, 0] = bad[which == 2]
        A[i[which == 3], 1, 1] = 0.0
    cast = lambda x: np.asarray(x, dtype)  # noqa: E731
    return sc, cast(p_ref), cast(p_cur), cast(A)


def _transfer(G, p_ref, p_cur):
    """The largest pixel error of `G p_ref` against `p_cur`, per element."""
    import numpy as np

    G = np.asarray(G, float)
    h = np.concatenate([np.asarray(p_ref, float), np.ones(p_ref.shape[:2] + (1,))], -1)
    q = np.einsum("nij,nkj->nki", G, h)
    with np.errstate(all="ignore"):
        return np.max(np.abs(q[..., :2] / q[..., 2:] - p_cur), (1, 2))


def fuzz_reconstruction(n, seed, dtype):
    import jax
    import numpy as np

    from visjax import RESULTS
    from visjax.geometry import euclidean_reconstruction, find_homography_checked

    tol = 1e-6 if dtype == "float64" else 1e-3
    f = jax.jit(jax.vmap(lambda a, b, c, d: euclidean_reconstruction(a, b, c, d, throw=False)))
    g = jax.jit(jax.vmap(find_homography_checked))
    out = {}
    for kind in KINDS:
        sc, p_ref, p_cur, A = _scenes(n, seed, kind, dtype)
        # a prior about 1 degree off picks between the two physical solutions (as
        # `visjax geometry` does): without one the choice is legitimately ambiguous
        prior = sc.n_star + 0.02 * np.random.default_rng(seed + 2).normal(size=sc.n_star.shape)
        rec = f(p_ref, p_cur, A, np.asarray(prior, dtype))
        ok = np.asarray(rec.result._value) == int(RESULTS.successful._value)
        finite = np.all(np.isfinite(np.asarray(rec.H)), (1, 2)) & np.all(
            np.isfinite(np.asarray(rec.alpha)), 1
        )
        # well-posed and invalid: against the scene's true H; near-degenerate (the moved
        # point leaves the scene's truth behind): the homography's transfer of the points
        # either physical solution recomposes H = R + x_h n^T (eq. (12)); which one the
        # prior picks is the paper's ambiguity, not an error
        H_rec = (
            np.asarray(rec.R_bar)
            + np.asarray(rec.x_h)[:, :, None] * np.asarray(rec.n_star)[:, None]
        )
        err = np.max(np.abs(H_rec - sc.H), (1, 2))
        if kind == "near_degenerate":
            err = _transfer(rec.G_n, p_ref, p_cur) / 100.0
        c = _counts()
        _classify(ok, finite, err, tol, c)
        out.setdefault("euclidean_reconstruction", {})[kind] = c
        G, r = g(p_ref, p_cur)
        okg = np.asarray(r._value) == int(RESULTS.successful._value)
        c = _counts()
        finite_g = np.all(np.isfinite(np.asarray(G)), (1, 2))
        _classify(
            okg, finite_g, _transfer(G, p_ref, p_cur), 1e-6 if dtype == "float64" else 5e-2, c
        )
        out.setdefault("find_homography_checked", {})[kind] = c
    return out


def fuzz_camera(n, seed, dtype):
    import jax
    import numpy as np

    from visjax import RESULTS
    from visjax.geometry import pixel_to_normalized, project_checked

    rng = np.random.default_rng(seed)
    out = {}
    for kind in KINDS:
        X = np.c_[rng.uniform(-1, 1, (n, 2)), rng.uniform(0.5, 5, n)]
        A = np.tile(np.array([[800.0, 0.0, 320.0], [0.0, 790.0, 240.0], [0, 0, 1]]), (n, 1, 1))
        if kind == "near_degenerate":
            X[:, 2] = 10.0 ** rng.uniform(-6, -2, n)  # points just in front of the camera
        elif kind == "invalid":
            which = rng.integers(0, 3, n)
            X[which == 0, 2] = -rng.uniform(0.1, 2, np.sum(which == 0))  # behind
            X[which == 1, 0] = np.nan
            A[which == 2, 0, 0] = rng.choice([0.0, np.nan], np.sum(which == 2))
        X, A = np.asarray(X, dtype), np.asarray(A, dtype)
        p, r = jax.jit(jax.vmap(lambda x, a: project_checked(x[None], a)))(X, A)
        p = np.asarray(p)[:, 0]
        ok = np.asarray(r._value) == int(RESULTS.successful._value)
        truth = X[:, :2].astype(float) / X[:, 2:].astype(float) * np.array([800.0, 790.0]) + [
            320,
            240,
        ]
        rel = np.max(np.abs(p - truth), 1) / np.maximum(np.max(np.abs(truth), 1), 1.0)
        c = _counts()
        _classify(ok, np.all(np.isfinite(p), 1), rel, 1e-12 if dtype == "float64" else 1e-5, c)
        out.setdefault("project_checked", {})[kind] = c
        # pixel_to_normalized: no error path; NaN in (or an unusable A) must give NaN out
        m = np.asarray(jax.jit(jax.vmap(pixel_to_normalized))(np.where(ok[:, None], p, np.nan), A))
        xy = X[:, :2].astype(float) / X[:, 2:].astype(float)
        with np.errstate(all="ignore"):
            err = np.max(np.abs(m - xy), 1) / np.maximum(np.max(np.abs(xy), 1), 1.0)
        c = _counts()
        _classify(ok, np.all(np.isfinite(m), 1), err, 1e-10 if dtype == "float64" else 1e-5, c)
        c["result_code"] = int(np.sum(~ok & np.all(np.isnan(m), 1)))  # NaN in, NaN out
        c["silently_wrong"] += int(np.sum(~ok & np.any(np.isfinite(m), 1)))
        out.setdefault("pixel_to_normalized", {})[kind] = c
    return out


def fuzz_so3(n, seed, dtype):
    import jax
    import numpy as np

    from visjax.geometry import so3_exp, so3_log

    rng = np.random.default_rng(seed)
    out = {}
    for kind in KINDS:
        u = rng.normal(size=(n, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        if kind == "well_posed":
            angle = rng.uniform(0, np.pi, n)
        elif kind == "near_degenerate":  # near 0 and near pi
            angle = np.where(
                rng.random(n) < 0.5,
                10.0 ** rng.uniform(-9, -3, n),
                np.pi - 10.0 ** rng.uniform(-9, -3, n),
            )
        else:
            angle = rng.uniform(0, np.pi, n)
        w = np.asarray(u * angle[:, None], dtype)
        R = np.asarray(jax.jit(jax.vmap(so3_exp))(w))
        if kind == "invalid":
            R = R.copy()
            R[np.arange(n), rng.integers(0, 3, n), rng.integers(0, 3, n)] = rng.choice(
                [np.nan, np.inf], n
            )
        back = np.asarray(jax.jit(jax.vmap(so3_log))(R))
        finite = np.all(np.isfinite(back), 1)
        c = _counts()
        if kind == "invalid":
            _nan_in_nan_out(c, back)
        else:
            # the rotation vector is unique except at pi, where -w is as good
            err = np.minimum(
                np.max(np.abs(back - w), 1),
                np.where(angle > 3.0, np.max(np.abs(back + w), 1), np.inf),
            )
            _classify(np.ones(n, bool), finite, err, 1e-7 if dtype == "float64" else 2e-3, c)
        out.setdefault("so3_log", {})[kind] = c
    return out


def fuzz_decomposition(n, seed, dtype):
    """`decompose_homography` and `decompose_homography_known_normal`: no error path, so
    NaN in must give NaN out; a finite H must recompose (eq. (12)) and R be a rotation."""
    import jax
    import numpy as np

    from visjax.geometry import decompose_homography, decompose_homography_known_normal
    from visjax.sim import random_planar_scenes, rotation_from_vector

    rng = np.random.default_rng(seed)
    general = jax.jit(jax.vmap(lambda H: decompose_homography(H)))
    known = jax.jit(jax.vmap(decompose_homography_known_normal))
    tol = 1e-9 if dtype == "float64" else 1e-4
    out = {}
    for kind in KINDS:
        sc = random_planar_scenes(n, 4, seed=seed)
        H, n_star = sc.H.copy(), sc.n_star.copy()
        if kind == "near_degenerate":  # near pure rotations and near the identity, any scale
            R = np.stack([rotation_from_vector(w) for w in rng.normal(size=(n, 3)) * 0.3])
            small = (10.0 ** rng.uniform(-9, -4, n))[:, None, None]
            H = R + small * np.einsum("ni,nj->nij", rng.normal(size=(n, 3)), n_star)
            H *= (10.0 ** rng.uniform(-8, 8, n))[:, None, None]
        elif kind == "invalid":
            H[np.arange(n), rng.integers(0, 3, n), rng.integers(0, 3, n)] = rng.choice(
                [np.nan, np.inf, -np.inf], n
            )
        Hd = np.asarray(H, dtype)
        Rs, ts, ns = (np.asarray(x, float) for x in general(Hd))
        Rk, xk = (np.asarray(x, float) for x in known(Hd, np.asarray(n_star, dtype)))
        c_gen, c_known = _counts(), _counts()
        if kind == "invalid":
            _nan_in_nan_out(c_gen, Rs, ts, ns)
            _nan_in_nan_out(c_known, Rk, xk)
        else:
            Hn = H / np.linalg.svd(H, compute_uv=False)[:, 1:2, None]  # middle singular value 1
            Hn *= np.sign(np.linalg.det(Hn))[:, None, None]
            recomposed = Rs + ts[..., :, None] * ns[..., None, :]
            err = np.max(np.abs(recomposed - Hn[:, None]), (1, 2, 3))
            ortho = np.max(np.abs(np.einsum("nkji,nkjl->nkil", Rs, Rs) - np.eye(3)), (1, 2, 3))
            finite = np.all(np.isfinite(recomposed.reshape(n, -1)), 1)
            # near a pure rotation the method's documented accuracy is sqrt(eps) (the
            # rotation branch's threshold balances the eigenvector method's eps / gap)
            tol_gen = tol if kind == "well_posed" else 10.0 * float(np.finfo(dtype).eps) ** 0.5
            _classify(np.ones(n, bool), finite, np.maximum(err, ortho), tol_gen, c_gen)
            # known normal: R + x_h n^T is H up to its positive scale
            a = Rk + xk[:, :, None] * np.asarray(n_star)[:, None, :]
            unit = lambda M: M / np.linalg.norm(M, axis=(1, 2), keepdims=True)  # noqa: E731
            err_k = np.max(np.abs(unit(a) - unit(Hn)), (1, 2))
            finite_k = np.all(np.isfinite(Rk.reshape(n, -1)), 1) & np.all(np.isfinite(xk), 1)
            _classify(np.ones(n, bool), finite_k, err_k, tol_gen, c_known)
        out.setdefault("decompose_homography", {})[kind] = c_gen
        out.setdefault("decompose_homography_known_normal", {})[kind] = c_known
    return out


def fuzz_so3_helpers(n, seed, dtype):
    """`so3_exp` against Rodrigues' formula in NumPy (eq. (A.3)), and `L_omega` against its
    inverse `L_omega_inv` (eq. (27)): no error path, NaN in gives NaN out."""
    import jax
    import numpy as np

    from visjax.geometry import L_omega, L_omega_inv, so3_exp
    from visjax.sim import rotation_from_vector

    rng = np.random.default_rng(seed + 5)
    exp_b = jax.jit(jax.vmap(so3_exp))
    L_b = jax.jit(jax.vmap(lambda w: L_omega(w) @ L_omega_inv(w)))
    tol = 1e-12 if dtype == "float64" else 1e-5
    out = {}
    for kind in KINDS:
        u = rng.normal(size=(n, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        if kind == "near_degenerate":  # near 0 and just below 2 pi (L_omega's pole)
            tiny = 10.0 ** rng.uniform(-9, -3, n)
            angle = np.where(rng.random(n) < 0.5, tiny, 2 * np.pi - 1e-2 - tiny)
        else:
            angle = rng.uniform(0, np.pi, n)
        w = u * angle[:, None]
        if kind == "invalid":
            w[np.arange(n), rng.integers(0, 3, n)] = rng.choice([np.nan, np.inf, -np.inf], n)
        wd = np.asarray(w, dtype)
        R = np.asarray(exp_b(wd), float)
        eye = np.asarray(L_b(wd), float)
        c_exp, c_L = _counts(), _counts()
        if kind == "invalid":
            _nan_in_nan_out(c_exp, R)
            _nan_in_nan_out(c_L, eye)
        else:
            ref = np.stack([rotation_from_vector(x) for x in np.asarray(wd, float)])
            finite = np.all(np.isfinite(R.reshape(n, -1)), 1)
            _classify(np.ones(n, bool), finite, np.max(np.abs(R - ref), (1, 2)), tol, c_exp)
            finite = np.all(np.isfinite(eye.reshape(n, -1)), 1)
            err = np.max(np.abs(eye - np.eye(3)), (1, 2))
            _classify(np.ones(n, bool), finite, err, 1e3 * tol, c_L)
        out.setdefault("so3_exp", {})[kind] = c_exp
        out.setdefault("L_omega", {})[kind] = c_L
    return out


def fuzz(n: int, seed: int, dtype: str) -> dict:
    results = {}
    for part in (fuzz_reconstruction, fuzz_camera, fuzz_so3, fuzz_decomposition, fuzz_so3_helpers):
        results.update(part(n, seed, dtype))
    totals = _counts()
    for per_kind in results.values():
        for c in per_kind.values():
            for k in CATEGORIES:
                totals[k] += c[k]
    return {"n_per_kind": n, "dtype": dtype, "seed": seed, "functions": results, "totals": totals}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000, help="inputs per function and kind")
    parser.add_argument("--dtype", choices=("float64", "float32"), default="float64")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    _setup(args.dtype)
    json.dump(fuzz(args.n, args.seed, args.dtype), sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
