"""Serial robots in Crane and Duffy's convention (Jang's thesis, chapter 4).

The thesis' testbed is a camera on a PUMA 560 and a target on a two-link planar robot. Its
chapter 4 follows C. D. Crane and J. Duffy, *Kinematic Analysis of Robot Manipulators*
(Cambridge, 1998): the transform between consecutive joint frames is eq. (4.2),
$T_F^6 = T_F^1\\,T_1^2\\,T_2^3\\,T_3^4\\,T_4^5\\,T_5^6$ (eq. (4.1)), the tool point is eq. (4.3),
the velocity Jacobian eq. (4.4), the tool-point velocity eq. (4.5) and the inverse velocity
kinematics eq. (4.6). Everything is pure JAX: `jit`, `vmap` and `grad` apply.

Convention (every method): vectors are in the fixed frame $F$ unless a name says otherwise;
$T_F^i$ maps coordinates in joint frame $i$ to $F$ (its third column is the joint axis
$S_i$, its fourth the origin $P_i$, both in $F$); frame $i$'s x-axis is the common normal
$a_{ij}$ to the next joint axis. A twist is $[V; \\omega]$, the linear velocity of a named
point first, then the angular velocity, in m/s and rad/s. Lengths are in metres (the
thesis' Table 4-1 is in centimetres: `puma560` converts).
"""

import functools
import math
from typing import final

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._results import RESULTS, all_finite, raise_or_keep
from .._util import as_float, check_shape
from ..geometry import so3_log


def link_transform(a, alpha, S, theta) -> Float[Array, "4 4"]:
    """The transform $T_i^j$ between joint frames $i$ and $j$ (Jang's thesis, eq. (4.2)).

    $$T_i^j = \\begin{bmatrix} c_j & -s_j & 0 & a_{ij} \\\\
    s_j c_{ij} & c_j c_{ij} & -s_{ij} & -s_{ij} S_j \\\\
    s_j s_{ij} & c_j s_{ij} & c_{ij} & c_{ij} S_j \\\\ 0 & 0 & 0 & 1 \\end{bmatrix}$$

    with $c_j = \\cos\\theta_j$, $s_j = \\sin\\theta_j$, $c_{ij} = \\cos\\alpha_{ij}$,
    $s_{ij} = \\sin\\alpha_{ij}$: a rotation $\\alpha_{ij}$ about $a_{ij}$, a translation
    $a_{ij}$ along it, a rotation $\\theta_j$ about $S_j$, a translation $S_j$ along it (the
    modified Denavit-Hartenberg form).

    **Arguments:** `a` the link length $a_{ij}$ (m), `alpha` the twist angle $\\alpha_{ij}$
    (rad), `S` the joint offset $S_j$ (m), `theta` the joint angle $\\theta_j$ (rad); scalars.

    **Returns:** the 4x4 homogeneous transform (coordinates in frame $j$ to frame $i$).
    """
    cj, sj = jnp.cos(theta), jnp.sin(theta)
    cij, sij = jnp.cos(alpha), jnp.sin(alpha)
    zero, one = jnp.zeros_like(cj), jnp.ones_like(cj)
    a = a + zero
    return jnp.stack(
        [
            jnp.stack([cj, -sj, zero, a]),
            jnp.stack([sj * cij, cj * cij, -sij + zero, -sij * S]),
            jnp.stack([sj * sij, cj * sij, cij + zero, cij * S]),
            jnp.stack([zero, zero, zero, one]),
        ]
    )


def _jacobian(Ts):
    """Eq. (4.4) from the joint frames $T_F^i$ (n, 4, 4): column $i$ is
    $[S_i \\times (P_n - P_i); S_i]$."""
    S, P = Ts[:, :3, 2], Ts[:, :3, 3]
    linear = jnp.cross(S, P[-1][None, :] - P)
    return jnp.concatenate([linear, S], axis=1).T


@final
class InverseVelocity(eqx.Module):
    """What `SerialChain.inverse_velocity` returns.

    **Fields:** `qdot` (n,) the joint rates (rad/s) of eq. (4.6); `sigma_min` the smallest
    singular value of the Jacobian (4.4) at `q` (metres: the linear rows dominate for a
    PUMA-sized arm); `result` a `RESULTS` item (`singular_configuration` when `sigma_min`
    is below the threshold, or `nonfinite_output`).
    """

    qdot: Float[Array, " n"]
    sigma_min: Float[Array, ""]
    result: RESULTS


