"""The uncalibrated camera on a moving platform of Nath et al., sections II and III.

Source: Nath, Dawson, Tatlicioglu, *Euclidean position estimation of static features using a
moving uncalibrated camera*. A camera rigidly mounted on a platform (an end effector) whose
pose $(R_b, x_b)$ in the world frame $\\mathcal W$ is measured; the camera's extrinsics
$(R_c, x_c)$ relative to the platform and its intrinsics $A$ (eq. (4)) are unknown.

Parameterisation (section III; the paper defers it to its reference [23], so it is derived
here). With $q = R_b^T(\\omega - x_b)$, the point in the platform frame, measurable for a
known feature and linear in $\\omega$ for an unknown one:

- $M = A R_c^T$ and $b = -A R_c^T x_c$, so that $A\\bar m = M q + b$ (eqs. (5)-(6));
  $\\theta_{c1} = [M_{11}, M_{12}, \\dots, M_{33}, b_1, b_2, b_3] \\in \\mathbb R^{12}$ (row-major).
- $r_3$, the last row of $R_c^T$, and $c = -r_3 x_c$, so that $z = r_3 q + c$ (eq. (7));
  $\\theta_{c2} = [r_3, c] \\in \\mathbb R^4$. Since the last row of $A$ is $[0, 0, 1]$, the
  third row of $M$ is $r_3$ and $b_3 = c$: $\\theta_{c2}$ repeats four entries of
  $\\theta_{c1}$ (the paper keeps them apart, and so does visjax).
- Unknown feature, $\\theta_{si} = [\\omega_{si}, 1]$ (eq. (11)): $W\\theta_{si} = M q + b$ with
  $W = [M R_b^T,\\ b - M R_b^T x_b] \\in \\mathbb R^{3 \\times 4}$ (eq. (10)) and
  $\\Pi = [r_3 R_b^T,\\ c - r_3 R_b^T x_b] \\in \\mathbb R^{1 \\times 4}$ (eq. (9)), built from
  the measured $(R_b, x_b)$ and the (estimated) camera parameters.
- Known feature $\\omega_{cj}$: $W_{xj}\\theta_{c1} = M q_j + b$ with
  $W_{xj} = [I_3 \\otimes q_j^T,\\ I_3] \\in \\mathbb R^{3 \\times 12}$, and
  $\\Pi_{xj} = [q_j^T, 1] \\in \\mathbb R^{1 \\times 4}$ (eq. (12)): measured signals only.

Convention: pixels are homogeneous $p = [u, v, 1]$ (eq. (2)); the camera parameters are
defined only up to a common scale ($\\lambda\\theta_{c1}, \\lambda\\theta_{c2}$ give the same
pixels).
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float, check_shape


def intrinsics_from_camera(
    f: float | ArrayLike,
    k_u: float | ArrayLike,
    k_v: float | ArrayLike,
    phi: float | ArrayLike,
    u0: float | ArrayLike,
    v0: float | ArrayLike,
) -> Float[Array, "3 3"]:
    """$A$ of Nath et al., eq. (4): $[[f k_u, f k_u \\cot\\phi, u_0], [0, f k_v/\\sin\\phi, v_0],
    [0, 0, 1]]$, with $\\phi$ the angle between the camera axes ($\\pi/2$: no skew).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    f, k_u, k_v, phi, u0, v0 = (as_float(x) for x in (f, k_u, k_v, phi, u0, v0))
    for name, value in (("f", f), ("k_u", k_u), ("k_v", k_v), ("phi", phi), ("u0", u0), ("v0", v0)):
        check_shape(value, (), name)
    z, o = jnp.zeros_like(f), jnp.ones_like(f)
    return jnp.stack(
        [
            jnp.stack([f * k_u, f * k_u * jnp.cos(phi) / jnp.sin(phi), u0]),
            jnp.stack([z, f * k_v / jnp.sin(phi), v0]),
            jnp.stack([z, z, o]),
        ]
    )


