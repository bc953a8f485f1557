"""Determinants and inverses of 2x2 and 3x3 matrices in closed form.

Under `vmap` on a CPU, `jnp.linalg.det`, `inv` and `solve` of a 3x3 matrix go through a
batched LU factorisation (a LAPACK call per matrix); these are a few dozen fused flops.
They are polynomial (the inverses rational), so smooth wherever the matrix is invertible.
For the well-conditioned matrices they serve (intrinsics, rotations, normalised
homographies) they agree with the LU results to a few ulps.
"""

import jax.numpy as jnp


def det2(S):
    """The determinant of a 2x2 matrix."""
    return S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]


def inv2(S):
    """The inverse of a 2x2 matrix (its adjugate over its determinant)."""
    adj = jnp.stack([jnp.stack([S[1, 1], -S[0, 1]]), jnp.stack([-S[1, 0], S[0, 0]])])
    return adj / det2(S)


def adjugate3(B):
    """The adjugate of a 3x3 matrix, $\\mathrm{adj}(B) = \\det(B) B^{-1}$: its rows are the
    cross products of $B$'s columns."""
    c0, c1, c2 = B[:, 0], B[:, 1], B[:, 2]
    return jnp.stack([jnp.cross(c1, c2), jnp.cross(c2, c0), jnp.cross(c0, c1)])


def det3(B):
    """The determinant of a 3x3 matrix (the triple product of its columns)."""
    return jnp.dot(B[:, 0], jnp.cross(B[:, 1], B[:, 2]))


def inv3(B):
    """The inverse of a 3x3 matrix (its adjugate over its determinant)."""
    adj = adjugate3(B)
    return adj / jnp.dot(adj[0], B[:, 0])


def mm(A, B):
    """`A @ B` for small matrices as a broadcast multiply and a sum: under `vmap` XLA fuses
    it with its neighbours, where a batched `dot` of 3x3 matrices is a slow GEMM call."""
    return jnp.sum(A[..., :, :, None] * B[..., None, :, :], axis=-2)


def mv(A, x):
    """`A @ x` for a small matrix and a vector, as `mm`."""
    return jnp.sum(A * x[..., None, :], axis=-1)
