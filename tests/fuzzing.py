"""The fuzz cases of the public geometry functions and the three stream builders:
well-posed, near-degenerate and invalid inputs, shared by the test suite
(`tests/test_fuzz.py`, a few hundred inputs) and the command line `benchmarks/fuzz.py`
(10,000 inputs per function and kind).

`fuzz(n, seed, dtype)` returns, per function, dtype and kind of input, how many inputs came
back `correct` (successful and within tolerance of the truth), as a `clear_error` (a raised
error), as a `result_code` (a non-successful `visjax.RESULTS`, or NaN where the function's
docstring says NaN in gives NaN out), `silent_nonfinite` (reported successful with a NaN or
inf), or `silently_wrong` (reported successful, finite, and off the truth by more than the
tolerance). The aim: the last two are 0.

Nothing here imports JAX at the top: the command line chooses float32 or float64 (x64 off
or on) before the first import.
"""

KINDS = ("well_posed", "near_degenerate", "invalid")
CATEGORIES = ("correct", "clear_error", "result_code", "silent_nonfinite", "silently_wrong")


# the batch size of every vmapped call (None: the whole set of inputs at once); the
# inputs are split into chunks of this size, the last one padded
_BATCH = [None]


def _vm(f):
    """`jit(vmap(f))` applied in chunks of `_BATCH[0]` inputs (one compilation per size)."""
    import jax
    import numpy as np

    g = jax.jit(jax.vmap(f))

    def call(*args):
        args = [np.asarray(a) for a in args]
        n = args[0].shape[0]
        b = _BATCH[0] or n
        if b >= n:
            return g(*args)
        parts = []
        for i in range(0, n, b):
            chunk = [a[i : i + b] for a in args]
            m = chunk[0].shape[0]
            if m < b:
                chunk = [np.concatenate([c, np.repeat(c[:1], b - m, 0)]) for c in chunk]
            parts.append(jax.tree_util.tree_map(lambda x: np.asarray(x)[:m], g(*chunk)))
        return jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *parts)

    return call


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
    from visjax.geometry import (
        euclidean_reconstruction,
        find_homography,
        find_homography_robust,
    )

    tol = 1e-6 if dtype == "float64" else 1e-3
    f = _vm(lambda a, b, c, d: euclidean_reconstruction(a, b, c, d, throw=False))

    def plain(a, b):
        out = find_homography(a, b, throw=False)
        return out.G, out.result

    g = _vm(plain)

    def robust(a, b):
        r = find_homography_robust(
            jax.random.key(0), a, b, iterations=16, threshold_px=3.0, throw=False
        )
        return r.H, r.result

    h = _vm(robust)
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
        out.setdefault("find_homography", {})[kind] = c
        # the robust homography from the same four correspondences: exact where they fix
        # one; near-degenerate, its contract is the inlier threshold (3 px)
        H, r = h(p_ref, p_cur)
        okh = np.asarray(r._value) == int(RESULTS.successful._value)
        c = _counts()
        tol_h = 3.0 if kind == "near_degenerate" else (1e-6 if dtype == "float64" else 5e-2)
        finite_h = np.all(np.isfinite(np.asarray(H)), (1, 2))
        _classify(okh, finite_h, _transfer(H, p_ref, p_cur), tol_h, c)
        out.setdefault("find_homography_robust", {})[kind] = c
    return out


def fuzz_camera(n, seed, dtype):
    import numpy as np

    from visjax import RESULTS
    from visjax.geometry import pixel_to_normalized
    from visjax.geometry._camera import _project_checked

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
        p, r = _vm(lambda x, a: _project_checked(x[None], a))(X, A)
        p = np.asarray(p)[:, 0]
        ok = np.asarray(r._value) == int(RESULTS.successful._value)
        truth = X[:, :2].astype(float) / X[:, 2:].astype(float) * np.array([800.0, 790.0]) + [
            320,
            240,
        ]
        rel = np.max(np.abs(p - truth), 1) / np.maximum(np.max(np.abs(truth), 1), 1.0)
        c = _counts()
        _classify(ok, np.all(np.isfinite(p), 1), rel, 1e-12 if dtype == "float64" else 1e-5, c)
        out.setdefault("project", {})[kind] = c
        # pixel_to_normalized: no error path; NaN in (or an unusable A) must give NaN out
        m = np.asarray(_vm(pixel_to_normalized)(np.where(ok[:, None], p, np.nan), A))
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
        R = np.asarray(_vm(so3_exp)(w))
        if kind == "invalid":
            R = R.copy()
            R[np.arange(n), rng.integers(0, 3, n), rng.integers(0, 3, n)] = rng.choice(
                [np.nan, np.inf], n
            )
        back = np.asarray(_vm(lambda r: so3_log(r).omega)(R))
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
    import numpy as np

    from visjax.geometry import decompose_homography, decompose_homography_known_normal
    from visjax.sim import random_planar_scenes, rotation_from_vector

    rng = np.random.default_rng(seed)
    general = _vm(lambda H: decompose_homography(H))
    known = _vm(decompose_homography_known_normal)
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
    import numpy as np

    from visjax.geometry import L_omega, L_omega_inv, so3_exp
    from visjax.sim import rotation_from_vector

    rng = np.random.default_rng(seed + 5)
    exp_b = _vm(so3_exp)
    L_b = _vm(lambda w: L_omega(w) @ L_omega_inv(w))
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


def _against_reference(counts, kind, out, ref, scale, tol):
    """Per element, for a function with no error path: `out` against a NumPy reference of
    the same formula (float64, from the same cast inputs), errors relative to `scale`.

    Invalid inputs: a NaN or inf must reach the outputs computed from it (where the
    reference is not finite, neither is `out`); that is the documented result (counted as
    a result code); a finite output there is silently wrong. Other inputs: every output
    finite and within `tol` of the reference."""
    import numpy as np

    n = out.shape[0]
    out = np.reshape(np.asarray(out, float), (n, -1))
    ref = np.reshape(np.asarray(ref, float), (n, -1))
    fin_out, fin_ref = np.isfinite(out), np.isfinite(ref)
    with np.errstate(all="ignore"):
        diff = np.where(fin_out & fin_ref, np.abs(out - ref), 0.0)
        err = np.max(diff, 1) / np.asarray(scale, float)
    turned_finite = np.any(fin_out & ~fin_ref, 1)
    if kind == "invalid":
        counts["silently_wrong"] += int(np.sum(turned_finite | ~(err <= tol)))
        counts["result_code"] += int(np.sum(~turned_finite & (err <= tol)))
        return
    _classify(
        np.ones(n, bool), np.all(fin_out, 1), np.where(turned_finite, np.inf, err), tol, counts
    )