def camera_parameters(
    A: Float[ArrayLike, "3 3"], R_c: Float[ArrayLike, "3 3"], x_c: Float[ArrayLike, "3"]
) -> tuple[Float[Array, "12"], Float[Array, "4"]]:
    """$(\\theta_{c1}, \\theta_{c2})$ of section III from $A$, $R_c$, $x_c$ (module docstring).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    A, R_c, x_c = as_float(A), as_float(R_c), as_float(x_c)
    check_shape(A, (3, 3), "A")
    check_shape(R_c, (3, 3), "R_c")
    check_shape(x_c, (3,), "x_c")
    M = A @ R_c.T
    b = -M @ x_c
    r3 = R_c.T[2]
    return jnp.concatenate([M.reshape(9), b]), jnp.concatenate([r3, -(r3 @ x_c)[None]])


def feature_in_camera(
    omega: Float[ArrayLike, "3"],
    R_b: Float[ArrayLike, "3 3"],
    x_b: Float[ArrayLike, "3"],
    R_c: Float[ArrayLike, "3 3"],
    x_c: Float[ArrayLike, "3"],
) -> Float[Array, "3"]:
    """$\\bar m = R_c^T[R_b^T(\\omega - x_b) - x_c]$ of eq. (5).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    omega, R_b, x_b, R_c, x_c = (as_float(x) for x in (omega, R_b, x_b, R_c, x_c))
    for name, value, shape in (
        ("omega", omega, (3,)),
        ("R_b", R_b, (3, 3)),
        ("x_b", x_b, (3,)),
        ("R_c", R_c, (3, 3)),
        ("x_c", x_c, (3,)),
    ):
        check_shape(value, shape, name)
    return R_c.T @ (R_b.T @ (omega - x_b) - x_c)