@final
class PoseSolution(eqx.Module):
    """What `SerialChain.solve_pose` returns: the joint angles `q` (n,), the final pose
    error `residual` (the norm of the position error in m plus the rotation angle in rad),
    and a `result` (`singular_configuration` where the Newton step met a singular Jacobian,
    `nonfinite_output`, or `max_steps_reached` when the error stayed above the tolerance)."""

    q: Float[Array, " n"]
    residual: Float[Array, ""]
    result: RESULTS


@final
class SerialChain(eqx.Module):
    """A chain of revolute joints in Crane and Duffy's convention (Jang's thesis, ch. 4).

    Row $k$ of the fields describes the transform into joint frame $k$: row 0 is
    $T_F^1$, a rotation $\\phi_1$ about the fixed Z axis (its $a$, $\\alpha$, $S$ are 0 for
    the thesis' fixed frame, which has its origin on the first joint axis); row $k \\geq 1$
    is $T_k^{k+1}$ of eq. (4.2) with $a_{k,k+1}$, $\\alpha_{k,k+1}$, $S_{k+1}$.

    **Fields:**

    - `a`, `alpha`, `S`: (n,) link lengths (m), twist angles (rad), joint offsets (m).
    - `tool`: (3,) the tool point ${}^nP_{tool}$ in the last joint frame (m), eq. (4.3).
    """

    a: Float[Array, " n"] = eqx.field(converter=as_float)
    alpha: Float[Array, " n"] = eqx.field(converter=as_float)
    S: Float[Array, " n"] = eqx.field(converter=as_float)
    tool: Float[Array, "3"] = eqx.field(converter=as_float, default=(0.0, 0.0, 0.0))

    def __check_init__(self):
        n = jnp.shape(self.a)
        if len(n) != 1 or n[0] < 1:
            raise ValueError(f"`SerialChain.a` must have shape (n,); got {n}.")
        for name in ("alpha", "S"):
            if jnp.shape(getattr(self, name)) != n:
                raise ValueError(
                    f"`SerialChain.{name}` must have the shape of `a`, {n}; got "
                    f"{jnp.shape(getattr(self, name))}."
                )
        if jnp.shape(self.tool) != (3,):
            raise ValueError(
                f"`SerialChain.tool` must have shape (3,); got {jnp.shape(self.tool)}."
            )

    @property
    def n_joints(self) -> int:
        return int(jnp.shape(self.a)[0])

    def _six_joints(self):
        if self.n_joints != 6:
            raise ValueError(
                f"inverse velocity kinematics (4.6) needs a square Jacobian (6 joints); this "
                f"chain has {self.n_joints}."
            )

    def _q(self, q, name="q"):
        q = as_float(q)
        check_shape(q, (self.n_joints,), name)
        return q

    def frames(self, q: Float[ArrayLike, " n"]) -> Float[Array, "n 4 4"]:
        """$T_F^1, T_F^2, \\ldots, T_F^n$: every joint frame in $F$ (products of eq. (4.2))."""
        return _frames(self, self._q(q))

    def forward(self, q: Float[ArrayLike, " n"]) -> Float[Array, "4 4"]:
        """$T_F^n$ (eq. (4.1) for the PUMA's $n = 6$): the last joint frame in $F$."""
        return self.frames(q)[-1]

    def tool_pose(self, q: Float[ArrayLike, " n"]) -> tuple[Float[Array, "3 3"], Float[Array, "3"]]:
        """`(R, p)`: the orientation of the last joint frame in $F$ ($R = R_F^n$, columns
        $a_{n,n+1}$, $S_n \\times a_{n,n+1}$, $S_n$) and the tool point ${}^FP_{tool}$ of
        eq. (4.3). For a camera on the tool, its frame: optical axis along $S_n$, x along
        $a_{n,n+1}$ (Jang's thesis, Fig. 4-1)."""
        T = self.forward(q)
        return T[:3, :3], T[:3, :3] @ self.tool + T[:3, 3]

    def jacobian(self, q: Float[ArrayLike, " n"]) -> Float[Array, "6 n"]:
        """The velocity Jacobian of eq. (4.4): $[{}^FV_n; {}^F\\omega_n] = J \\dot q$.

        Column $i$ is $[S_i \\times (P_n - P_i); S_i]$ with $S_i$ and $P_i$ the third and
        fourth columns of $T_F^i$: $V_n$ is the velocity of the last frame's origin $P_n$.
        """
        return _jacobian(self.frames(q))

    def tool_twist(
        self, q: Float[ArrayLike, " n"], qdot: Float[ArrayLike, " n"], *, local: bool = False
    ) -> Float[Array, "6"]:
        """$[{}^FV_{tool}; {}^F\\omega_{tool}]$ of eq. (4.5) for joint rates `qdot`:
        $V_{tool} = V_n + \\omega_n \\times (P_{tool} - P_n)$, $\\omega_{tool} = \\omega_n$.

        With `local=True` both are expressed in the last joint frame's basis
        ($R_F^{nT} V$, $R_F^{nT}\\omega$): for a camera on the tool, the camera velocities
        $u = [v_c, \\omega]$ of the thesis' eq. (2.11).
        """
        return _tool_twist(self, self._q(q), self._q(qdot, "qdot"), local)

    def _tool_twist(self, q, qdot, local):
        Ts = self.frames(q)
        R = Ts[-1, :3, :3]
        twist = _jacobian(Ts) @ qdot
        V_n, w = twist[:3], twist[3:]
        V_tool = V_n + jnp.cross(w, R @ self.tool)  # eq. (4.5)
        if local:
            return jnp.concatenate([R.T @ V_tool, R.T @ w])
        return jnp.concatenate([V_tool, w])

    def inverse_velocity(
        self,
        q: Float[ArrayLike, " n"],
        twist: Float[ArrayLike, "6"],
        *,
        local: bool = False,
        min_singular_value: float = 1e-3,
        throw: bool = True,
    ) -> InverseVelocity:
        """The joint rates that give the tool point a commanded twist (eq. (4.6)).

        $\\dot q = J^{-1}[V_{tool} - \\omega_{tool} \\times (P_{tool} - P_n); \\omega_{tool}]$,
        solved by LU (differentiable), for a chain of six joints.

        **Arguments:**

        - `q` (6,): the joint angles; `twist` (6,): $[V_{tool}; \\omega_{tool}]$, in $F$, or
            in the last joint frame's basis with `local=True` (a camera's own velocities).
        - `min_singular_value`: the configuration is refused as singular when the smallest
            singular value of $J$ is below it (metres; the thesis: "unless the Jacobian
            matrix is non-singular" the inverse does not exist). Checked under
            `stop_gradient`.
        - `throw`: raise on a singular configuration (default), or return the result code.

        **Returns:** an `InverseVelocity` (its `qdot` is only meaningful when `result` is
        `successful`).
        """
        self._six_joints()
        twist = as_float(twist)
        check_shape(twist, (6,), "twist")
        out = _inverse_velocity(self, self._q(q), twist, local, min_singular_value)
        return raise_or_keep(out.result, out, throw)

    def _inverse_velocity(self, q, twist, local, min_singular_value):
        Ts = self.frames(q)
        R = Ts[-1, :3, :3]
        V_tool, w = twist[:3], twist[3:]
        if local:
            V_tool, w = R @ V_tool, R @ w
        V_n = V_tool - jnp.cross(w, R @ self.tool)  # eq. (4.6), the bracket
        J = _jacobian(Ts)
        sigma = jnp.linalg.svd(jax.lax.stop_gradient(J), compute_uv=False)
        sigma_min = sigma[-1]
        singular = ~(sigma_min >= min_singular_value)  # NaN counts as singular
        # a singular J would make the LU solve's value and derivative NaN: solve with the
        # identity there (the result code says the value is not to be used)
        J_safe = jnp.where(singular, jnp.eye(6, dtype=J.dtype), J)
        qdot = jnp.linalg.solve(J_safe, jnp.concatenate([V_n, w]))
        result = RESULTS.where(singular, RESULTS.singular_configuration, RESULTS.successful)
        result = RESULTS.where(
            (result == RESULTS.successful) & ~all_finite(qdot), RESULTS.nonfinite_output, result
        )
        return InverseVelocity(qdot=qdot, sigma_min=sigma_min, result=result)

    def solve_pose(
        self,
        R_target: Float[ArrayLike, "3 3"],
        p_target: Float[ArrayLike, "3"],
        q_guess: Float[ArrayLike, " n"],
        *,
        steps: int = 40,
        tol: float = 1e-10,
        throw: bool = True,
    ) -> PoseSolution:
        """Joint angles that put the tool at a pose, by Newton's method on eq. (4.6).

        Each step commands the tool twist that would remove the pose error in unit time,
        $[p^* - p(q);\\ \\log(R^* R(q)^T)]$ (in $F$), and adds the joint rates of (4.6). The
        solution is the one the iteration reaches from `q_guess` (a serial arm has several
        inverse solutions; the thesis uses the forward and velocity analyses only).

        **Arguments:** `R_target` (3, 3), `p_target` (3,): the tool frame's orientation and
        tool point in $F$; `q_guess` (n,); `steps` Newton steps; `tol` the accepted residual.

        **Returns:** a `PoseSolution`.
        """
        R_target, p_target = as_float(R_target), as_float(p_target)
        check_shape(R_target, (3, 3), "R_target")
        check_shape(p_target, (3,), "p_target")
        q = self._q(q_guess, "q_guess")
        self._six_joints()
        out = _solve_pose(self, R_target, p_target, q, steps, tol)
        return raise_or_keep(out.result, out, throw)

    def _solve_pose(self, R_target, p_target, q, steps, tol):
        def error(q):
            R, p = self.tool_pose(q)
            return jnp.concatenate([p_target - p, so3_log(R_target @ R.T).omega])

        def step(carry, _):
            q, result = carry
            out = self._inverse_velocity(q, error(q), False, 1e-3)
            ok = out.result == RESULTS.successful
            q = jnp.where(ok & (result == RESULTS.successful), q + out.qdot, q)
            result = RESULTS.where(result == RESULTS.successful, out.result, result)
            return (q, result), None

        (q, result), _ = jax.lax.scan(step, (q, RESULTS.successful), None, length=steps)
        e = error(q)
        residual = jnp.linalg.norm(e[:3]) + jnp.linalg.norm(e[3:])
        result = RESULTS.where(
            (result == RESULTS.successful) & ~(residual <= tol), RESULTS.max_steps_reached, result
        )
        return PoseSolution(q=q, residual=residual, result=result)


