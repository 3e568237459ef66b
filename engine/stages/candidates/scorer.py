"""The image likelihood of stage 3: d_S (thesis 4.4.1, eq. 4.4) plus the keypoint term."""

from __future__ import annotations

import numpy as np

from engine.body.shapes import CAPSULE_A, CAPSULE_B, CAPSULE_T, BodyShape
from engine.body.skeleton import N_PARTS
from engine.measures import KeypointTarget
from engine.render.camera import Camera
from engine.render.capsules import PART_CAPSULES, PartScorer, Target, d_A_batch, d_S_batch
from engine.stages.candidates.settings import CandidateSettings


class _Scorer:
    """d_S against one target region (thesis 4.4.1, eq. 4.4) for the three uses of stage 3.

    ``part`` scores poses of one part with the others at the context posture (BP, 4.6.2;
    incremental :class:`~engine.render.capsules.PartScorer`), ``full`` scores whole postures
    (refinement, candidates; :func:`~engine.render.capsules.d_S_batch`). Both are exact
    renders of the capsule body, so their values agree. With 2D keypoints, both add
    ``keypoint_weight`` d_K (beyond the thesis).
    """

    def __init__(
        self,
        target: Target,
        shape: BodyShape,
        camera: Camera,
        joints: np.ndarray,
        s: CandidateSettings,
        keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.target, self.shape, self.camera = target, shape, camera
        self.kp = None
        if keypoints is not None and s.keypoint_weight > 0 and np.any(keypoints[1] > 0):
            tau_px = s.keypoint_tau * camera.scale * max(float(np.ptp(joints[:, 1])), 0.3)
            self.kp = (KeypointTarget(keypoints[0], keypoints[1], tau_px=tau_px), s.keypoint_weight)
        self.lam = (s.lambda_a, s.lambda_e)
        self.subpixel = s.subpixel_rows
        self.parts = PartScorer(
            target, shape, camera, joints, lambda_A=s.lambda_a, lambda_E=s.lambda_e
        )
        self.n_evals = 0

    def set_pose(self, joints: np.ndarray) -> None:
        self.parts.set_pose(joints)

    def keypoints(self, postures: np.ndarray) -> np.ndarray:
        """The keypoint term w d_K of postures (N, 17, 3), (N,); zeros without keypoints."""
        if self.kp is None:
            return np.zeros(len(postures))
        target, w = self.kp
        return w * target.d_K(self.camera.project(postures))

    def part(self, part: int, samples: np.ndarray) -> np.ndarray:
        """Likelihood cost of poses of one part, the others at :meth:`set_pose`'s, (S,)."""
        self.n_evals += len(samples)
        return self.keypoints(samples) + self.parts.score(part, samples)

    def full(self, postures: np.ndarray) -> np.ndarray:
        """Likelihood cost of whole postures (N, 17, 3), (N,)."""
        self.n_evals += len(postures)
        out = self.keypoints(postures)
        lam_a, lam_e = self.lam
        if self.subpixel > 0:  # d_A measured continuously, d_E as rendered
            out = out + lam_a * d_A_batch(
                postures, self.target, self.shape, self.camera, subpixel_rows=self.subpixel
            )
            lam_a = 0.0
            if lam_e == 0.0:
                return out
        return out + d_S_batch(
            postures, self.target, self.shape, self.camera, lambda_A=lam_a, lambda_E=lam_e
        )

    def silhouette(self, postures: np.ndarray) -> np.ndarray:
        """d_A alone of ``postures`` (N, 17, 3), from row spans without rendering, (N,)."""
        self.n_evals += len(postures)
        return d_A_batch(postures, self.target, self.shape, self.camera)

    def visible_fraction(self, joints: np.ndarray) -> np.ndarray:
        """Fraction of each part's projected area that is front-most in ``joints``, (12,).

        The part's own area is the capsules' analytic area (2 r l + pi r^2 in pixels; the
        few overlaps inside a part make it a slight overestimate, which only errs towards
        calling a part occluded when it nearly is).
        """
        self.parts.set_pose(joints)
        labels = self.parts.render().labels
        seen = np.bincount(labels[labels >= 0].astype(np.int64), minlength=N_PARTS)
        pc_uv = self.camera.project(joints)
        a, b = pc_uv[CAPSULE_A], pc_uv[CAPSULE_B]
        length = np.linalg.norm(b - a, axis=-1) * np.abs(CAPSULE_T[:, 1] - CAPSULE_T[:, 0])
        r = np.asarray(self.shape.radii) * self.camera.scale
        area = 2.0 * r * length + np.pi * r**2
        own = np.array([area[PART_CAPSULES[p]].sum() for p in range(N_PARTS)])
        return seen / np.maximum(own, 1.0)