def _rotations(rng, n):
    import numpy as np

    from visjax.sim import rotation_from_vector

    return np.stack([rotation_from_vector(w) for w in rng.normal(size=(n, 3))])


def _poison(rng, kind, *arrays):
    """For `kind == "invalid"`: one entry of one of `arrays` per element set to NaN or
    +-inf (in place). Returns the arrays."""
    import numpy as np

    if kind != "invalid":
        return arrays
    n = arrays[0].shape[0]
    which = rng.integers(0, len(arrays), n)
    bad = rng.choice([np.nan, np.inf, -np.inf], n)
    for i in range(n):
        a = arrays[which[i]][i]
        a.reshape(-1)[rng.integers(0, a.size)] = bad[i]
    return arrays


def _magnitudes(rng, kind, n, shape):
    """Random entries: magnitudes 1e-3..1e3 (well-posed), or tiny and huge, 1e-12..1e12
    (near-degenerate: the scales where a formula with cancellations or a fixed threshold
    breaks)."""

    span = 12 if kind == "near_degenerate" else 3
    size = (n,) + tuple(shape)
    return rng.normal(size=size) * 10.0 ** rng.uniform(-span, span, (n,) + (1,) * len(shape))


def fuzz_algebra(n, seed, dtype):
    """The functions with no error path (their docstrings say NaN in, NaN out): `skew`,
    `vee`, `sinc`, `to_homogeneous`, `intrinsic_matrix`, `camera_matrix`, `intrinsics_from_camera`,
    `extended_intrinsics`, `normalized_to_pixel`, `alpha_g33`, `euclidean_homography`,
    `projective_homography`, `camera_parameters`, `feature_in_camera` and the two
    regressors of Nath et al. (eqs. (9), (10), (12)), each against the same formula in
    NumPy."""
    import numpy as np

    from visjax import geometry as g

    rng = np.random.default_rng(seed + 11)
    eps = float(np.finfo(dtype).eps)
    tol = 64 * eps
    cast = lambda *xs: [np.asarray(x, dtype) for x in xs]  # noqa: E731
    f64 = lambda *xs: [np.asarray(x, float) for x in xs]  # noqa: E731
    out = {}

    def record(name, kind, got, ref, scale, tol_=tol):
        c = _counts()
        _against_reference(c, kind, got, ref, scale, tol_)
        out.setdefault(name, {})[kind] = c

    def norm(x):
        """The largest finite magnitude of each element (the scale of the finite data)."""
        x = np.asarray(x, float).reshape(np.shape(x)[0], -1)
        return np.maximum(np.max(np.where(np.isfinite(x), np.abs(x), 0.0), 1), 1e-300)

    for kind in KINDS:
        # skew / vee / to_homogeneous / camera_matrix / extended_intrinsics
        (v,) = _poison(rng, kind, _magnitudes(rng, kind, n, (3,)))
        (v,) = cast(v)
        (vf,) = f64(v)
        ref = np.zeros((n, 3, 3))
        ref[:, 0, 1], ref[:, 0, 2], ref[:, 1, 2] = -vf[:, 2], vf[:, 1], -vf[:, 0]
        ref[:, 1, 0], ref[:, 2, 0], ref[:, 2, 1] = vf[:, 2], -vf[:, 1], vf[:, 0]
        record("skew", kind, _vm(g.skew)(v), ref, norm(vf), 0.0)
        (S,) = cast(*_poison(rng, kind, _magnitudes(rng, kind, n, (3, 3))))
        (Sf,) = f64(S)
        ref = 0.5 * np.stack(
            [Sf[:, 2, 1] - Sf[:, 1, 2], Sf[:, 0, 2] - Sf[:, 2, 0], Sf[:, 1, 0] - Sf[:, 0, 1]], 1
        )
        record("vee", kind, _vm(g.vee)(S), ref, norm(Sf), tol)
        (x,) = cast(*_poison(rng, kind, _magnitudes(rng, kind, n, (2,))))
        ref = np.concatenate([x.astype(float), np.ones((n, 1))], 1)
        record("to_homogeneous", kind, _vm(g.to_homogeneous)(x), ref, norm(ref), 0.0)
        (theta,) = cast(*_poison(rng, kind, _magnitudes(rng, kind, n, (4,))))
        t = theta.astype(float)
        ref = np.zeros((n, 3, 3))
        ref[:, 0, 0], ref[:, 0, 2], ref[:, 1, 1], ref[:, 1, 2], ref[:, 2, 2] = (
            t[:, 0],
            t[:, 2],
            t[:, 1],
            t[:, 3],
            1.0,
        )
        record("camera_matrix", kind, _vm(g.camera_matrix)(theta), ref, norm(ref), 0.0)
        (A,) = cast(*_poison(rng, kind, _magnitudes(rng, kind, n, (3, 3))))
        ref = A.astype(float).copy()
        ref[:, :2, 2] = np.where(np.isfinite(ref[:, :2, 2]), 0.0, np.nan)
        record("extended_intrinsics", kind, _vm(g.extended_intrinsics)(A), ref, norm(A), 0.0)

        # sinc: near 0 (the Taylor branch and its threshold) when near-degenerate
        if kind == "near_degenerate":
            x = rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-12, -1, n)
            x[: n // 10] = 0.0
        else:
            x = rng.uniform(-50, 50, n)
        (x,) = cast(*_poison(rng, kind, x[:, None]))
        xf = x[:, 0].astype(float)
        with np.errstate(all="ignore"):
            ref = np.where(xf == 0.0, 1.0, np.sin(xf) / np.where(xf == 0.0, 1.0, xf))
        record("sinc", kind, _vm(g.sinc)(x[:, 0]), ref, np.ones(n), 8 * eps)

        # intrinsic_matrix, intrinsics_from_camera, normalized_to_pixel
        fx, fy = (10.0 ** rng.uniform(1, 4, n) for _ in range(2))
        cx, cy, sk = rng.uniform(0, 1000, n), rng.uniform(0, 1000, n), rng.normal(0, 5, n)

        def intrinsics():
            """This kind's random intrinsic matrices (eq. (15)), a fresh copy each call."""
            A = np.tile(np.eye(3), (n, 1, 1))
            A[:, 0, 0], A[:, 0, 1], A[:, 0, 2], A[:, 1, 1], A[:, 1, 2] = fx, sk, cx, fy, cy
            return A

        args = np.stack([fx, fy, cx, cy, sk], 1)
        if kind == "near_degenerate":
            args[:, :2] = 10.0 ** rng.uniform(-9, 9, (n, 2))
        (args,) = cast(*_poison(rng, kind, args))
        a = args.astype(float)
        ref = np.zeros((n, 3, 3))
        ref[:, 0] = a[:, [0, 4, 2]]
        ref[:, 1, 1:] = a[:, [1, 3]]
        ref[:, 2, 2] = 1.0
        got = _vm(lambda z: g.intrinsic_matrix(z[0], z[1], z[2], z[3], z[4]))(args)
        record("intrinsic_matrix", kind, got, ref, norm(ref), 0.0)
        phi = np.pi / 2 + rng.normal(0, 0.05, n)
        if kind == "near_degenerate":  # axes nearly parallel
            phi = rng.choice([1e-4, np.pi - 1e-4], n) * (1 + rng.uniform(-0.5, 0.5, n))
        e4 = np.stack(
            [fx / 1000, 10.0 ** rng.uniform(2, 4, n), 10.0 ** rng.uniform(2, 4, n), phi, cx, cy], 1
        )
        (e4,) = cast(*_poison(rng, kind, e4))
        b = e4.astype(float)
        ref = np.zeros((n, 3, 3))
        ref[:, 0] = np.stack(
            [b[:, 0] * b[:, 1], b[:, 0] * b[:, 1] * np.cos(b[:, 3]) / np.sin(b[:, 3]), b[:, 4]], 1
        )
        ref[:, 1] = np.stack([np.zeros(n), b[:, 0] * b[:, 2] / np.sin(b[:, 3]), b[:, 5]], 1)
        ref[:, 2, 2] = 1.0
        got = _vm(lambda z: g.intrinsics_from_camera(z[0], z[1], z[2], z[3], z[4], z[5]))(e4)
        record("intrinsics_from_camera", kind, got, ref, norm(ref), 16 * tol)
        m = _magnitudes(rng, kind, n, (2,))
        A = intrinsics()
        m, A = cast(*_poison(rng, kind, m, A))
        mf, Af = f64(m, A)
        # eq. (15) for an upper-triangular A (the entries below the diagonal are not read)
        u = Af[:, 0, 0] * mf[:, 0] + Af[:, 0, 1] * mf[:, 1] + Af[:, 0, 2]
        ref = np.stack([u, Af[:, 1, 1] * mf[:, 1] + Af[:, 1, 2]], 1)
        scale = norm(Af[:, :2]) * (norm(mf) + 1.0)
        record("normalized_to_pixel", kind, _vm(g.normalized_to_pixel)(m, A), ref, scale, 2 * tol)

        # alpha_g33 = 1 / (G_n p*)_3: error of the reciprocal against the row product,
        # relative to the sum of magnitudes of its terms (the product's conditioning)
        G = np.tile(np.eye(3), (n, 1, 1)) + 1e-3 * rng.normal(size=(n, 3, 3))
        p = rng.uniform(0, 640, (n, 4, 2))
        if kind == "near_degenerate":  # points near the line at infinity of G
            delta = rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-9, -3, n)
            G[:, 2, 0] = (delta - G[:, 2, 2] - G[:, 2, 1] * p[:, 0, 1]) / p[:, 0, 0]
        G, p = cast(*_poison(rng, kind, G, p))
        Gf, pf = f64(G, p)
        w = np.einsum("nkj,nj->nk", np.concatenate([pf, np.ones((n, 4, 1))], -1), Gf[:, 2])
        got = np.asarray(_vm(g.alpha_g33)(G, p), float)
        terms = (
            np.abs(pf[..., 0] * Gf[:, 2:, 0])
            + np.abs(pf[..., 1] * Gf[:, 2:, 1])
            + np.abs(Gf[:, 2:, 2])
        )
        with np.errstate(all="ignore"):
            got_w = 1.0 / got
        record("alpha_g33", kind, got_w, w, np.nan_to_num(np.max(terms, 1), nan=1.0), 8 * tol)

        # euclidean_homography / projective_homography: backward error against A^-1 G A,
        # relative to |A^-1| |G| |A|; an unusable A gives all NaN (documented)
        A = intrinsics()
        H = _rotations(rng, n) + 0.1 * rng.normal(size=(n, 3, 3))
        if kind == "near_degenerate":
            A[:, 0, 0] = 10.0 ** rng.uniform(-6, 6, n)
            H *= 10.0 ** rng.uniform(-12, 12, (n, 1, 1))
        bad_A = np.zeros(n, bool)
        if kind == "invalid":
            bad_A = rng.random(n) < 0.3
            A[bad_A, 1, 1] = rng.choice([0.0, np.nan], int(np.sum(bad_A)))
            H[~bad_A] = _poison(rng, kind, H[~bad_A])[0]
        H, A = cast(H, A)
        Hf, Af = f64(H, A)
        with np.errstate(all="ignore"):
            Ainv = np.linalg.inv(np.where(bad_A[:, None, None], np.eye(3), Af))
            ref_e = np.where(bad_A[:, None, None], np.nan, Ainv @ Hf @ Af)
            ref_p = np.where(bad_A[:, None, None], np.nan, Af @ Hf @ Ainv)
            scale = np.nan_to_num(
                np.linalg.norm(Ainv, axis=(1, 2))
                * np.linalg.norm(np.nan_to_num(Hf), axis=(1, 2))
                * np.linalg.norm(Af, axis=(1, 2)),
                nan=1.0,
            )
        record(
            "euclidean_homography", kind, _vm(g.euclidean_homography)(H, A), ref_e, scale, 8 * tol
        )
        record(
            "projective_homography", kind, _vm(g.projective_homography)(H, A), ref_p, scale, 8 * tol
        )

        # Nath et al.: camera_parameters, feature_in_camera, the regressors (9), (10), (12)
        R_b, R_c = _rotations(rng, n), _rotations(rng, n)
        x_b, x_c, omega = (rng.normal(size=(n, 3)) for _ in range(3))
        if kind == "near_degenerate":  # far from the origin, features near the platform
            x_b *= 10.0 ** rng.uniform(3, 8, (n, 1))
            omega = x_b + 10.0 ** rng.uniform(-6, 0, (n, 1)) * rng.normal(size=(n, 3))
        A = intrinsics()
        R_b, R_c, x_b, x_c, omega, A = cast(*_poison(rng, kind, R_b, R_c, x_b, x_c, omega, A))
        Rbf, Rcf, xbf, xcf, omf, Af = f64(R_b, R_c, x_b, x_c, omega, A)
        M = Af @ Rcf.transpose(0, 2, 1)
        b = -np.einsum("nij,nj->ni", M, xcf)
        r3 = Rcf.transpose(0, 2, 1)[:, 2]
        th1 = np.concatenate([M.reshape(n, 9), b], 1)
        th2 = np.concatenate([r3, -np.sum(r3 * xcf, 1, keepdims=True)], 1)
        c1, c2 = _vm(g.camera_parameters)(A, R_c, x_c)
        sc = (norm(Af) + 1.0) * (norm(xcf) + 1.0)
        record(
            "camera_parameters",
            kind,
            np.concatenate([c1, c2], 1),
            np.concatenate([th1, th2], 1),
            sc,
            8 * tol,
        )
        q = np.einsum("nji,nj->ni", Rbf, omf - xbf)
        ref = np.einsum("nji,nj->ni", Rcf, q - xcf)
        sc = norm(omf) + norm(xbf) + norm(xcf)
        record(
            "feature_in_camera",
            kind,
            _vm(g.feature_in_camera)(omega, R_b, x_b, R_c, x_c),
            ref,
            sc,
            8 * tol,
        )
        th1c, th2c = cast(th1, th2)
        W, Pi = _vm(g.unknown_feature_regressors)(R_b, x_b, th1c, th2c)
        Mc, bc = th1c.astype(float)[:, :9].reshape(n, 3, 3), th1c.astype(float)[:, 9:]
        r3c, cc = th2c.astype(float)[:, :3], th2c.astype(float)[:, 3]
        MR = Mc @ Rbf.transpose(0, 2, 1)
        W_ref = np.concatenate([MR, (bc - np.einsum("nij,nj->ni", MR, xbf))[:, :, None]], 2)
        rR = np.einsum("ni,nji->nj", r3c, Rbf)
        Pi_ref = np.concatenate([rR, (cc - np.sum(rR * xbf, 1))[:, None]], 1)[:, None]
        sc = (norm(th1c) + 1.0) * (norm(xbf) + 1.0)
        record(
            "unknown_feature_regressors",
            kind,
            np.concatenate([np.reshape(W, (n, -1)), np.reshape(Pi, (n, -1))], 1),
            np.concatenate([W_ref.reshape(n, -1), Pi_ref.reshape(n, -1)], 1),
            sc,
            8 * tol,
        )
        W, Pi = _vm(g.known_feature_regressors)(R_b, x_b, omega)
        W_ref = np.concatenate(
            [
                np.einsum("ij,nk->nijk", np.eye(3), q).reshape(n, 3, 9),
                np.tile(np.eye(3), (n, 1, 1)),
            ],
            2,
        )
        # NaN in q reaches every W entry of its row block only through the kron: NumPy's
        # einsum with the identity leaves 0 * NaN = NaN in the off-diagonal blocks too
        Pi_ref = np.concatenate([q, np.ones((n, 1))], 1)[:, None]
        record(
            "known_feature_regressors",
            kind,
            np.concatenate([np.reshape(W, (n, -1)), np.reshape(Pi, (n, -1))], 1),
            np.concatenate([W_ref.reshape(n, -1), Pi_ref.reshape(n, -1)], 1),
            norm(omf) + norm(xbf),
            8 * tol,
        )
        # camera_from_parameters (footnote 3): the camera back from theta_c1
        # times any nonzero scale; against the true camera, or for invalid input against
        # the same RQ formula in NumPy (where a NaN reaches)
        lam = rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-2, 2, n)
        if kind == "near_degenerate":
            lam = rng.choice([-1, 1], n) * 10.0 ** rng.uniform(-12, 12, n)
        Rc_true, xc_true = _rotations(rng, n), rng.normal(size=(n, 3)) * 0.2
        A_true = intrinsics()
        Mt = A_true @ Rc_true.transpose(0, 2, 1)
        t1 = np.concatenate([Mt.reshape(n, 9), -np.einsum("nij,nj->ni", Mt, xc_true)], 1)
        (t1,) = cast(*_poison(rng, kind, t1 * lam[:, None]))
        got = np.concatenate([np.reshape(x, (n, -1)) for x in _vm(g.camera_from_parameters)(t1)], 1)
        if kind == "invalid":
            (t1f,) = f64(t1)
            M = t1f[:, :9].reshape(n, 3, 3)
            with np.errstate(all="ignore"):
                sgn = np.where(np.linalg.det(M) < 0, -1.0, 1.0)
                sgn[~np.all(np.isfinite(M.reshape(n, -1)), 1)] = np.nan
                k = sgn / np.linalg.norm(M[:, 2], axis=1)
                M, b = M * k[:, None, None], t1f[:, 9:] * k[:, None]
                r3 = M[:, 2]
                a12 = np.sum(M[:, 1] * r3, 1)
                v = M[:, 1] - a12[:, None] * r3
                a11 = np.linalg.norm(v, axis=1)
                r2 = v / a11[:, None]
                a01, a02 = np.sum(M[:, 0] * r2, 1), np.sum(M[:, 0] * r3, 1)
                u = M[:, 0] - a01[:, None] * r2 - a02[:, None] * r3
                a00 = np.linalg.norm(u, axis=1)
                r1 = u / a00[:, None]
                A_ref = np.zeros((n, 3, 3))
                A_ref[:, 0] = np.stack([a00, a01, a02], 1)
                A_ref[:, 1, 1:] = np.stack([a11, a12], 1)
                A_ref[:, 2, 2] = 1.0
                R_ref = np.stack([r1, r2, r3], 1).transpose(0, 2, 1)
                y1 = (b[:, 1] - a12 * b[:, 2]) / a11
                y0 = (b[:, 0] - a01 * y1 - a02 * b[:, 2]) / a00
                x_ref = -(r1 * y0[:, None] + r2 * y1[:, None] + r3 * b[:, 2:])
            ref = np.concatenate([A_ref.reshape(n, -1), R_ref.reshape(n, -1), x_ref], 1)
            record("camera_from_parameters", kind, got, ref, norm(ref), 1e3 * tol)
        else:
            ref = np.concatenate([A_true.reshape(n, -1), Rc_true.reshape(n, -1), xc_true], 1)
            # the RQ factorisation's error grows with the conditioning of A (focal lengths
            # spanning 10..1e4 px against unit rows)
            record("camera_from_parameters", kind, got, ref, norm(ref), 1e5 * tol)
    return out


