"""Result codes shared by every visjax function that can fail on values inside jit."""

import equinox as eqx


class RESULTS(eqx.Enumeration):
    """Why a computation failed, for callers who asked for a result code (`throw=False`).

    Functions that take `throw=True` (the default) raise an `EquinoxRuntimeError` whose
    message is the text of the item below; with `throw=False` they return the item
    instead, and the caller decides.
    """

    successful = ""
    nonfinite_input = "A measurement is not finite (NaN or inf pixel coordinates)."
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
    singular_jacobian = "The kinematics Jacobian J (seed 000, eq. (33)) is singular or not finite."
    nonfinite_state = "The estimator state became non-finite (NaN or inf)."


def raise_or_keep(result, x, throw: bool):
    """With `throw`, attach the runtime error of `result` to `x`; else return `x` as is."""
    if throw:
        return result.error_if(x, result != RESULTS.successful)
    return x
