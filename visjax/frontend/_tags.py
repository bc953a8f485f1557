"""AprilTags as features: the four corners of each tag, detected in every frame by OpenCV's
ArUco module (its `DICT_APRILTAG_*` dictionaries: no other package).

A tag's four corners are coplanar points a known distance apart (the tag's side): exactly
the input of the fixed-camera velocity estimator of Chitrakaran et al., with the known
length its side. Feature numbering, everywhere a tag's corners are features (the tracks
file of `visjax track --tags`, the camera file's `tag` of `visjax data`): feature
$4 i + c$ is corner $c$ of the tag with id $i$, in OpenCV's order (0 top-left, 1 top-right,
2 bottom-right, 3 bottom-left of the tag's black square, as the tag is drawn), so corners
0 and 1 are one side apart.
"""

import numpy as np

from ._scene_render import TAG_FAMILIES
from ._tracking import Tracks, detect_aruco
from ._video import _check_fps, check_frames


def _family(family: str) -> str:
    if family not in TAG_FAMILIES:
        raise ValueError(f"unknown AprilTag family {family!r}; choose from {TAG_FAMILIES}.")
    return family


def detect_tags(image, family: str = "36h11") -> tuple[np.ndarray, np.ndarray]:
    """AprilTags of `family` (`TAG_FAMILIES`) in a grey image, with sub-pixel corners.

    **Returns:** `(ids (m,) int, corners (m, 4, 2) float)`, sorted by id, corners in
    OpenCV's order (module docstring); a tag whose id appears twice in the image is left
    out (which of the two is which cannot be told)."""
    ids, corners = detect_aruco(image, dictionary=_family(family))
    unique, counts = np.unique(ids, return_counts=True)
    once = np.isin(ids, unique[counts == 1])
    return ids[once], corners[once]


def track_tags(frames, family: str = "36h11", *, fps=30.0, progress: bool = False) -> Tracks:
    """The corners of every AprilTag of `family` through grey frames, detected in each
    frame (no tracking between frames: a tag's corners are found anew, to sub-pixel
    accuracy, wherever it is seen).

    **Arguments:** `frames` (N, H, W) uint8; `family` one of `TAG_FAMILIES`; `fps` frames
    per second; `progress` a tqdm bar over frames.

    **Returns:** a `Tracks` whose feature $4 i + c$ is corner $c$ of tag $i$ (module
    docstring), for the ids up to the largest seen: NaN in a frame where the tag was not
    found (and throughout for an id never seen); `marker_id` and `corner` name them; `born`
    is the first frame a tag was seen in (N for an id never seen)."""
    from tqdm import tqdm

    frames = check_frames(frames)
    rate = _check_fps(fps)
    found = [
        detect_tags(image, family)
        for image in tqdm(frames, desc="tags", unit="frame", disable=not progress)
    ]
    seen = [int(i) for ids, _ in found for i in ids]
    n = 4 * (max(seen) + 1) if seen else 0
    pixels = np.full((frames.shape[0], n, 2), np.nan)
    for k, (ids, corners) in enumerate(found):
        for i, c in zip(ids, corners):
            pixels[k, 4 * i : 4 * i + 4] = c
    alive = np.all(np.isfinite(pixels), axis=-1)
    born = np.where(alive.any(axis=0), np.argmax(alive, axis=0), frames.shape[0])
    return Tracks(
        t=np.arange(frames.shape[0]) / rate,
        pixels=pixels,
        born=born.astype(int),
        marker_id=np.repeat(np.arange(n // 4), 4),
        corner=np.tile(np.arange(4), n // 4),
        fps=rate,
    )