def fuzz_select_solution(n, seed, dtype):
    """`select_solution` on the four solutions of `decompose_homography` (Chitrakaran et
    al., eq. (12)): with the true normal as prior it must pick the true solution; with
    an uninformative prior, a solution with every reference point in front of the plane
    (eq. (4)); with a NaN or inf anywhere, `ok` false."""
    import numpy as np

    from visjax.geometry import decompose_homography, select_solution
    from visjax.sim import random_planar_scenes

    rng = np.random.default_rng(seed + 13)
    decompose = _vm(lambda H: decompose_homography(H))
    select = _vm(select_solution)
    tol = 1e-6 if dtype == "float64" else 1e-2
    out = {}
    for kind in KINDS:
        sc = random_planar_scenes(n, 4, seed=seed + 13)
        Rs, ts, ns = (np.array(x) for x in decompose(np.asarray(sc.H, dtype)))
        A = np.asarray(sc.A, float)
        h = np.concatenate([sc.p_ref, np.ones((n, 4, 1))], -1)
        m_ref = np.einsum("nij,nkj->nki", np.linalg.inv(A), h)
        # the true normal as prior must pick the true solution (a noisy prior may rightly
        # pick the other physical one: two normals can be a few degrees apart)
        prior = sc.n_star.copy()
        if kind == "near_degenerate":
            prior = rng.normal(size=(n, 3))  # uninformative: either physical solution
        m_ref, prior = np.asarray(m_ref, dtype), np.asarray(prior, dtype)
        Rs, ts, ns, m_ref, prior = _poison(rng, kind, Rs, ts, ns, m_ref, prior)
        R, t, nn, ok = (np.asarray(x) for x in select(Rs, ts, ns, m_ref, prior))
        finite = np.all(np.isfinite(R.reshape(n, -1)), 1) & np.all(np.isfinite(t), 1)
        finite &= np.all(np.isfinite(nn), 1)
        if kind == "well_posed":
            err = np.max(np.abs(nn - sc.n_star), 1)
        else:
            in_front = np.all(np.einsum("nki,ni->nk", m_ref.astype(float), nn) > 0, 1)
            err = np.where(in_front, 0.0, np.inf)
        if kind == "invalid":
            ok_inv = ok.astype(bool)
            c = _counts()
            c["result_code"] = int(np.sum(~ok_inv))
            c["silent_nonfinite"] = int(np.sum(ok_inv & ~finite))
            c["silently_wrong"] = int(np.sum(ok_inv & finite))  # a NaN input decided it
        else:
            c = _counts()
            _classify(ok.astype(bool), finite, err, tol, c)
        out.setdefault("select_solution", {})[kind] = c
    return out


