"""The section-3 reconstruction of Chitrakaran et al. with OpenCV, for comparison."""

import numpy as np


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
