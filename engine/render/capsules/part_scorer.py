"""d_S of a body where one part moves and the others stay (thesis 4.6.2): the rest is rendered
once, each sample of the moving part only where it lies.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.shapes import CAPSULE_A, CAPSULE_B, CAPSULE_T, N_CAPSULES, BodyShape
from engine.measures import LAMBDA_A, LAMBDA_E
from engine.render import _raster
from engine.render.camera import Camera
from engine.render.capsules.full import Render, _check_box, _render_caps
from engine.render.capsules.projection import (
    _ALL_CAPS,
    _PART_I64,
    PART_CAPSULES,
    SEAM_END,
    ProjectedCapsules,
    _check_joints,
    _check_part,
    _project,
)
from engine.render.capsules.target import Target, _check_camera_target, _d_A, _d_E

#: Each part's complement: the capsules of every other part (np.setdiff1d's values, once).
_OTHER_CAPS = tuple(np.setdiff1d(_ALL_CAPS, caps) for caps in PART_CAPSULES)


@dataclass
class _FixedSpans:
    """The row spans of every part but one (d_A alone, :func:`_raster.row_unions`)."""

    lo: np.ndarray
    hi: np.ndarray
    n_row: np.ndarray
    row_counts: np.ndarray
    area: int
    inter: int


@dataclass
class _Fixed:
    """The rendering of every part but one, over the whole image."""

    z: np.ndarray
    sil: np.ndarray
    edge: np.ndarray
    flags: np.ndarray
    area: int
    inter: int
    n_edge: int
    sum_edge: float


class PartScorer:
    """d_S of a body where one part moves and the others stay (thesis 4.6.2, eq. 4.16).

    The rendering of all parts but the moving one is cached (per moving part, built on first
    use); ``score`` then rasterises only the moving part's capsules inside their bounding
    box and combines counts:

    - d_A: |A| = |fixed| + |moving \\ fixed|, |A and A'| likewise (exact);
    - d_E: fixed outline pixels hidden by a nearer moving surface are removed, the moving
      part's visible outline pixels are added (exact, since every part's outline depends
      only on its own capsules and the depth order; equal to a full render up to exact depth
      ties, which the full render breaks by capsule order).

    With ``lambda_E`` 0, d_A alone needs no depth and no image: the other parts' union of
    row spans is cached instead, and each sample's capsules are merged into the rows they
    meet (the same pixels; profile of stage 3: a third of the time of the image path).

    The configuration is a set of part poses, not necessarily one connected skeleton: each
    part's capsules come from the ``joints`` array they were last set from.

    Parameters
    ----------
    target : Target
    shape : BodyShape
    camera : Camera
    joints : ndarray, shape (17, 3)
        Initial pose of every part.
    lambda_A, lambda_E : float
        Weights of eq. 4.4.

    Raises
    ------
    InvalidInput
        Bad ``joints``, or a target whose size differs from the camera's image.
    """

    def __init__(
        self,
        target: Target,
        shape: BodyShape,
        camera: Camera,
        joints: np.ndarray,
        *,
        lambda_A: float = LAMBDA_A,
        lambda_E: float = LAMBDA_E,
    ) -> None:
        _check_camera_target(camera, target)
        self.target = target
        self.shape = shape
        self.camera = camera
        self.lambda_A = float(lambda_A)
        self.lambda_E = float(lambda_E)
        self._fixed: dict[int, _Fixed] = {}
        self._spans: dict[int, _FixedSpans] = {}
        # the camera is fixed: its projection and radii are computed once, not per call
        self._rad_m = np.asarray(shape.radii, dtype=float)
        self._rad_px = self._rad_m * float(camera.scale)
        self._A_T = camera.A.T
        self._c = np.array([camera.cx, camera.cy])
        self._view = camera.view_dir
        self.set_pose(joints)

    def set_pose(self, joints: np.ndarray) -> None:
        """Set every part's pose from one posture (17, 3)."""
        j = _check_joints(joints, "joints", batch=False)
        pc = _project(j, self.shape, self.camera)
        self._ends = pc.ends_px.copy()
        self._depth = pc.depth.copy()
        self._fixed.clear()
        self._spans.clear()

    def update_part(self, part: int, joints: np.ndarray) -> None:
        """Move one part to its pose in ``joints`` (17, 3); the other parts stay."""
        p = _check_part(part)
        j = _check_joints(joints, "joints", batch=False)
        caps = PART_CAPSULES[p]
        pc = _project(j[None], self.shape, self.camera)
        self._ends[caps] = pc.ends_px[0, caps]
        self._depth[caps] = pc.depth[0, caps]
        self._fixed = {k: v for k, v in self._fixed.items() if k == p}
        self._spans = {k: v for k, v in self._spans.items() if k == p}

    def _current(self) -> ProjectedCapsules:
        rm = np.asarray(self.shape.radii, dtype=float)
        s = float(self.camera.scale)
        return ProjectedCapsules(self._ends, rm * s, self._depth, rm, s)

    def _fixed_for(self, part: int) -> _Fixed:
        f = self._fixed.get(part)
        if f is None:
            caps = _OTHER_CAPS[part]
            t = self.target
            # the whole-image render of the other parts, touching only the rows they cover
            z = np.empty(t.silhouette.shape)
            sil = np.zeros(t.silhouette.shape, dtype=bool)
            edge = np.zeros(t.silhouette.shape, dtype=bool)
            flags = np.zeros(t.silhouette.shape, dtype=np.uint8)
            counts = np.empty(3, dtype=np.int64)
            _raster.render_image(
                self._ends, self._depth, self._rad_px, self._rad_m, _PART_I64, SEAM_END, caps,
                float(self.camera.scale), t.silhouette, z, sil, edge, flags, counts,
            )  # fmt: skip
            f = _Fixed(
                z=z,
                sil=sil,
                edge=edge,
                flags=flags,
                area=int(counts[0]),
                inter=int(counts[1]),
                n_edge=int(counts[2]),
                sum_edge=float(t.cost[edge].sum()),
            )
            self._fixed[part] = f
        return f

    def _spans_for(self, part: int) -> _FixedSpans:
        f = self._spans.get(part)
        if f is None:
            caps = _OTHER_CAPS[part]
            H = self.target.silhouette.shape[0]
            lo = np.empty((H, len(caps)))
            hi = np.empty((H, len(caps)))
            n_row = np.zeros(H, dtype=np.int64)
            row_counts = np.zeros((H, 2), dtype=np.int64)
            area, inter = _raster.row_unions(
                self._ends, self._rad_px, caps, self.target.prefix, lo, hi, n_row, row_counts
            )
            f = _FixedSpans(lo, hi, n_row, row_counts, int(area), int(inter))
            self._spans[part] = f
        return f

    def render(self) -> Render:
        """Full render of the current configuration."""
        return _render_caps(self._current(), _ALL_CAPS, self.camera, _check_box(None, self.camera))

    def current_score(self) -> float:
        """d_S of the current configuration."""
        r = self.render()
        t = self.target
        area = np.count_nonzero(r.silhouette)
        inter = np.count_nonzero(r.silhouette & t.silhouette)
        dA = _d_A(np.array(area), np.array(inter), t.area)
        dE = _d_E(np.array(t.cost[r.edges].sum()), np.array(np.count_nonzero(r.edges)), t.xi)
        return float(self.lambda_A * dA + self.lambda_E * dE)

    def score(self, part: int, joints_samples: np.ndarray) -> np.ndarray:
        """d_S with ``part`` at each sampled pose and the other parts fixed.

        Parameters
        ----------
        part : int
            Moving part, 0..11.
        joints_samples : ndarray, shape (S, 17, 3)
            Only the joints that place ``part``'s capsules are read.

        Returns
        -------
        d : ndarray, shape (S,)

        Raises
        ------
        InvalidInput
            Bad ``part`` or ``joints_samples``.
        """
        p = _check_part(part)
        j = _check_joints(joints_samples, "joints_samples", batch=True)
        caps = PART_CAPSULES[p]
        S = j.shape[0]
        # project only the moving part's capsules; other rows are never read by the kernel
        a = j[:, CAPSULE_A[caps], :]
        b = j[:, CAPSULE_B[caps], :]
        e3 = a[:, :, None, :] + CAPSULE_T[caps][None, :, :, None] * (b - a)[:, :, None, :]
        ends = np.zeros((S, N_CAPSULES, 2, 2))
        depth = np.zeros((S, N_CAPSULES, 2))
        # the same arithmetic as Camera.project and Camera.depth, with A cached
        if self.camera.distance > 0:
            ends[:, caps] = self.camera.project(e3)
        else:
            ends[:, caps] = e3 @ self._A_T + self._c
        t = self.target
        if self.lambda_E == 0.0:
            fs = self._spans_for(p)
            counts = np.empty((S, 2), dtype=np.int64)
            _raster.part_sil_counts(
                ends, self._rad_px, caps, t.prefix, fs.lo, fs.hi, fs.n_row, fs.row_counts,
                fs.area, fs.inter, counts,
            )  # fmt: skip
            return self.lambda_A * _d_A(counts[:, 0], counts[:, 1], t.area)
        depth[:, caps] = e3 @ self._view
        fx = self._fixed_for(p)
        out_i = np.empty((S, 4), dtype=np.int64)
        out_f = np.empty((S, 2))
        _raster.part_counts(
            ends, depth, self._rad_px, self._rad_m, SEAM_END, caps,
            float(self.camera.scale), fx.flags, fx.z, t.cost, out_i, out_f,
        )  # fmt: skip
        dA = _d_A(fx.area + out_i[:, 0], fx.inter + out_i[:, 1], t.area)
        n_e = fx.n_edge + out_i[:, 2] - out_i[:, 3]
        s_e = fx.sum_edge + out_f[:, 0] - out_f[:, 1]
        dE = _d_E(s_e, n_e, t.xi)
        return self.lambda_A * dA + self.lambda_E * dE