def fuzz_camera_matrix_lstsq(n, seed, dtype):
    """`camera_matrix_lstsq` (Jang, section 2.3) on exact data from a random camera matrix:
    well-posed (points over the image), near-degenerate (offset, narrow data: 1e-3 wide),
    invalid (a NaN or inf coordinate, or no variation along an axis: it must raise).
    Errors relative to the largest entry of theta, against the conditioning of the data."""
    import jax
    import numpy as np

    from visjax.geometry import camera_matrix_lstsq

    rng = np.random.default_rng(seed + 17)
    k = 12
    eps = float(np.finfo(dtype).eps)
    single = jax.jit(lambda m, p: camera_matrix_lstsq(m, p).theta)
    batched = _vm(lambda m, p: camera_matrix_lstsq(m, p).theta)
    out = {}
    for kind in KINDS:
        theta = np.stack(
            [
                rng.uniform(300, 1500, n),
                rng.uniform(300, 1500, n),
                rng.uniform(200, 500, n),
                rng.uniform(150, 400, n),
            ],
            1,
        )
        width = 1e-3 if kind == "near_degenerate" else 0.5
        centre = rng.uniform(-0.4, 0.4, (n, 1, 2)) if kind == "near_degenerate" else 0.0
        m = centre + width * rng.uniform(-1, 1, (n, k, 2))
        p = m * theta[:, None, :2] + theta[:, None, 2:]
        if kind == "invalid":
            flat = rng.random(n) < 0.3
            axis = rng.integers(0, 2, n)
            m[flat, :, axis[flat]] = m[flat, :1, axis[flat]]
            m[~flat], p[~flat] = _poison(rng, kind, m[~flat], p[~flat])
        m, p = np.asarray(m, dtype), np.asarray(p, dtype)
        # conditioning of a centred 1-D fit: |x| / spread of x, times the data's scale
        cond = 1.0 + np.max(np.abs(m.astype(float)), (1, 2)) / width
        tol = 1e3 * eps * cond
        c = _counts()
        try:
            est = np.asarray(batched(m, p), float)
            raised = np.zeros(n, bool)
        except (RuntimeError, ValueError):  # see docs/errors.md: JAX's fast path
            est, raised = np.full((n, 4), np.nan), np.zeros(n, bool)
            for i in range(n):  # which inputs raise: one at a time
                try:
                    est[i] = np.asarray(single(m[i], p[i]), float)
                except (RuntimeError, ValueError):  # see docs/errors.md: JAX's fast path
                    raised[i] = True
        c["clear_error"] = int(np.sum(raised))
        keep = ~raised
        err = np.max(np.abs(est - theta), 1) / np.max(np.abs(theta), 1)
        finite = np.all(np.isfinite(est), 1)
        sub = _counts()
        _classify(np.ones(int(np.sum(keep)), bool), finite[keep], err[keep], tol[keep], sub)
        for key in ("correct", "silent_nonfinite", "silently_wrong"):
            c[key] += sub[key]
        if kind == "invalid":  # an invalid input that did not raise is silently wrong
            c["silently_wrong"] += c.pop("correct")
            c["correct"] = 0
        out.setdefault("camera_matrix_lstsq", {})[kind] = c
    return out


