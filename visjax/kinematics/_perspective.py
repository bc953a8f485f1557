"""Perspective dynamics of a point seen by a moving camera (Jang's thesis, eq. (2.11)).

Written once and used by both the simulator (`visjax.sim`, the truth) and the unknown
input observer (`visjax.estimators`). State $x = [X/Z, Y/Z, 1/Z]$ of the point in the
camera frame, camera velocities $u = [v_c, \\omega]$ (camera basis), point velocity $v_p$.
"""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._util import as_float


def known_input_term(y: Float[ArrayLike, "2"], u: Float[ArrayLike, "6"]) -> Float[Array, "3"]:
    """$g(y, u) = [\\Omega_1, \\Omega_2, 0]$ of eqs. (2.11), (3.1): the rotation-induced flow.

    $\\Omega_1 = x_1 x_2 \\omega_x - \\omega_y - x_1^2\\omega_y + x_2\\omega_z$,
    $\\Omega_2 = \\omega_x + x_2^2\\omega_x - x_1 x_2\\omega_y - x_1\\omega_z$.
    """
    x1, x2 = y[0], y[1]
    wx, wy, wz = u[3], u[4], u[5]
    o1 = x1 * x2 * wx - wy - x1**2 * wy + x2 * wz
    o2 = wx + x2**2 * wx - x1 * x2 * wy - x1 * wz
    return jnp.stack([o1, o2, jnp.zeros_like(o1)])


def camera_term(x: Float[ArrayLike, "3"], u: Float[ArrayLike, "6"]) -> Float[Array, "3"]:
    """$f(x, u) = [f_1, f_2, f_3]$ of eq. (2.11): the camera-translation flow.

    $f_1 = (x_1 v_{cz} - v_{cx}) x_3$, $f_2 = (x_2 v_{cz} - v_{cy}) x_3$,
    $f_3 = v_{cz} x_3^2 + (x_2\\omega_x - x_1\\omega_y) x_3$.
    """
    x1, x2, x3 = x[0], x[1], x[2]
    vcx, vcy, vcz, wx, wy = u[0], u[1], u[2], u[3], u[4]
    return jnp.stack(
        [
            (x1 * vcz - vcx) * x3,
            (x2 * vcz - vcy) * x3,
            vcz * x3**2 + (x2 * wx - x1 * wy) * x3,
        ]
    )


def perspective_dynamics(
    x: Float[ArrayLike, "3"], u: Float[ArrayLike, "6"], v_p: Float[ArrayLike, "3"]
) -> Float[Array, "3"]:
    """$\\dot x$ of eq. (2.11) for a point moving with velocity $v_p$ (camera basis).

    $\\dot x = f(x, u) + g(y, u) + [v_{px} x_3 - x_1 v_{pz} x_3,\\ v_{py} x_3 - x_2 v_{pz}
    x_3,\\ -v_{pz} x_3^2]$; the last term is $D d$ with $d$ of eq. (3.21). Used by the
    simulator (the truth) and, without the unknown term, by the observer.
    """
    x, u, v_p = as_float(x), as_float(u), as_float(v_p)
    x1, x2, x3 = x[0], x[1], x[2]
    unknown = jnp.stack(
        [v_p[0] * x3 - x1 * v_p[2] * x3, v_p[1] * x3 - x2 * v_p[2] * x3, -v_p[2] * x3**2]
    )
    return camera_term(x, u) + known_input_term(x[:2], u) + unknown
