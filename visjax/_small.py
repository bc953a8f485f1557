"""Determinants, inverses and the symmetric eigendecomposition of 2x2 and 3x3 matrices in
closed form, and the solve of a small symmetric positive definite system by unrolled
elimination (`spd_solve`).

Under `vmap` on a CPU, `jnp.linalg.det`, `inv` and `solve` of a 3x3 matrix go through a
batched LU factorisation (a LAPACK call per matrix); these are a few dozen fused flops.
They are polynomial (the inverses rational), so smooth wherever the matrix is invertible.
For the well-conditioned matrices they serve (intrinsics, rotations, normalised
homographies) they agree with the LU results to a few ulps.
"""

import functools
import math

import jax
import jax.numpy as jnp

# Small matrices as rows of scalars. Under `vmap` on a CPU, every operation on a scalar is
# one elementwise operation over the batch, which XLA fuses into few loops; the same
# formulas on (3, 3) arrays compile to many small fusions of strided slices and
# concatenations, each a pass over the batch. `rows` and `from_rows` convert at the
# boundaries of a computation (XLA folds a slice of a stack into its operand).


def rows(M):
    """A small matrix as a list of rows of scalars (a vector as a list of scalars)."""
    if M.ndim == 1:
        return [M[i] for i in range(M.shape[0])]
    return [[M[i, j] for j in range(M.shape[1])] for i in range(M.shape[0])]


def from_rows(R, dtype):
    """The array of `dtype` of a list of rows of scalars (or of a list of scalars); Python
    numbers among them become constants of `dtype`."""
    if isinstance(R[0], (list, tuple)):
        return jnp.stack([from_rows(r, dtype) for r in R])
    return jnp.stack([jnp.asarray(x, dtype) for x in R])


def barrier(x):
    """`jax.lax.optimization_barrier(x)` where JAX computes on a CPU, `x` elsewhere.

    The per-frame computations (`_homography._dlt`, the decompositions, `so3_log`, the
    velocity measurement) materialise a few shared quantities once per frame with a
    barrier: XLA's CPU compiler has no multi-output fusion and would otherwise recompute
    them into each consumer (the velocity measurement of a frame, measured on 2 cores:
    95 kernels, 8.6 kB and 3,156 flops per frame with the barriers; 97, 8.9 kB and 3,304
    without). A GPU's compiler fuses siblings into multi-output kernels: there a barrier
    would only cut its fusions, so it is left out (not yet measured on a GPU). The
    backend is JAX's default one, read when the function is traced."""
    if jax.default_backend() == "cpu":
        return jax.lax.optimization_barrier(x)
    return x


def total(xs):
    """The sum of a list of scalars."""
    out = xs[0]
    for x in xs[1:]:
        out = out + x
    return out


def _is_zero(x):
    return isinstance(x, float) and x == 0.0


def sdot(a, b):
    """The dot product of two lists of scalars (terms with a literal 0.0 are skipped)."""
    terms = [x * y for x, y in zip(a, b) if not (_is_zero(x) or _is_zero(y))]
    return total(terms) if terms else 0.0


def scross(a, b):
    """The cross product of two 3-lists of scalars."""
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def smm(A, B):
    """The product of two matrices given by rows of scalars."""
    return [[sdot(r, [b[j] for b in B]) for j in range(len(B[0]))] for r in A]


def smv(A, x):
    """A matrix (rows of scalars) times a vector (a list of scalars)."""
    return [sdot(r, x) for r in A]


def stranspose(A):
    """The transpose of a matrix given by rows of scalars."""
    return [list(c) for c in zip(*A)]


def sskew(v):
    """$[v]_\\times$ of a 3-list of scalars, as rows (zeros as Python floats)."""
    return [[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]]


def sadjugate(B):
    """The adjugate of a 3x3 matrix given by rows: its rows are the cross products of
    the columns."""
    c = stranspose(B)
    return [scross(c[1], c[2]), scross(c[2], c[0]), scross(c[0], c[1])]


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
    return dot(B[:, 0], jnp.cross(B[:, 1], B[:, 2]))


def inv3(B):
    """The inverse of a 3x3 matrix (its adjugate over its determinant)."""
    adj = adjugate3(B)
    return adj / dot(adj[0], B[:, 0])


