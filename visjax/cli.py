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


def velocity(args) -> dict:
    _enable_x64()
    from tqdm import tqdm

    from .plots import plot_velocity
    from .studies import DOF_NAMES, summarise, velocity_experiment

    stages = tqdm(total=4, desc="velocity", unit="stage", disable=args.quiet)
    started = []

    def progress(stage):
        if started:
            stages.update()
        started.append(stage)
        stages.set_postfix_str(stage)

    r = velocity_experiment(
        args.duration,
        args.rate,
        args.noise,
        K=args.K,
        rho=args.rho,
        seed=args.seed,
        progress=progress,
    )
    summary = summarise(r, args.duration, args.rate, args.noise)
    summary["K"], summary["rho"] = list(args.K), list(args.rho)
    progress("figure")
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        title = (
            f"seed 000, section 6: {args.rate:g} Hz, {args.duration:g} s, "
            f"pixel noise {args.noise:g} px"
        )
        plot_velocity(r.ts, r.velocity, r.estimate, title=title, path=out / "velocity.png")
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()

    a, b = summary["window_s"]
    print(
        f"Velocity estimator (seed 000, eqs. 39-40), section-6 simulation: {args.duration:g} s at "
        f"{args.rate:g} Hz, pixel noise {args.noise:g} px"
    )
    print(f"recovered z1* = {summary['z1_star_recovered']:.6f} m")
    print(f"{'DOF':<6}{f'RMS {a:g}-{b:g} s':>16}{f'max {a:g}-{b:g} s':>16}")
    for name, rms, mx in zip(DOF_NAMES, summary["rms_5_10s"], summary["max_5_10s"]):
        unit = "m/s" if name.startswith("v") else "rad/s"
        print(f"{name:<6}{rms:>16.5f}{mx:>16.5f}  {unit}")
    if args.out is not None:
        print(f"wrote {Path(args.out) / 'summary.json'} and {Path(args.out) / 'velocity.png'}")
    return summary


def structure(args) -> dict:
    _enable_x64()
    from tqdm import tqdm

    from .plots import plot_structure
    from .sim import SETS
    from .studies import structure_experiment

    names = args.set or list(SETS)
    for name in names:
        if name not in SETS:
            raise SystemExit(f"visjax structure: unknown set {name!r}; choose from {list(SETS)}")
    out = None if args.out is None else Path(args.out)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    summary = {}
    for name in tqdm(names, desc="structure", unit="set", disable=args.quiet):
        r = structure_experiment(name, args.duration, args.noise, seed=args.seed)
        summary[name] = {
            "rms": [float(x) for x in r.rms],
            "thesis_rms": list(SETS[name].thesis_rms),
        }
        if out is not None:
            kind = "moving" if SETS[name].moving else "static"
            plot_structure(
                r.ts,
                r.position,
                r.estimate,
                path=out / f"structure_{name}.png",
                title=f"seed 003, set {name} ({kind} point), simulated: pixel noise "
                f"{args.noise:g} px, camera 30 Hz, observer 1 kHz",
            )
    print(
        f"UIO (seed 003, eq. 3.5), simulated analogues: {args.duration:g} s, pixel noise "
        f"{args.noise:g} px, RMS position error over the second half (m)"
    )
    for group, label in (("I.", "Table 5-3 (static point)"), ("II.", "Table 5-4 (moving point)")):
        sets = [n for n in names if n.startswith(group)]
        if not sets:
            continue
        print(f"\n{label}: visjax (thesis)")
        print(f"{'':<4}" + "".join(f"{n:>20}" for n in sets))
        for i, axis in enumerate("xyz"):
            row = "".join(
                f"{summary[n]['rms'][i]:>11.4f} ({summary[n]['thesis_rms'][i]:.4f})" for n in sets
            )
            print(f"{axis:<4}{row}")
    if out is not None:
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
        print(f"\nwrote {out / 'summary.json'} and structure_<set>.png")
    return summary