def _run_flags(run_one, streams, expected, counts):
    """Invalid samples: `run` must stop with `nonfinite_measurement` at `expected`."""
    import numpy as np

    from visjax import RESULTS

    code, failed = (np.asarray(x) for x in run_one(*streams))
    flagged = (code == int(RESULTS.nonfinite_measurement._value)) & (failed == expected)
    counts["result_code"] += int(np.sum(flagged))
    counts["silently_wrong"] += int(np.sum(~flagged))


def fuzz_streams(n, seed, dtype):
    """The three stream builders on windows of 8 samples of the papers' scenarios:
    well-posed (samples far apart), near-degenerate (consecutive 1 kHz samples: motion of
    a few thousandths of a pixel; or extreme camera matrices and coordinates), invalid (one
    NaN or inf in one sample: the stream keeps it non-finite or NaN-fills that frame, and
    `run` stops there with `nonfinite_measurement`, at the right sample)."""
    import numpy as np
    from scipy.spatial.transform import Rotation

    from visjax import RESULTS
    from visjax.estimators import (
        SaveAt,
        VelocityEstimator,
        fixed_camera,
        moving_point_stream,
        run,
        static_points_stream,
        velocity_stream,
    )
    from visjax.papers import chitrakaran, jang, nath

    rng = np.random.default_rng(seed + 19)
    T = 8
    out = {}
    ok_code = int(RESULTS.successful._value)
    cast = lambda *xs: [np.asarray(x, dtype) for x in xs]  # noqa: E731

    def windows(N, step):
        start = rng.integers(0, N - (T - 1) * step, n)
        return start[:, None] + step * np.arange(T)[None, :]

    def run_result(est, dt=None):
        def go(stream):
            sol = run(est, stream, dt=dt, saveat=SaveAt(outputs=False), throw=False)
            return sol.result._value, sol.failed_sample

        return go

    # velocity_stream (Chitrakaran et al.): e against the true motion (eqs. (18)-(28))
    sc = chitrakaran.section6_scenario(10.0, 1000.0)
    P, R, x_f, s = (np.asarray(v, float) for v in (sc.pixels, sc.R, sc.x_f, sc.s))
    A = np.asarray(sc.A, dtype)
    n_obj = np.cross(s[0], s[1])
    est_v = VelocityEstimator(K=chitrakaran.K_EQ63, rho=chitrakaran.RHO_EQ63)
    ts = np.asarray(np.arange(T) * 1e-3, dtype)

    def fixed(pixels, R_star, n_star, z1_star):
        camera = fixed_camera(
            pixels, A, R_star, np.asarray(s[0], dtype), n_star=n_star, z1_star=z1_star, throw=False
        )
        stream = velocity_stream(ts, pixels, camera, throw=False)
        return stream

    build_fixed = _vm(lambda *a: fixed(*a).measured().ys)
    run_fixed = _vm(lambda *a: run_result(est_v)(fixed(*a)))
    tol_e = 1e-7 if dtype == "float64" else 5e-2
    for kind in KINDS:
        k = windows(P.shape[0], 1 if kind == "near_degenerate" else 1200)
        k0 = k[:, 0]
        pixels = P[k].copy()
        m1 = x_f[k] + np.einsum("ntij,j->nti", R[k], s[0])
        n_star = np.einsum("nij,j->ni", R[k0], n_obj)
        n_star *= np.sign(np.sum(n_star * m1[:, 0], 1))[:, None]
        n_star /= np.linalg.norm(n_star, axis=1, keepdims=True)
        e_true = np.concatenate(
            [
                pixels[:, :, 0] - pixels[:, :1, 0],
                np.log(m1[..., 2] / m1[:, :1, 2])[..., None],
                Rotation.from_matrix(np.einsum("ntij,nkj->ntik", R[k], R[k0]).reshape(-1, 3, 3))
                .as_rotvec()
                .reshape(n, T, 3),
            ],
            -1,
        )
        bad_frame = rng.integers(0, T, n)
        if kind == "invalid":
            pixels[np.arange(n), bad_frame, rng.integers(0, 4, n), rng.integers(0, 2, n)] = (
                rng.choice([np.nan, np.inf, -np.inf], n)
            )
        args = cast(pixels, R[k0], n_star, m1[:, 0, 2])
        c = _counts()
        if kind == "invalid":
            _run_flags(run_fixed, args, bad_frame, c)
        else:
            ys = build_fixed(*args)
            e = np.asarray(ys.e, float)
            ok = np.all(np.asarray(ys.result._value) == ok_code, 1)
            scale = np.maximum(np.max(np.abs(e_true), (1, 2)), 1.0)
            err = np.max(np.abs(e - e_true), (1, 2)) / scale
            _classify(ok, np.all(np.isfinite(e.reshape(n, -1)), 1), err, tol_e, c)
        out.setdefault("velocity_stream", {})[kind] = c

    # moving_point_stream (Jang): y = K_c^{-1} p (eq. (3.1)), u passed through
    th = jang.scenario("II.1", 10.0)
    F_p, F_u = np.asarray(th.frame_pixels, float), np.asarray(th.frame_velocities, float)
    observer = jang.observer("II.1")
    # 33 ms frames (a 30.3 Hz camera): the last one on the 1 ms grid, so `run` reaches it
    frame_ts = np.asarray(np.arange(T) * 0.033, dtype)

    def moving(pixels, velocities, K_c):
        return moving_point_stream(frame_ts, pixels, velocities, K_c, throw=False)

    build_moving = _vm(lambda *a: moving(*a).ys)
    run_moving = _vm(lambda *a: run_result(observer, 1e-3)(moving(*a)))
    for kind in KINDS:
        k = windows(F_p.shape[0], 1)
        pixels, velocities = F_p[k].copy(), F_u[k].copy()
        K_c = np.tile(np.asarray(th.Kc_observer, float), (n, 1, 1))
        if kind == "near_degenerate":  # extreme focal lengths and pixel coordinates
            K_c[:, 0, 0] *= 10.0 ** rng.uniform(-6, 6, n)
            K_c[:, 1, 1] *= 10.0 ** rng.uniform(-6, 6, n)
            pixels *= 10.0 ** rng.uniform(-3, 5, (n, 1, 1))
        bad_frame = rng.integers(0, T, n)
        if kind == "invalid":
            target = rng.random(n) < 0.5
            i = np.arange(n)
            pixels[i[target], bad_frame[target], rng.integers(0, 2)] = np.nan
            velocities[i[~target], bad_frame[~target], rng.integers(0, 6)] = rng.choice(
                [np.nan, np.inf, -np.inf], int(np.sum(~target))
            )
        args = cast(pixels, velocities, K_c)
        c = _counts()
        if kind == "invalid":
            _run_flags(run_moving, args, bad_frame, c)
        else:
            ys = build_moving(*args)
            pf, Kf = args[0].astype(float), args[2].astype(float)
            y_ref = np.linalg.solve(
                Kf[:, None], np.concatenate([pf, np.ones((n, T, 1))], -1)[..., None]
            )[..., :2, 0]
            y = np.asarray(ys.y, float)
            scale = np.maximum(np.max(np.abs(y_ref), (1, 2)), 1e-300)
            err = np.max(np.abs(y - y_ref), (1, 2)) / scale
            err = np.maximum(err, np.max(np.abs(np.asarray(ys.u, float) - args[1]), (1, 2)))
            finite = np.all(np.isfinite(y.reshape(n, -1)), 1)
            _classify(np.ones(n, bool), finite, err, 64 * float(np.finfo(dtype).eps), c)
        out.setdefault("moving_point_stream", {})[kind] = c

    # static_points_stream (Nath et al.): the known features' regressors (eq. (12))
    ns = nath.scenario(2.0)
    R_b, x_b, p_s, p_c = (np.asarray(v, float) for v in (ns.R_b, ns.x_b, ns.p_s, ns.p_c))
    omega_c = np.asarray(ns.omega_c, float)
    est_a = nath.initial_estimator(ns)
    ts = np.asarray(np.arange(T) * 1e-3, dtype)

    def platform(R_b, x_b, p_s, p_c, omega_c):
        return static_points_stream(ts, R_b, x_b, p_s, p_c, omega_c, throw=False)

    build_platform = _vm(lambda *a: platform(*a).ys)
    run_platform = _vm(lambda *a: run_result(est_a)(platform(*a)))
    for kind in KINDS:
        k = windows(R_b.shape[0], 1 if kind == "near_degenerate" else 250)
        args = [
            R_b[k].copy(),
            x_b[k].copy(),
            p_s[k].copy(),
            p_c[k].copy(),
            np.tile(omega_c, (n, 1, 1)),
        ]
        if kind == "near_degenerate":  # far from the world origin
            offset = rng.normal(size=(n, 1, 3)) * 10.0 ** rng.uniform(2, 6, (n, 1, 1))
            args[1] = args[1] + offset
            args[4] = args[4] + offset
        bad_frame = rng.integers(0, T, n)
        if kind == "invalid":
            which = rng.integers(0, 4, n)
            bad = rng.choice([np.nan, np.inf, -np.inf], n)
            # a NaN pixel is a feature out of view (masked in both laws, the run goes on):
            # the invalid pixels here are infinite
            bad = np.where((which >= 2) & np.isnan(bad), np.inf, bad)
            for i in range(n):
                a = args[which[i]][i, bad_frame[i]]
                a.reshape(-1)[rng.integers(0, a.size)] = bad[i]
        args = cast(*args)
        c = _counts()
        if kind == "invalid":
            _run_flags(run_platform, args, bad_frame, c)
        else:
            ys = build_platform(*args)
            Rf, xf, of = (a.astype(float) for a in (args[0], args[1], args[4]))
            q = np.einsum("ntji,ntmj->ntmi", Rf, of[:, None] - xf[:, :, None])
            W_ref = np.concatenate(
                [
                    np.einsum("ij,ntmk->ntmijk", np.eye(3), q).reshape(n, T, -1, 3, 9),
                    np.broadcast_to(np.eye(3), q.shape[:3] + (3, 3)),
                ],
                -1,
            )
            Pi_ref = np.concatenate([q, np.ones(q.shape[:3] + (1,))], -1)
            W, Pi = np.asarray(ys.W_x, float), np.asarray(ys.Pi_x, float)
            scale = np.max(np.abs(of), (1, 2)) + np.max(np.abs(xf), (1, 2))
            err = (
                np.maximum(
                    np.max(np.abs(W - W_ref).reshape(n, -1), 1),
                    np.max(np.abs(Pi - Pi_ref).reshape(n, -1), 1),
                )
                / scale
            )
            finite = np.all(np.isfinite(W.reshape(n, -1)), 1) & np.all(
                np.isfinite(Pi.reshape(n, -1)), 1
            )
            _classify(np.ones(n, bool), finite, err, 64 * float(np.finfo(dtype).eps), c)
        out.setdefault("static_points_stream", {})[kind] = c
    return out


