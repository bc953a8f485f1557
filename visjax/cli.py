"""The `visjax` command line.

`visjax geometry`: random planar scenes, Euclidean reconstruction (seed 000, section 3) with
visjax and with OpenCV, errors of both against ground truth.
"""

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def _enable_x64():
    import jax

    jax.config.update("jax_enable_x64", True)


def _angle_deg(R_est, R_true):
    """Angle of R_est^T R_true, by atan2 (arccos loses half the digits near 0)."""
    E = np.swapaxes(R_est, -1, -2) @ R_true
    s = np.stack(
        [E[..., 2, 1] - E[..., 1, 2], E[..., 0, 2] - E[..., 2, 0], E[..., 1, 0] - E[..., 0, 1]], -1
    )
    c = np.trace(E, axis1=-2, axis2=-1) - 1.0
    return np.rad2deg(np.arctan2(np.linalg.norm(s, axis=-1), c))


def _normal_deg(n_est, n_true):
    s = np.linalg.norm(np.cross(n_est, n_true), axis=-1)
    return np.rad2deg(np.arctan2(s, np.sum(n_est * n_true, -1)))


def _opencv_reconstruction(p_ref, p_cur, A, n_prior):
    """The same pipeline with OpenCV: findHomography (method 0), decomposeHomographyMat, and the
    selection rule of visjax (reference points in front, then the normal closest to the prior).
    """
    import cv2

    G, _ = cv2.findHomography(p_ref, p_cur, 0)
    beta = 1.0 / (np.c_[p_ref, np.ones(len(p_ref))] @ G[2])  # alpha_i g33, eq. (17)
    count, Rs, ts, ns = cv2.decomposeHomographyMat(G, A)
    m_ref = np.linalg.solve(A, np.c_[p_ref, np.ones(len(p_ref))].T).T
    best, best_score = 0, -np.inf
    for k in range(count):
        n = ns[k].ravel()
        if np.all(m_ref @ n > 0) and n @ n_prior > best_score:
            best, best_score = k, n @ n_prior
    H = np.linalg.solve(A, G @ A)
    g33 = np.sign(beta[0]) / np.linalg.svd(H, compute_uv=False)[1]
    return {
        "R_bar": Rs[best],
        "x_h": ts[best].ravel(),
        "n_star": ns[best].ravel() if count > 1 else n_prior,
        "alpha": beta / g33,
        "H": g33 * H,
    }


def _errors(est, sc):
    """Per-scene errors against ground truth."""
    return {
        "H_max_abs": np.max(np.abs(est["H"] - sc.H), axis=(-2, -1)),
        "R_bar_deg": _angle_deg(est["R_bar"], sc.R_bar),
        "x_h_abs": np.linalg.norm(est["x_h"] - sc.x_h, axis=-1),
        "n_star_deg": _normal_deg(est["n_star"], sc.n_star),
        "alpha_rel": np.max(np.abs(est["alpha"] / sc.alpha - 1.0), axis=-1),
    }


def geometry(args) -> dict:
    _enable_x64()
    import jax

    from .geometry import euclidean_reconstruction
    from .sim import random_planar_scenes

    sc = random_planar_scenes(args.scenes, args.points, seed=args.seed, noise_px=args.noise)
    rng = np.random.default_rng(args.seed + 1)
    # A rough prior of the plane normal (about 1 degree off) picks between the two physical
    # decompositions; both pipelines get the same one.
    prior = sc.n_star + 0.02 * rng.normal(size=sc.n_star.shape)

    recon = jax.jit(jax.vmap(euclidean_reconstruction))
    t0 = time.perf_counter()
    jax.block_until_ready(recon(sc.p_ref, sc.p_cur, sc.A, prior))
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    rec = jax.block_until_ready(recon(sc.p_ref, sc.p_cur, sc.A, prior))
    t_visjax = time.perf_counter() - t0
    ours = {k: np.asarray(getattr(rec, k)) for k in ("R_bar", "x_h", "n_star", "alpha", "H")}

    t0 = time.perf_counter()
    cv = [
        _opencv_reconstruction(sc.p_ref[i], sc.p_cur[i], sc.A[i], prior[i]) for i in range(len(sc))
    ]
    t_cv = time.perf_counter() - t0
    theirs = {k: np.stack([c[k] for c in cv]) for k in cv[0]}

    errors = {"visjax": _errors(ours, sc), "opencv": _errors(theirs, sc)}
    summary = {
        "scenes": args.scenes,
        "points": args.points,
        "noise_px": args.noise,
        "seed": args.seed,
        "seconds": {"visjax_compile": t_compile, "visjax": t_visjax, "opencv": t_cv},
        "errors": {
            who: {
                k: {"median": float(np.median(v)), "max": float(np.max(v))} for k, v in errs.items()
            }
            for who, errs in errors.items()
        },
    }

    title = (
        f"Euclidean reconstruction (seed 000, sec. 3): {args.scenes} random planar scenes, "
        f"{args.points} points, pixel noise {args.noise} px"
    )
    print(title)
    print(
        f"{'error vs ground truth':<22}{'visjax median':>15}{'visjax max':>13}"
        f"{'OpenCV median':>15}{'OpenCV max':>13}"
    )
    for k in errors["visjax"]:
        v, c = summary["errors"]["visjax"][k], summary["errors"]["opencv"][k]
        print(f"{k:<22}{v['median']:>15.3e}{v['max']:>13.3e}{c['median']:>15.3e}{c['max']:>13.3e}")
    s = summary["seconds"]
    print(
        f"time: visjax {s['visjax'] * 1e3:.2f} ms batched (+{s['visjax_compile']:.1f} s compile), "
        f"OpenCV {s['opencv'] * 1e3:.2f} ms loop"
    )

    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        _geometry_figure(sc, ours, errors, out / "geometry.png")
        print(f"wrote {out / 'summary.json'} and {out / 'geometry.png'}")
    return summary


def _geometry_figure(sc, ours, errors, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(11, 4.5))
    p_ref, p_cur = sc.p_ref[0], sc.p_cur[0]
    q = np.c_[p_ref, np.ones(len(p_ref))] @ (sc.A[0] @ ours["H"][0] @ np.linalg.inv(sc.A[0])).T
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
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="visjax", description="Vision-based nonlinear estimators in JAX."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser(
        "geometry",
        help="homography estimation and decomposition: visjax vs OpenCV vs ground truth",
    )
    g.add_argument("--scenes", type=int, default=100, help="random planar scenes (default 100)")
    g.add_argument("--points", type=int, default=4, help="points per scene, >= 4 (default 4)")
    g.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma in px (default 0)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--out", type=str, default=None, help="directory for summary.json and figure")
    g.set_defaults(func=geometry)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "points", 4) < 4:
        print("visjax: --points must be at least 4", file=sys.stderr)
        return 2
    args.func(args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