def euclidean(args) -> dict:
    _enable_x64()
    from tqdm import tqdm

    from .plots import plot_euclidean
    from .studies import euclidean_experiment, final_errors

    stages = tqdm(total=2, desc="euclidean", unit="stage", disable=args.quiet)
    stages.set_postfix_str("simulate and estimate (compiles once)")
    r = euclidean_experiment(args.duration, args.noise_px, seed=args.seed)
    stages.update()
    errors = final_errors(r)
    summary = {
        "final_position_error_m": [float(e) for e in errors],
        "duration_s": args.duration,
        "noise_px": args.noise_px,
        "final_camera_prediction_error_px": float(np.asarray(r.p_tilde_c[-1]).max()),
        "covariance_resets": int(r.resets[-1]),
    }
    stages.set_postfix_str("figure")
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        plot_euclidean(
            r,
            path=out / "euclidean.png",
            title=f"seed 004: adaptive LS structure, {args.duration:g} s at 1 kHz, "
            f"pixel noise {args.noise_px:g} px",
        )
        (out / "summary.json").write_text(json.dumps(summary, indent=2))
    stages.update()
    stages.close()
    print(
        f"Adaptive LS structure estimator (seed 004, eqs. 37-51): {args.duration:g} s at 1 kHz, "
        f"pixel noise {args.noise_px:g} px, uncalibrated camera"
    )
    for i, e in enumerate(errors):
        print(f"feature {i + 1}: final position error {e * 1000:8.3f} mm")
    print(
        f"camera prediction error {summary['final_camera_prediction_error_px']:.3f} px, "
        f"covariance resets {summary['covariance_resets']}"
    )
    if args.out is not None:
        print(f"wrote {Path(args.out) / 'summary.json'} and {Path(args.out) / 'euclidean.png'}")
    return summary


def reproduce(args) -> dict:
    """Every paper's main experiment into one folder, then a summary table."""
    out = Path(args.out)
    results = {}
    print("== seed 000, section 6: velocity estimator ==")
    results["velocity"] = velocity(
        argparse.Namespace(
            duration=10.0,
            rate=1000.0,
            noise=0.0,
            seed=0,
            K=_defaults()[0],
            rho=_defaults()[1],
            out=str(out / "velocity"),
            quiet=args.quiet,
        )
    )
    print("\n== seed 000, section 3: Euclidean reconstruction vs OpenCV ==")
    results["geometry"] = geometry(
        argparse.Namespace(
            scenes=20 if args.quick else 100,
            points=4,
            noise=0.0,
            seed=0,
            out=str(out / "geometry"),
        )
    )
    print("\n== seed 003: unknown input observer, the thesis' seven sets (simulated) ==")
    results["structure"] = structure(
        argparse.Namespace(
            set=None,
            duration=20.0 if args.quick else 30.0,
            noise=0.1,
            seed=0,
            out=str(out / "structure"),
            quiet=args.quiet,
        )
    )
    print("\n== seed 004: Euclidean structure from an uncalibrated moving camera ==")
    results["euclidean"] = euclidean(
        argparse.Namespace(
            noise_px=0.0,
            duration=20.0 if args.quick else 30.0,
            seed=0,
            out=str(out / "euclidean"),
            quiet=args.quiet,
        )
    )
    v, g = results["velocity"], results["geometry"]["errors"]
    rows = [
        ("000 velocity, max RMS 5-10 s (m/s, rad/s)", f"{max(v['rms_5_10s']):.4f}", "< 0.05"),
        ("000 z1* recovered (m)", f"{v['z1_star_recovered']:.6f}", "1.99"),
        (
            "000 reconstruction, max R_bar error (deg)",
            f"{g['visjax']['R_bar_deg']['max']:.1e}",
            f"OpenCV {g['opencv']['R_bar_deg']['max']:.1e}",
        ),
    ]
    st = results["structure"]
    static = [n for n in st if n.startswith("I.")]
    moving = [n for n in st if n.startswith("II.")]
    for names, what in ((static, "static"), (moving, "moving")):
        mean = float(np.mean([st[n]["rms"] for n in names]))
        thesis = float(np.mean([st[n]["thesis_rms"] for n in names]))
        rows.append((f"003 UIO {what} point, mean RMS (m)", f"{mean:.4f}", f"thesis {thesis:.4f}"))
    e = results["euclidean"]["final_position_error_m"]
    rows.append(("004 structure, max final position error (mm)", f"{max(e) * 1000:.3f}", "aim 1"))
    print("\n== summary ==")
    for name, value, ref in rows:
        print(f"{name:<46}{value:>12}   ({ref})")
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(
        json.dumps({"rows": [dict(zip(("what", "value", "reference"), r)) for r in rows]}, indent=2)
    )
    print(f"wrote {out}/ (velocity/, geometry/, structure/, euclidean/, summary.json)")
    return results