def spd_solve(G, b):
    """The solution $x$ of $G x = b$ for a small symmetric positive definite `G` (n, n) and
    `b` (n,), by Gaussian elimination without pivoting ($G = L D L^T$), unrolled over the
    static `n`: elementwise operations only (under `vmap` on a CPU, `jnp.linalg.solve`
    is a batched LAPACK call per matrix, and two such calls in one program can hang on
    jaxlib 0.10: `apply_xla_cpu_workarounds`). Exact for SPD `G` up to rounding; no
    check of definiteness (a zero pivot gives non-finite values)."""
    n = G.shape[-1]
    A = [[G[..., i, j] for j in range(n)] for i in range(n)]
    y = [b[..., i] for i in range(n)]
    for k in range(n):  # forward elimination
        for i in range(k + 1, n):
            f = A[i][k] / A[k][k]
            A[i] = [A[i][j] - f * A[k][j] if j >= k else A[i][j] for j in range(n)]
            y[i] = y[i] - f * y[k]
    x = [None] * n
    for i in reversed(range(n)):  # back substitution
        s = y[i]
        for j in range(i + 1, n):
            s = s - A[i][j] * x[j]
        x[i] = s / A[i][i]
    return jnp.stack(x, axis=-1)


_UNROLL = 64  # longer axes keep XLA's reduction


def _reduce(x, axis, op, fallback):
    if axis is None:
        x, axis = x.reshape(-1), 0
    if x.shape[axis] > _UNROLL:
        return fallback(x, axis=axis)
    # one program per shape: outside `jit` (or under an eager `vmap` or `grad`) not one
    # compiled slice per entry; inside `jit` its trace is cached and inlined
    return _unrolled(x, axis, op)


@functools.partial(jax.jit, static_argnums=(1, 2))
def _unrolled(x, axis, op):
    parts = [jax.lax.index_in_dim(x, k, axis, keepdims=False) for k in range(x.shape[axis])]
    out = parts[0]
    for q in parts[1:]:
        out = op(out, q)
    return out


def ssum(x, axis=None):
    """`jnp.sum(x, axis)` over a small axis (or all of a small array), unrolled into adds.

    Under `vmap` on a CPU a reduction over 3 or 4 entries is a kernel call of its own
    (a pass over the batch) and a boundary of XLA's fusions; the adds fuse with their
    neighbours into one loop. Axes longer than 64 are reduced by `jnp.sum`."""
    return _reduce(x, axis, jnp.add, jnp.sum)


def smax(x, axis=None):
    """`jnp.max(x, axis)` over a small axis, unrolled as `ssum` (NaN propagates)."""
    return _reduce(x, axis, jnp.maximum, jnp.max)


def sall(x, axis=None):
    """`jnp.all(x, axis)` over a small axis, unrolled as `ssum`."""
    return _reduce(x, axis, jnp.logical_and, jnp.all)


def dot(u, v):
    """`u @ v` for two short vectors, unrolled."""
    return ssum(u * v, -1)


def mm(A, B):
    """`A @ B` for small matrices, unrolled into broadcast multiplies and adds: under `vmap`
    a batched `dot` of 3x3 matrices is a slow GEMM call and a fusion boundary."""
    out = A[..., :, 0:1] * B[..., 0:1, :]
    for k in range(1, A.shape[-1]):
        out = out + A[..., :, k : k + 1] * B[..., k : k + 1, :]
    return out


def mv(A, x):
    """`A @ x` for a small matrix and a vector, unrolled as `mm`."""
    out = A[..., :, 0] * x[..., 0:1]
    for k in range(1, A.shape[-1]):
        out = out + A[..., :, k] * x[..., k : k + 1]
    return out


def norm(x):
    """The Euclidean norm of a short vector (or Frobenius of a small matrix), unrolled."""
    return jnp.sqrt(ssum(x * x))


def _unit(x):
    return x / norm(x)


