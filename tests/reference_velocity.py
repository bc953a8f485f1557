"""A NumPy transcription of the velocity estimator of Chitrakaran, Dawson, Dixon, Chen,
*Identification of a moving object's velocity with a fixed camera*, one step at a time.

Written as a user would write it from the paper, with no vectorisation over time: at each
1 kHz sample, the homography from the four point pairs (eq. (17), 8x8 DLT with g33 = 1),
H = A^-1 G A (eq. (16)), its decomposition with the known normal n* (eq. (12)), the depth
ratio, e (eqs. (18)-(20), (24), (28)), J (eq. (33)), then one Euler step of eqs. (39)-(40)
and v_hat = J^-1 kappa_hat (Theorem 2). Used, as an independent reference, by the tests
(`tests/estimators/test_velocity.py`) and by the benchmarks (`benchmarks/velocity_benchmark.py`,
`benchmarks/monte_carlo.py`, which put the repository's root on `sys.path`).
"""

import numpy as np


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _log(R):
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(c)  # eq. (28)
    if theta < 1e-12:
        return np.zeros(3)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return theta * w / (2.0 * np.sin(theta))


def _L_omega(e_w):
    theta = np.linalg.norm(e_w)
    if theta < 1e-12:
        return np.eye(3)
    u = _skew(e_w / theta)
    sinc = np.sin(theta) / theta
    sinc2 = np.sin(theta / 2) / (theta / 2)
    return np.eye(3) - theta / 2 * u + (1 - sinc / sinc2**2) * u @ u  # eq. (27)


def _homography(p_ref, p_cur):
    M = np.zeros((8, 8))
    b = np.zeros(8)
    for i in range(4):
        x, y = p_ref[i]
        u, v = p_cur[i]
        M[2 * i] = [x, y, 1, 0, 0, 0, -u * x, -u * y]
        M[2 * i + 1] = [0, 0, 0, x, y, 1, -v * x, -v * y]
        b[2 * i], b[2 * i + 1] = u, v
    return np.append(np.linalg.solve(M, b), 1.0).reshape(3, 3)


def numpy_velocity_estimator(pixels, A, R_star, s1, z1_star, n_star, K, rho, dt):
    """Run the estimator over `pixels` (N, 4, 2), frame 0 the reference; returns v_hat (N, 6)."""
    n_star = n_star / np.linalg.norm(n_star)
    a = np.cross([1.0, 0.0, 0.0] if abs(n_star[0]) < 0.9 else [0.0, 1.0, 0.0], n_star)
    a /= np.linalg.norm(a)
    b = np.cross(n_star, a)
    A_inv = np.linalg.inv(A)
    Ae = A.copy()
    Ae[0, 2] = Ae[1, 2] = 0.0  # eq. (22)
    p_ref = pixels[0]
    out = np.zeros((len(pixels), 6))
    e_hat = eta = None
    for k in range(len(pixels)):
        p = pixels[k]
        G = _homography(p_ref, p)
        Hn = A_inv @ G @ A  # = H / g33
        beta1 = 1.0 / (G[2] @ np.array([p_ref[0, 0], p_ref[0, 1], 1.0]))  # alpha_1 g33
        Hs = np.sign(beta1) * Hn
        ra, rb = Hs @ a, Hs @ b
        scale = np.sqrt(np.linalg.norm(ra) * np.linalg.norm(rb))
        ra, rb = ra / np.linalg.norm(ra), rb / np.linalg.norm(rb)
        # symmetric orthonormalisation of the pair
        c = ra @ rb
        f = 0.5 * c / np.sqrt(1 - c * c) if abs(c) > 0 else 0.0
        ra, rb = ra - f * rb, rb - f * ra
        ra, rb = ra / np.linalg.norm(ra), rb / np.linalg.norm(rb)
        R_bar = np.outer(ra, a) + np.outer(rb, b) + np.outer(np.cross(ra, rb), n_star)
        g33 = np.sign(beta1) / scale
        alpha1 = beta1 / g33
        e_w = _log(R_bar)
        e = np.concatenate([p[0] - p_ref[0], [-np.log(alpha1)], e_w])  # eqs. (18)-(20), (24)
        m1 = A_inv @ np.array([p[0, 0], p[0, 1], 1.0])
        Lv = np.array([[1, 0, -m1[0]], [0, 1, -m1[1]], [0, 0, 1.0]])  # eq. (23)
        R = R_bar @ R_star
        B = alpha1 / z1_star * Ae @ Lv
        J = np.zeros((6, 6))
        J[:3, :3] = B
        J[:3, 3:] = -B @ R @ _skew(s1) @ R.T
        J[3:, 3:] = _L_omega(e_w)  # eq. (33)
        if k == 0:
            e_hat, eta = e.copy(), np.zeros(6)
        e_tilde = e - e_hat  # eq. (36)
        kappa = eta + (K + 1.0) * e_tilde  # eq. (40)
        out[k] = np.linalg.solve(J, kappa)  # Theorem 2
        e_hat = e_hat + dt * kappa  # eq. (39), Euler
        eta = eta + dt * ((K + 1.0) * e_tilde + rho * np.sign(e_tilde))
    return out