# The methods' arithmetic, compiled: one program per chain size when called outside `jit`
# (not one compiled operation per line); inlined under `jit`.
@jax.jit
def _frames(chain, q):
    links = jax.vmap(link_transform)(chain.a, chain.alpha, chain.S, q)

    def step(T, link):
        T = T @ link
        return T, T

    _, Ts = jax.lax.scan(step, jnp.eye(4, dtype=links.dtype), links)
    return Ts


@functools.partial(jax.jit, static_argnums=3)
def _tool_twist(chain, q, qdot, local):
    return chain._tool_twist(q, qdot, local)


@functools.partial(jax.jit, static_argnums=3)
def _inverse_velocity(chain, q, twist, local, min_singular_value):
    return chain._inverse_velocity(q, twist, local, min_singular_value)


@functools.partial(jax.jit, static_argnums=4)
def _solve_pose(chain, R_target, p_target, q, steps, tol):
    return chain._solve_pose(R_target, p_target, q, steps, tol)


_CM = 0.01
_DEG = math.pi / 180.0

# Jang's thesis, Table 4-1 (cm, degrees): a12 = 0, alpha12 = -90; a23 = 43.18, alpha23 = 0,
# S2 = 15.05; a34 = -1.91, alpha34 = 90, S3 = 0; a45 = 0, alpha45 = -90, S4 = 43.31;
# a56 = 0, alpha56 = 90, S5 = 0. S6 is not in the table: the tool point (4.3) carries the
# offset along S6, so S6 = 0 here.
PUMA560_TABLE = {
    "a": (0.0, 0.0, 43.18 * _CM, -1.91 * _CM, 0.0, 0.0),
    "alpha": (0.0, -90 * _DEG, 0.0, 90 * _DEG, -90 * _DEG, 90 * _DEG),
    "S": (0.0, 15.05 * _CM, 0.0, 43.31 * _CM, 0.0, 0.0),
}