def fuzz_sl3(n, seed, dtype):
    """SL(3): `sl3_project` against $M - \\mathrm{tr}(M)/3\\, I$ in NumPy (well-posed:
    entries 1e-3..1e3; near-degenerate: 1e-12..1e12); `sl3_exp` against SciPy's `expm`
    of the projection (well-posed: norms up to 3; near-degenerate: tiny norms, 1e-12..1e-3,
    and large ones, 10..30); `sl3_normalize` against $H / \\det(H)^{1/3}$ (well-posed:
    well-conditioned matrices; near-degenerate: the same scaled by 1e-12..1e12). Invalid:
    a NaN or inf entry; `sl3_exp` and `sl3_normalize` then give NaN (a result code)."""
    import numpy as np
    import scipy.linalg

    from visjax import geometry as g

    rng = np.random.default_rng(seed + 23)
    eps = float(np.finfo(dtype).eps)
    out = {}
    for kind in KINDS:
        # the projection: linear, no error path (NaN and inf reach the entries they touch)
        (M,) = _poison(rng, kind, _magnitudes(rng, kind, n, (3, 3)))
        M = np.asarray(M, dtype)
        Mf = M.astype(float)
        with np.errstate(invalid="ignore"):
            ref = Mf - np.trace(Mf, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
        scale = np.maximum(np.max(np.where(np.isfinite(Mf), np.abs(Mf), 0.0), (1, 2)), 1e-300)
        c = _counts()
        _against_reference(c, kind, _vm(g.sl3_project)(M), ref, scale, 64 * eps)
        out.setdefault("sl3_project", {})[kind] = c

        # the exponential
        X = rng.normal(size=(n, 3, 3))
        X /= np.linalg.norm(X, axis=(1, 2), keepdims=True)
        if kind == "near_degenerate":
            big = rng.random(n) < 0.5
            size = np.where(big, rng.uniform(10, 30, n), 10.0 ** rng.uniform(-12, -3, n))
        else:
            size = rng.uniform(0, 3, n)
        X = X * size[:, None, None]
        (X,) = _poison(rng, kind, X)
        X = np.asarray(X, dtype)
        E = np.asarray(_vm(g.sl3_exp)(X), float)
        c = _counts()
        if kind == "invalid":
            _nan_in_nan_out(c, E)
        else:
            Xf = X.astype(float)
            Y = Xf - np.trace(Xf, axis1=1, axis2=2)[:, None, None] / 3.0 * np.eye(3)
            ref = np.stack([scipy.linalg.expm(y) for y in Y])
            err = np.max(np.abs(E - ref), (1, 2)) / np.max(np.abs(ref), (1, 2))
            # rounding grows with the squarings (up to 12) and the norm
            tol = 1e3 * eps * (1.0 + np.linalg.norm(Y, axis=(1, 2)))
            finite = np.all(np.isfinite(E.reshape(n, -1)), 1)
            _classify(np.ones(n, bool), finite, err / tol, 1.0, c)
        out.setdefault("sl3_exp", {})[kind] = c

        # the unit-determinant representative
        H = _rotations(rng, n) + 0.3 * rng.normal(size=(n, 3, 3))
        if kind == "near_degenerate":
            H = H * (10.0 ** rng.uniform(-12, 12, n))[:, None, None]
        (H,) = _poison(rng, kind, H)
        H = np.asarray(H, dtype)
        N = np.asarray(_vm(g.sl3_normalize)(H), float)
        c = _counts()
        if kind == "invalid":
            _nan_in_nan_out(c, N)
        else:
            Hf = H.astype(float)
            d = np.linalg.det(Hf / np.max(np.abs(Hf), (1, 2))[:, None, None])
            ref = Hf / np.max(np.abs(Hf), (1, 2))[:, None, None] / np.cbrt(d)[:, None, None]
            cond = np.linalg.cond(Hf)
            err = np.max(np.abs(N - ref), (1, 2)) / np.max(np.abs(ref), (1, 2))
            ok = np.all(np.isfinite(N.reshape(n, -1)), 1)  # NaN: a singular matrix's code
            _classify(ok, ok, err / (64 * eps * cond), 1.0, c)
        out.setdefault("sl3_normalize", {})[kind] = c
    return out


def fuzz_distortion(n, seed, dtype):
    """`distort_pixels` against OpenCV's `cv2.projectPoints` (the same lens model, one call
    per element), `undistort_pixels` by the round trip; near-degenerate: strong barrel
    distortion out to the image's corners, where a pixel may have no point (NaN, the
    documented answer); invalid: non-finite pixels or coefficients (NaN out)."""
    import cv2
    import numpy as np

    from visjax.geometry import distort_pixels, undistort_pixels

    rng = np.random.default_rng(seed)
    A1 = np.array([[800.0, 0.0, 320.0], [0.0, 790.0, 240.0], [0, 0, 1]])
    out = {}
    tol = 1e-9 if dtype == "float64" else 2e-4  # relative to the pixel's size
    for kind in KINDS:
        p = np.c_[rng.uniform(0, 640, n), rng.uniform(0, 480, n)]
        dist = np.c_[rng.uniform(-0.3, 0.1, n), rng.uniform(-0.05, 0.05, (n, 3)) * [1, 0.02, 0.02],
                     rng.uniform(-0.01, 0.01, n)]  # fmt: skip
        if kind == "near_degenerate":
            dist[:, 0] = rng.uniform(-0.45, -0.35, n)  # strong barrel, out to the corners
            p = np.c_[rng.choice([0.0, 640.0], n), rng.choice([0.0, 480.0], n)] + rng.normal(
                0, 5, (n, 2)
            )
        elif kind == "invalid":
            which = rng.integers(0, 2, n)
            p[which == 0, rng.integers(0, 2)] = rng.choice([np.nan, np.inf], np.sum(which == 0))
            dist[which == 1, 0] = np.nan
        A = np.tile(A1, (n, 1, 1))
        cast = lambda x: np.asarray(x, dtype)  # noqa: E731
        d = np.asarray(_vm(distort_pixels)(cast(p), cast(A), cast(dist)), float)
        u = np.asarray(_vm(undistort_pixels)(cast(d), cast(A), cast(dist)), float)
        if kind == "invalid":
            for name, got in (("distort_pixels", d), ("undistort_pixels", u)):
                c = _counts()
                _nan_in_nan_out(c, got)
                out.setdefault(name, {})[kind] = c
            continue
        truth = np.stack([
            cv2.projectPoints(np.linalg.solve(A1, [*pk, 1.0])[None], np.zeros(3), np.zeros(3), A1,
                              dk)[0][0, 0] for pk, dk in zip(p, dist)
        ])  # fmt: skip
        scale = np.maximum(np.max(np.abs(truth), 1), 1.0)
        with np.errstate(all="ignore"):
            c = _counts()
            _classify(np.ones(n, bool), np.all(np.isfinite(d), 1),
                      np.max(np.abs(d - truth), 1) / scale, tol, c)  # fmt: skip
            out.setdefault("distort_pixels", {})[kind] = c
            found = np.all(np.isfinite(u), 1)  # NaN: no point gives the pixel (documented)
            c = _counts()
            _classify(found, found, np.max(np.abs(u - p), 1) / scale, tol, c)
            out.setdefault("undistort_pixels", {})[kind] = c
    return out


PARTS = (
    "fuzz_reconstruction",
    "fuzz_camera",
    "fuzz_distortion",
    "fuzz_so3",
    "fuzz_decomposition",
    "fuzz_so3_helpers",
    "fuzz_sl3",
    "fuzz_algebra",
    "fuzz_select_solution",
    "fuzz_camera_matrix_lstsq",
    "fuzz_streams",
)


def fuzz(n: int, seed: int, dtype: str, batch: int | None = None, parts=PARTS) -> dict:
    """Run every part on `n` inputs per function and kind, vmapped in batches of `batch`
    (default: all `n` at once)."""
    _BATCH[0] = batch
    results = {}
    for part in parts:
        results.update(globals()[part](n, seed, dtype))
    totals = _counts()
    for per_kind in results.values():
        for c in per_kind.values():
            for k in CATEGORIES:
                totals[k] += c[k]
    return {
        "n_per_kind": n,
        "batch": batch or n,
        "dtype": dtype,
        "seed": seed,
        "functions": results,
        "totals": totals,
    }