def _defaults():
    from .sim import K_EQ63, RHO_EQ63

    return list(K_EQ63), list(RHO_EQ63)


def _six(text: str) -> list[float]:
    values = [float(x) for x in text.replace(",", " ").split()]
    if len(values) != 6 or not all(v > 0 for v in values):
        raise argparse.ArgumentTypeError(
            f"expected six positive numbers (the diagonal), got {text!r}"
        )
    return values


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

    from .sim import K_EQ63, RHO_EQ63

    v = sub.add_parser(
        "velocity",
        help="seed 000: the fixed-camera velocity estimator on the section-6 simulation",
    )
    v.add_argument("--duration", type=float, default=10.0, help="seconds (default 10)")
    v.add_argument("--rate", type=float, default=1000.0, help="sample rate in Hz (default 1000)")
    v.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma in px (default 0)")
    v.add_argument("--seed", type=int, default=0, help="noise seed")
    v.add_argument(
        "--K",
        type=_six,
        default=list(K_EQ63),
        help='diagonal of K (default "300 300 200 15 15 15")',
    )
    v.add_argument(
        "--rho",
        type=_six,
        default=list(RHO_EQ63),
        help='diagonal of rho (default "100 100 10 1 1 1")',
    )
    v.add_argument("--out", type=str, default=None, help="directory for summary.json and figure")
    v.add_argument("--quiet", action="store_true", help="no progress bar")
    v.set_defaults(func=velocity)

    st = sub.add_parser(
        "structure",
        help="seed 003: the unknown input observer on simulated analogues of the thesis' sets",
    )
    st.add_argument("--set", action="append", help="I.1 ... II.3 (repeatable; default: all)")
    st.add_argument("--duration", type=float, default=30.0, help="seconds per set (default 30)")
    st.add_argument(
        "--noise", type=float, default=0.1, help="pixel noise sigma in px (default 0.1)"
    )
    st.add_argument("--seed", type=int, default=0)
    st.add_argument("--out", type=str, default=None, help="directory for figures and summary")
    st.add_argument("--quiet", action="store_true", help="no progress bar")
    st.set_defaults(func=structure)

    eu = sub.add_parser(
        "euclidean",
        help="seed 004: Euclidean positions from an uncalibrated moving camera (adaptive LS)",
    )
    eu.add_argument("--noise-px", type=float, default=0.0, help="pixel noise sigma (default 0)")
    eu.add_argument("--duration", type=float, default=30.0, help="seconds (default 30)")
    eu.add_argument("--seed", type=int, default=0)
    eu.add_argument("--out", type=str, default=None, help="directory for figure and summary")
    eu.add_argument("--quiet", action="store_true", help="no progress bar")
    eu.set_defaults(func=euclidean)

    r = sub.add_parser("reproduce", help="every paper's main experiment, figures and a summary")
    r.add_argument("--quick", action="store_true", help="smaller geometry batch")
    r.add_argument("--out", type=str, default="results", help="output directory (default results)")
    r.add_argument("--quiet", action="store_true", help="no progress bars")
    r.set_defaults(func=reproduce)
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