def puma560(
    tool: Float[ArrayLike, "3"] | tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> SerialChain:
    """The PUMA 560 of Jang's thesis, Table 4-1, in metres, with the tool point `tool`
    (${}^6P_{tool}$, m, in the sixth joint frame). Joint angles $q = [\\phi_1, \\theta_2,
    \\ldots, \\theta_6]$ in radians, as the thesis measures them (no offsets)."""
    return SerialChain(tool=tool, **PUMA560_TABLE)


def puma560_forward(q: Float[ArrayLike, "6"]) -> Float[Array, "4 4"]:
    """$T_F^6$ of the PUMA 560 (Jang's thesis, eq. (4.1), Table 4-1) in metres for joint
    angles `q` (6,) $= [\\phi_1, \\theta_2, \\ldots, \\theta_6]$ in radians."""
    return puma560().forward(q)


@final
class TwoLinkArm(eqx.Module):
    """A two-link planar robot (Jang's thesis, section 5.1: the target rides on its end
    effector). Closed form, in its own base frame: joint 1 at the origin, both joints about
    the base z axis.

    Convention: $p(q) = [l_1 c_1 + l_2 c_{12},\\ l_1 s_1 + l_2 s_{12}]$ (m), $q$ in rad,
    $q_2$ relative to link 1. The thesis gives no link lengths: they are fields.

    **Fields:** `l1`, `l2`: the link lengths (m), positive.
    """

    l1: Float[Array, ""] = eqx.field(converter=as_float)
    l2: Float[Array, ""] = eqx.field(converter=as_float)

    def __check_init__(self):
        for name in ("l1", "l2"):
            if jnp.shape(getattr(self, name)) != ():
                raise ValueError(f"`TwoLinkArm.{name}` must be a scalar.")

    def forward(self, q: Float[ArrayLike, "2"]) -> Float[Array, "2"]:
        """The end point $p(q)$ in the base plane (m)."""
        q = as_float(q)
        check_shape(q, (2,), "q")
        q12 = q[0] + q[1]
        return jnp.stack(
            [
                self.l1 * jnp.cos(q[0]) + self.l2 * jnp.cos(q12),
                self.l1 * jnp.sin(q[0]) + self.l2 * jnp.sin(q12),
            ]
        )

    def jacobian(self, q: Float[ArrayLike, "2"]) -> Float[Array, "2 2"]:
        """$\\partial p / \\partial q$ (2x2); $\\det = l_1 l_2 \\sin q_2$."""
        q = as_float(q)
        check_shape(q, (2,), "q")
        q12 = q[0] + q[1]
        s1, c1, s12, c12 = jnp.sin(q[0]), jnp.cos(q[0]), jnp.sin(q12), jnp.cos(q12)
        return jnp.stack(
            [
                jnp.stack([-self.l1 * s1 - self.l2 * s12, -self.l2 * s12]),
                jnp.stack([self.l1 * c1 + self.l2 * c12, self.l2 * c12]),
            ]
        )

    def inverse(self, p: Float[ArrayLike, "2"], *, elbow: int = 1) -> Float[Array, "2"]:
        """Joint angles that put the end point at `p`: $\\cos q_2 = (|p|^2 - l_1^2 -
        l_2^2)/(2 l_1 l_2)$, $q_2$ of the sign `elbow` (+1 or -1). A point out of reach is
        an error inside `jit` (`equinox.error_if`)."""
        if elbow not in (1, -1):
            raise ValueError(f"`elbow` must be +1 or -1; got {elbow!r}.")
        p = as_float(p)
        check_shape(p, (2,), "p")
        c2 = (p @ p - self.l1**2 - self.l2**2) / (2 * self.l1 * self.l2)
        c2 = eqx.error_if(
            c2, ~(jnp.abs(c2) <= 1.0), "two-link inverse kinematics: the point is out of reach."
        )
        s2 = elbow * jnp.sqrt(jnp.clip(1.0 - c2**2, 0.0))
        q2 = jnp.arctan2(s2, c2)
        q1 = jnp.arctan2(p[1], p[0]) - jnp.arctan2(self.l2 * s2, self.l1 + self.l2 * c2)
        return jnp.stack([q1, q2])

    def inverse_velocity(
        self,
        q: Float[ArrayLike, "2"],
        pdot: Float[ArrayLike, "2"],
        *,
        min_sin_q2: float = 1e-3,
        throw: bool = True,
    ) -> InverseVelocity:
        """$\\dot q = J^{-1}\\dot p$, refused (`singular_configuration`) when
        $|\\sin q_2| <$ `min_sin_q2` (the arm stretched out or folded)."""
        q = as_float(q)
        pdot = as_float(pdot)
        check_shape(pdot, (2,), "pdot")
        J = self.jacobian(q)
        s2 = jax.lax.stop_gradient(jnp.abs(jnp.sin(q[1])))
        singular = ~(s2 >= min_sin_q2)
        J_safe = jnp.where(singular, jnp.eye(2, dtype=J.dtype), J)
        qdot = jnp.linalg.solve(J_safe, pdot)
        sigma_min = jnp.linalg.svd(jax.lax.stop_gradient(J), compute_uv=False)[-1]
        result = RESULTS.where(singular, RESULTS.singular_configuration, RESULTS.successful)
        result = RESULTS.where(
            (result == RESULTS.successful) & ~all_finite(qdot), RESULTS.nonfinite_output, result
        )
        return raise_or_keep(result, InverseVelocity(qdot, sigma_min, result), throw)
