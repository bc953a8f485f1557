"""KLT point tracking (Jang's thesis, section 2.4). NumPy and OpenCV: never inside jit.

The thesis tracks with the pure-translation model $I_1(m + d) = I_0(m)$ over a small
window $w$: minimising $\\int_w [I_1(m + d) - I_0(m)]^2 \\omega\\, dm$ gives $Z d = e$ with
$Z = \\int_w g g^T \\omega\\, dm$, $e = \\int_w (I_0 - I_1) g\\, \\omega\\, dm$ and
$g = \\nabla((I_0 + I_1)/2)$, iterated to convergence. `klt_translation` transcribes that;
`klt_track` is OpenCV's pyramidal Lucas-Kanade, the implementation the thesis used.
"""

import numpy as np


def klt_track(frames, p0, *, win: int = 21, levels: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Track points through a sequence of 8-bit images with OpenCV's pyramidal LK.

    **Arguments:** `frames` (N, H, W) uint8; `p0` (n, 2) pixel positions in frame 0;
    `win` the window size; `levels` the pyramid levels.

    **Returns:** `(tracks, ok)`: (N, n, 2) positions and (N, n) booleans (tracked so far).
    """
    import cv2

    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.dtype != np.uint8:
        raise ValueError(f"`frames` must be (N, H, W) uint8; got {frames.shape} {frames.dtype}.")
    p = np.asarray(p0, np.float32).reshape(-1, 1, 2)
    tracks = [p[:, 0].astype(float)]
    ok = [np.ones(len(p), bool)]
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-4)
    for k in range(1, len(frames)):
        p, status, _ = cv2.calcOpticalFlowPyrLK(
            frames[k - 1],
            frames[k],
            p,
            None,
            winSize=(win, win),
            maxLevel=levels,
            criteria=criteria,
        )
        tracks.append(p[:, 0].astype(float))
        ok.append(ok[-1] & (status[:, 0] == 1))
    return np.stack(tracks), np.stack(ok)


def klt_translation(I0, I1, point, *, win: int = 15, iterations: int = 30, tol: float = 1e-4):
    """The displacement $d$ of `point` from `I0` to `I1` by the thesis' KLT iteration.

    Uniform weight $\\omega$ over a `win` x `win` window; sub-pixel windows by bilinear
    interpolation. Returns `(d, converged)`.
    """
    import cv2

    I0 = np.asarray(I0, np.float32)
    I1 = np.asarray(I1, np.float32)
    c = tuple(float(x) for x in point)
    patch0 = cv2.getRectSubPix(I0, (win + 2, win + 2), c).astype(float)
    d = np.zeros(2)
    for _ in range(iterations):
        patch1 = cv2.getRectSubPix(I1, (win + 2, win + 2), (c[0] + d[0], c[1] + d[1]))
        patch1 = patch1.astype(float)
        mean = 0.5 * (patch0 + patch1)
        gu = 0.5 * (mean[1:-1, 2:] - mean[1:-1, :-2])
        gv = 0.5 * (mean[2:, 1:-1] - mean[:-2, 1:-1])
        diff = (patch0 - patch1)[1:-1, 1:-1]
        Z = np.array([[np.sum(gu * gu), np.sum(gu * gv)], [np.sum(gu * gv), np.sum(gv * gv)]])
        e = np.array([np.sum(diff * gu), np.sum(diff * gv)])
        step = np.linalg.solve(Z, e)
        d = d + step
        if np.linalg.norm(step) < tol:
            return d, True
    return d, False
