"""Result codes shared by every visjax function that can fail on values inside jit.

`RESULTS` extends `diffrax.RESULTS`, which extends `optimistix.RESULTS`: the codes of a
diffrax solver step or of an optimistix solve promote into it (`RESULTS.promote(r)`) and are
kept, never dropped.
"""

import diffrax
import jax
import jax.numpy as jnp

from ._small import sall


class RESULTS(diffrax.RESULTS):  # pyright: ignore[reportGeneralTypeIssues]
    """Why a computation failed, for callers who asked for a result code (`throw=False`).

    Functions that take `throw=True` (the default) raise a runtime error whose message is
    the text of the item below (`equinox.EquinoxRuntimeError` outside `jax.jit`, a
    `jax.errors.JaxRuntimeError` inside it: both are `RuntimeError`s); with `throw=False`
    they return the item instead, and the caller decides. The return type never depends on
    `throw`.
    """

    nonfinite_pixels = "A measurement is not finite (NaN or inf pixel coordinates)."
    degenerate_points = (
        "The point correspondences are degenerate: three or more of the points are "
        "collinear or coincident, so the homography is not determined."
    )
    g33_zero = (
        "g33 of the projective homography is zero: the image origin maps to infinity "
        "and the normalisation G / g33 of eq. (17) is undefined."
    )
    behind_camera = (
        "A point is behind the camera: a depth or a depth ratio alpha_i is not positive."
    )
    no_physical_solution = (
        "No homography decomposition places the reference points in front of the camera."
    )
    singular_jacobian = (
        "The kinematics Jacobian J (Chitrakaran et al., eq. (33)) is singular or not finite."
    )
    invalid_intrinsics = (
        "The intrinsic matrix (or another camera or plane parameter) is not finite, or the "
        "intrinsics are not invertible (a zero focal length)."
    )
    nonfinite_output = (
        "The computation produced a non-finite value from finite inputs: a degenerate "
        "configuration that no other check named."
    )
    nonfinite_state = (
        "The estimator state became non-finite (NaN or inf); `Solution.failed_sample` is the "
        "sample held when it happened."
    )
    nonfinite_measurement = (
        "A measurement sample is not finite (NaN or inf); `Solution.failed_sample` is its "
        "index. The run stopped there."
    )
    diverged = (
        "The estimator state left its valid set (a standing assumption of its paper: a "
        "bounded state, a positive depth estimate, a scale away from zero); "
        "`Solution.failed_sample` is the sample held when it happened."
    )
    depth_recovery_failed = (
        "The reference depth z1* could not be recovered (Chitrakaran et al., section 5): the "
        "premise R* s1 = d* w does not hold, the two features of the known length coincide "
        "in the image, or the depth is not positive."
    )
    invalid_settings = (
        "The estimator's gains or constants break an assumption of its paper (a gain that "
        "must be positive, a bound that must be ordered, a matrix that must be Hurwitz)."
    )
    singular_configuration = (
        "The robot's velocity Jacobian (Jang's thesis, eq. (4.4)) is singular or nearly so "
        "at these joint angles: the inverse velocity kinematics (4.6) does not exist there."
    )
    unstable_step = (
        "The integration step exceeds the Euler stability bound that the estimator "
        "declares for its gains (`max_stable_dt`): the run would diverge. Use a smaller "
        "`dt` (the measurement is held between samples)."
    )
    too_few_inliers = (
        "Fewer than four correspondences agree with any homography within the inlier "
        "threshold (RANSAC found no consensus, or the threshold is not positive): no "
        "homography is determined."
    )
    chattering_step = (
        "The integration step is too long for the estimator's sign gain (`rho` of the "
        "velocity estimator): under Euler steps the sign term's chattering in the estimate "
        "would exceed the bound the estimator declares for it (`step_bounds`), so the "
        "estimate would be mostly chatter. Use a smaller `dt` or a smaller gain."
    )
    too_many_dropped_frames = (
        "More than `visjax.io.MAX_DROPPED_FRACTION` of the frames have a feature missing "
        "(`dropped_fraction()`): the estimate rests mostly on held or extrapolated frames."
    )
    not_a_rotation = (
        "A matrix that should be a rotation is not one: R^T R != I or det R != 1 beyond "
        "the tolerance of `visjax.geometry.so3_log` (10 sqrt(eps))."
    )
    nonfinite_matrix = "A matrix given is not finite (a NaN or inf entry)."


def raise_or_keep(result, x, throw: bool):
    """With `throw`, attach the runtime error of `result` to `x`; else return `x` as is."""
    if throw:
        return result.error_if(x, result != RESULTS.successful)
    return x


def first_failure(result, failed, code, index):
    """ "First failure wins": record `code` and `index` if nothing has failed yet
    (`failed < 0`) and `code` is not successful; otherwise keep `result` and `failed`.

    **Returns:** `(result, failed)`, `failed` with its own dtype.
    """
    fresh = (failed < 0) & (code != RESULTS.successful)
    return RESULTS.where(fresh, code, result), jnp.where(fresh, index, failed).astype(
        jnp.result_type(failed)
    )


def all_finite(tree):
    """Whether every floating entry of a pytree is finite. An explicit `isfinite` test, so
    that no reduction can drop a NaN (XLA's CPU `max` can, in large `vmap` batches)."""
    leaves = jax.tree_util.tree_leaves(tree)
    leaves = [x for x in leaves if jnp.issubdtype(jnp.result_type(x), jnp.inexact)]
    return _all_finite(leaves) if leaves else jnp.array(True)


@jax.jit  # one program per set of shapes outside `jit`, not one operation per leaf
def _all_finite(leaves):
    return sall(jnp.stack([sall(jnp.isfinite(x)) for x in leaves]))


def intrinsics_ok(A):
    """A usable intrinsic matrix: finite, with non-zero focal lengths (invertible, eq. (15))."""
    return sall(jnp.isfinite(A)) & (A[0, 0] != 0.0) & (A[1, 1] != 0.0) & (A[2, 2] != 0.0)


def result_names(result):
    """The name of a `RESULTS` item (`"successful"`, `"diverged"`, ...), or a list of names
    for a batch of them (a `vmap`ped `Solution.result`)."""
    import numpy as np

    names = {int(item._value): name for name, item in RESULTS._name_to_item.items()}
    values = np.asarray(result._value)
    if values.ndim == 0:
        return names[int(values)]
    return [names[int(v)] for v in values.ravel()]
