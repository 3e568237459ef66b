"""Before stage 0: is the performer filmed so that an analysis can work?

One frame (the first) is enough to catch what spoils most uploads (issue 21 item 6): nobody in
view, part of the body out of the picture, the body too small, a second person. The checks
read MediaPipe's legacy pose and face models, which ship inside its wheel (as
:mod:`engine.stages.perception` does); each problem comes with what to do about it, in the
performer's words. A warning, never a refusal: the analysis decides on the whole video.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.errors import InvalidInput

#: BlazePose landmarks (33) of the body parts that must be in the picture, in the words the
#: message uses.
_PARTS: dict[str, tuple[int, ...]] = {
    "head": (0, 7, 8),
    "hands": (15, 16),
    "feet": (27, 28, 29, 30, 31, 32),
}
#: A landmark this far outside the picture (share of its size) is out of view: the model
#: places parts it cannot see beyond the border.
_OUTSIDE = 0.01
#: The body should fill at least this share of the picture's height: smaller, the silhouette
#: and the keypoints are a few pixels per bone.
MIN_BODY_SHARE = 0.3


@dataclass(frozen=True)
class Framing:
    """What one frame says about the filming.

    Attributes
    ----------
    person_found : bool
    out_of_view : tuple of str
        Body parts outside the picture ("head", "hands", "feet").
    body_share : float
        The body's height over the picture's (0 without a person).
    people : int
        People seen: the pose model's one, plus faces away from it.
    problems : tuple of str
        What to change, one sentence each; empty when the framing looks right.
    """

    person_found: bool
    out_of_view: tuple[str, ...] = ()
    body_share: float = 0.0
    people: int = 0
    problems: tuple[str, ...] = field(default=())


def check_framing(rgb: np.ndarray) -> Framing:
    """Check one RGB frame (H, W, 3) uint8.

    Raises
    ------
    InvalidInput
        Not an RGB image, or the perception extra is missing.
    """
    f = np.asarray(rgb)
    if f.ndim != 3 or f.shape[-1] != 3 or f.dtype != np.uint8 or min(f.shape[:2]) < 16:
        raise InvalidInput(f"a frame must be uint8 of shape (H, W, 3), got {f.dtype} {f.shape}")
    try:
        from mediapipe.python.solutions import face_detection, pose
    except ImportError as e:
        raise InvalidInput("the framing check needs the 'perception' extra") from e
    f = np.ascontiguousarray(f)
    with pose.Pose(static_image_mode=True, model_complexity=1) as model:
        found = model.process(f).pose_landmarks
    with face_detection.FaceDetection(model_selection=1, min_detection_confidence=0.6) as fd:
        faces = fd.process(f).detections or []
    centres = np.array([[d.location_data.relative_bounding_box.xmin
                         + d.location_data.relative_bounding_box.width / 2,
                         d.location_data.relative_bounding_box.ymin
                         + d.location_data.relative_bounding_box.height / 2]
                        for d in faces]).reshape(-1, 2)  # fmt: skip
    if found is None:
        return framing_of(None, centres)
    lm = np.array([(p.x, p.y) for p in found.landmark])  # (33, 2), share of width / height
    return framing_of(lm, centres)


def framing_of(landmarks: np.ndarray | None, faces: np.ndarray) -> Framing:
    """:class:`Framing` from the pose model's landmarks (33, 2) (share of the picture's width
    and height, None without a person) and face centres (F, 2) in the same units."""
    if landmarks is None:
        people = len(faces)
        return Framing(False, people=people, problems=(
            "No one was found in the first frame: start the video with your whole body in "
            "view, in the expert's first posture.",
        ))  # fmt: skip
    lm = np.asarray(landmarks, float)
    outside = (lm < -_OUTSIDE) | (lm > 1 + _OUTSIDE)  # (33, 2)
    out = tuple(part for part, idx in _PARTS.items() if outside[list(idx)].any())
    inside = np.clip(lm, 0.0, 1.0)
    share = float(inside[:, 1].max() - inside[:, 1].min())
    lo, hi = inside.min(0), inside.max(0)
    pad = 0.1 * (hi - lo)
    away = ~np.all((faces >= lo - pad) & (faces <= hi + pad), axis=1) if len(faces) else []
    people = 1 + int(np.sum(away))
    problems = []
    if out:
        problems.append(
            f"Your {_words(out)} {'is' if out == ('head',) else 'are'} out of the picture: step "
            "back or move the camera so that your whole body shows, with some room around it."
        )
    if share < MIN_BODY_SHARE and not out:
        problems.append(
            f"You fill only {share:.0%} of the picture's height: come closer to the camera "
            "(or zoom in) so that your body fills most of it."
        )
    if people > 1:
        problems.append(
            "Someone else is in view: film with only you in the picture, or the analysis may "
            "follow the wrong person."
        )
    return Framing(True, out, share, people, tuple(problems))


def first_frame_problems(
    landmarks: np.ndarray | None, detected: bool, width: int, height: int
) -> tuple[str, ...]:
    """What the analysed video's first frame says about the filming, from the perception
    step's landmarks of that frame (33, 2+) in pixels of a ``width`` x ``height`` picture.

    The same check as the upload page's (:func:`framing_of`), done again by the engine for
    the videos a browser cannot decode and for uploads through the API. Without the face
    detector it cannot tell whether someone else is in view. None for landmarks means the
    model gives none (an older stored stage): nothing to say.
    """
    if landmarks is None:
        return ()
    if not detected:
        return framing_of(None, np.zeros((0, 2))).problems
    lm = np.asarray(landmarks, float)[:, :2] / np.array([width, height], float)
    return framing_of(lm, np.zeros((0, 2))).problems


def _words(parts: tuple[str, ...]) -> str:
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