def _eigh3_forward(A):
    """Eigenvalues (ascending) and eigenvectors (columns) of a symmetric 3x3 matrix.

    The eigenvalues are those of $q I + p C$ with $q = \\mathrm{tr}(A)/3$,
    $p = \\|A - qI\\|_F / \\sqrt 6$ and $\\det C / 2 = \\cos 3\\varphi$: $q + 2p\\cos(\\varphi +
    2\\pi k/3)$ (the trigonometric solution of the characteristic cubic). Only the one
    farthest from the other two is taken from it (the largest when $\\cos 3\\varphi \\ge 0$,
    else the smallest): its eigenvector is the longest cross product of two rows of
    $A - \\lambda I$, well conditioned since its gap is at least half the spread. The other
    two come from the 2x2 matrix $A$ makes on the plane orthogonal to it, by a rotation
    $\\tan 2\\theta = 2 s_{12} / (s_{11} - s_{22})$; every eigenvalue is a Rayleigh quotient.
    Errors are of the order of those of LAPACK's: eps times the norm for the eigenvalues,
    eps over the gap for the eigenvectors.
    """
    dtype = A.dtype
    eye = jnp.eye(3, dtype=dtype)
    s = smax(jnp.abs(A))
    s = jnp.where(s > 0.0, s, 1.0)
    A = A / s
    q = (A[0, 0] + A[1, 1] + A[2, 2]) / 3.0
    B = A - q * eye
    p = jnp.sqrt(ssum(B * B) / 6.0)
    scalar = p <= 0.0  # A = qI: any basis
    p_safe = jnp.where(scalar, 1.0, p)
    r = jnp.clip(det3(B / p_safe) / 2.0, -1.0, 1.0)
    phi = jnp.arccos(r) / 3.0
    top = r >= 0.0  # the largest eigenvalue is the isolated one
    lam = q + 2.0 * p * jnp.where(top, jnp.cos(phi), jnp.cos(phi + 2.0 * math.pi / 3.0))

    rows = A - lam * eye
    big = smax(jnp.abs(rows))
    rows = rows / jnp.where(big > 0.0, big, 1.0)  # no underflow in the cross products
    crosses = jnp.stack(
        [
            jnp.cross(rows[0], rows[1]),
            jnp.cross(rows[0], rows[2]),
            jnp.cross(rows[1], rows[2]),
        ]
    )
    sizes = ssum(crosses * crosses, 1)
    c = jnp.where(
        sizes[0] >= jnp.maximum(sizes[1], sizes[2]),
        crosses[0],
        jnp.where(sizes[1] >= sizes[2], crosses[1], crosses[2]),
    )
    c = jnp.where(scalar | (smax(sizes) <= 0.0), eye[2], c)
    v = _unit(c)

    # An orthonormal basis (u, w) of the plane orthogonal to v.
    u = jnp.where(
        jnp.abs(v[0]) > jnp.abs(v[1]),
        _unit(jnp.stack([-v[2], jnp.zeros((), dtype), v[0]])),
        _unit(jnp.stack([jnp.zeros((), dtype), v[2], -v[1]])),
    )
    w = jnp.cross(v, u)
    Au, Aw = mv(A, u), mv(A, w)
    s11, s22, s12 = dot(u, Au), dot(w, Aw), dot(u, Aw)
    two_theta = jnp.arctan2(s12, (s11 - s22) / 2.0)
    cos_t, sin_t = jnp.cos(two_theta / 2.0), jnp.sin(two_theta / 2.0)
    e_hi = cos_t * u + sin_t * w
    e_lo = cos_t * w - sin_t * u
    mu_hi, mu_lo = dot(e_hi, mv(A, e_hi)), dot(e_lo, mv(A, e_lo))
    lam_v = dot(v, mv(A, v))

    values = jnp.where(top, jnp.stack([mu_lo, mu_hi, lam_v]), jnp.stack([lam_v, mu_lo, mu_hi]))
    vectors = jnp.where(top, jnp.stack([e_lo, e_hi, v], axis=1), jnp.stack([v, e_lo, e_hi], axis=1))
    values = jnp.where(scalar, q, values)
    vectors = jnp.where(scalar, eye, vectors)
    return values * s, vectors


@jax.custom_jvp
def _eigh3(A):
    return _eigh3_forward(A)


@_eigh3.defjvp
def _eigh3_jvp(primals, tangents):
    # The first-order perturbation of a symmetric eigenproblem (the rule of
    # `jnp.linalg.eigh`): d(lambda_i) = v_i^T dA v_i and
    # dV = V (F o V^T dA V), F_ij = 1 / (lambda_j - lambda_i) off the diagonal.
    (A,), (dA,) = primals, tangents
    lam, V = _eigh3(A)
    G = mm(V.T, mm(dA, V))
    eye = jnp.eye(3, dtype=lam.dtype)
    F = 1.0 / (eye + lam[None, :] - lam[:, None]) - eye
    return (lam, V), (jnp.diagonal(G), mm(V, F * G))


def eigh3(A):
    """`jnp.linalg.eigh` of a symmetric 3x3 matrix in closed form.

    Returns `(values, vectors)`: the eigenvalues in ascending order and the orthonormal
    eigenvectors as columns, like `jnp.linalg.eigh` (which on a CPU is a LAPACK call per
    matrix under `vmap`). `A` is symmetrised first. Derivatives follow the same rule as
    `jnp.linalg.eigh`'s, finite where the eigenvalues are distinct.
    """
    return _eigh3((A + A.T) / 2.0)
