"""OpenCV as a baseline, imported inside calls only: the section-3 reconstruction of
Chitrakaran et al. (`opencv_reconstruction`) and RANSAC homographies per frame
(`ransac_homographies`, the homography problem's `ransac` method)."""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float


def opencv_reconstruction(p_ref, p_cur, A, n_prior) -> dict:
    """The Euclidean reconstruction of one frame with OpenCV: `cv2.findHomography`
    (method 0), `cv2.decomposeHomographyMat`, and the selection rule of visjax (reference
    points in front, then the normal closest to the prior). NumPy in, NumPy out; OpenCV is
    imported here, not with visjax.

    **Returns:** a dict with `R_bar`, `x_h`, `n_star`, `alpha` (one per point, eq. (17)) and
    the Euclidean `H` (eq. (16)), like `visjax.geometry.euclidean_reconstruction`.
    """
    import cv2

    p_ref, p_cur, A, n_prior = (np.asarray(x, float) for x in (p_ref, p_cur, A, n_prior))
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


def _ransac_host(reference, pixels, threshold):
    import cv2

    # under `vmap` (`expand_dims`) each argument has the batch's leading axes, of size 1
    # where it is not batched: broadcast to the batch (a vmapped threshold: each its own)
    reference, pixels = np.asarray(reference, np.float64), np.asarray(pixels, np.float64)
    threshold = np.asarray(threshold, np.float64)
    batch = np.broadcast_shapes(reference.shape[:-2], pixels.shape[:-3], threshold.shape)
    frames = pixels.shape[-3]
    out = np.full(batch + (frames, 3, 3), np.nan)
    flat = np.broadcast_to(pixels, batch + pixels.shape[-3:]).reshape((-1,) + pixels.shape[-2:])
    ref = np.broadcast_to(reference, batch + reference.shape[-2:]).reshape(
        (-1,) + reference.shape[-2:]
    )
    res = out.reshape((-1, 3, 3))
    thresholds = np.broadcast_to(threshold, batch).reshape(-1)
    for k in range(flat.shape[0]):
        t = float(thresholds[k // frames])
        G, _ = cv2.findHomography(ref[k // frames], flat[k], cv2.RANSAC, t)
        if G is not None:
            res[k] = G
    return res.reshape(out.shape)


def ransac_homographies(
    reference: Float[ArrayLike, "n 2"],
    pixels: Float[ArrayLike, "N n 2"],
    *,
    threshold_px: float | ArrayLike = 3.0,
) -> Float[Array, "N 3 3"]:
    """OpenCV's `cv2.findHomography(reference, pixels[k], cv2.RANSAC, threshold_px)` at each
    frame, through `jax.pure_callback` (so it runs under `jit` and `vmap`, one frame after
    another on the host; not differentiable): the projective homographies $G_k$,
    $p \\sim G_k \\mathring p$ (N, 3, 3), NaN where OpenCV found none."""
    reference, pixels = jnp.asarray(reference), jnp.asarray(pixels)
    shape = jax.ShapeDtypeStruct(pixels.shape[:-2] + (3, 3), pixels.dtype)
    return jax.pure_callback(
        _ransac_host, shape, reference, pixels, threshold_px, vmap_method="expand_dims"
    )