def unknown_feature_regressors(
    R_b: Float[ArrayLike, "3 3"],
    x_b: Float[ArrayLike, "3"],
    theta_c1: Float[ArrayLike, "12"],
    theta_c2: Float[ArrayLike, "4"],
) -> tuple[Float[Array, "3 4"], Float[Array, "1 4"]]:
    """$W$ (eq. (10)) and $\\Pi$ (eq. (9)), with $p_{si} = W\\theta_{si} / \\Pi\\theta_{si}$ (8).

    Built from the measured platform pose and camera parameters (true, or estimated: then
    they are $\\hat W$, $\\hat\\Pi$ of eq. (15)).

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    R_b, x_b, theta_c1, theta_c2 = (as_float(x) for x in (R_b, x_b, theta_c1, theta_c2))
    check_shape(R_b, (3, 3), "R_b")
    check_shape(x_b, (3,), "x_b")
    check_shape(theta_c1, (12,), "theta_c1")
    check_shape(theta_c2, (4,), "theta_c2")
    M, b = theta_c1[:9].reshape(3, 3), theta_c1[9:]
    r3, c = theta_c2[:3], theta_c2[3]
    MR = M @ R_b.T
    W = jnp.concatenate([MR, (b - MR @ x_b)[:, None]], axis=1)
    rR = r3 @ R_b.T
    Pi = jnp.concatenate([rR, (c - rR @ x_b)[None]])[None, :]
    return W, Pi


def known_feature_regressors(
    R_b: Float[ArrayLike, "3 3"], x_b: Float[ArrayLike, "3"], omega_c: Float[ArrayLike, "3"]
) -> tuple[Float[Array, "3 12"], Float[Array, "1 4"]]:
    """$W_{xj}$ and $\\Pi_{xj}$ of eq. (12): $p_{cj} = W_{xj}\\theta_{c1} / \\Pi_{xj}\\theta_{c2}$.

    With $q_j = R_b^T(\\omega_{cj} - x_b)$: $W_{xj} = [I_3 \\otimes q_j^T, I_3]$,
    $\\Pi_{xj} = [q_j^T, 1]$. Measured signals only.

    No error path: NaN in, NaN out (a NaN or inf entry reaches every output entry
    computed from it; none is turned finite).
    """
    R_b, x_b, omega_c = as_float(R_b), as_float(x_b), as_float(omega_c)
    check_shape(R_b, (3, 3), "R_b")
    check_shape(x_b, (3,), "x_b")
    check_shape(omega_c, (3,), "omega_c")
    q = R_b.T @ (omega_c - x_b)
    eye = jnp.eye(3, dtype=q.dtype)
    W = jnp.concatenate([jnp.kron(eye, q[None, :]), eye], axis=1)
    Pi = jnp.concatenate([q, jnp.ones((1,), q.dtype)])[None, :]
    return W, Pi


def camera_from_parameters(
    theta_c1: Float[ArrayLike, "12"],
) -> tuple[Float[Array, "3 3"], Float[Array, "3 3"], Float[Array, "3"]]:
    """$A$, $R_c$, $x_c$ back from the camera parameters (the paper's footnote 3).

    $\\theta_{c1}$ holds $M = A R_c^T$ and $b = -M x_c$ up to a common scale $\\lambda$
    (module docstring). The third row of $A$ is $[0, 0, 1]$, so the third row of $M$ is
    the unit row $r_3$ of $R_c^T$: $|\\lambda| = \\|M_3\\|$; and $\\det M = \\lambda^3
    A_{11}A_{22}$ with positive focal lengths, so the sign of $\\lambda$ is that of
    $\\det M$ (a right-handed $R_c$). ($\\theta_{c2}$ repeats $r_3$ and $c = b_3$ with its
    own scale in the estimator, so it is not needed.) Then an
    RQ factorisation, row by row from the bottom (Gram-Schmidt): $M_2 = A_{22} r_2 + A_{23}
    r_3$ and $M_1 = A_{11} r_1 + A_{12} r_2 + A_{13} r_3$ with positive $A_{11}$, $A_{22}$;
    $R_c = [r_1; r_2; r_3]^T$ and $x_c = -M^{-1} b = -R_c A^{-1} b$.

    With estimated parameters $R_c$ is orthonormal and right-handed by construction; how
    far the estimate is from a camera shows in the residual $M - A R_c^T$ (zero here by
    construction) only through $A$: check that its entries are plausible.

    No error path: NaN in, NaN out.
    """
    theta_c1 = as_float(theta_c1)
    check_shape(theta_c1, (12,), "theta_c1")
    M, b = theta_c1[:9].reshape(3, 3), theta_c1[9:]
    sign = jnp.where(jnp.linalg.det(M) < 0.0, -1.0, 1.0)
    sign = jnp.where(jnp.all(jnp.isfinite(M)), sign, jnp.nan)  # no sign a NaN decided
    scale = sign / jnp.linalg.norm(M[2])
    M, b = scale * M, scale * b
    r3 = M[2]
    a12 = M[1] @ r3
    v = M[1] - a12 * r3
    a11 = jnp.linalg.norm(v)
    r2 = v / a11
    a01, a02 = M[0] @ r2, M[0] @ r3
    u = M[0] - a01 * r2 - a02 * r3
    a00 = jnp.linalg.norm(u)
    r1 = u / a00
    z, o = jnp.zeros_like(a00), jnp.ones_like(a00)
    A = jnp.stack([jnp.stack([a00, a01, a02]), jnp.stack([z, a11, a12]), jnp.stack([z, z, o])])
    R_c = jnp.stack([r1, r2, r3]).T
    # x_c = -M^{-1} b = -R_c A^{-1} b, with A^{-1} b by back substitution (A_33 = 1)
    y1 = (b[1] - a12 * b[2]) / a11
    y0 = (b[0] - a01 * y1 - a02 * b[2]) / a00
    x_c = -(r1 * y0 + r2 * y1 + r3 * b[2])
    return A, R_c, x_c
