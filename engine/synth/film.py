"""Filming the performer: a fixed scaled orthographic camera framing the whole motion
(thesis 2.1.3 item 1), the mesh body over a textured background, sensor noise.
"""

from __future__ import annotations

import numpy as np

from engine.body.shapes import BodyShape, capsule_endpoints
from engine.render.camera import Camera
from engine.synth.settings import SynthSettings


def fit_camera(joints: np.ndarray, shape: BodyShape, settings: SynthSettings) -> Camera:
    """Camera framing the whole motion at ``settings.fill`` of the image height, centred.

    Parameters
    ----------
    joints : ndarray, shape (T', 17, 3)
    shape : BodyShape
    settings : SynthSettings
    """
    cam1 = Camera(
        scale=1.0,
        theta_z=np.radians(settings.theta_z_deg),
        azimuth=np.radians(settings.azimuth_deg),
        width=settings.width,
        height=settings.height,
    )
    ends = cam1.project(capsule_endpoints(joints))  # (T', C, 2, 2)
    r = np.asarray(shape.radii)[None, :, None, None]
    lo = (ends - r).min(axis=(0, 1, 2))
    hi = (ends + r).max(axis=(0, 1, 2))
    ext = np.maximum(hi - lo, 1e-6)
    scale = min(settings.fill * settings.height / ext[1], 0.95 * settings.width / ext[0])
    mid = (lo + hi) / 2.0
    return cam1.with_(
        scale=float(scale),
        cx=float(settings.width / 2.0 - 0.5 - scale * mid[0]),
        cy=float(settings.height / 2.0 - 0.5 - scale * mid[1]),
    )


def _film(
    joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    settings: SynthSettings,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Render the postures (T', 17, 3) as the mesh body: RGB frames (T', H, W, 3) uint8 over
    the background, with sensor noise, and the true silhouettes (T', H, W)."""
    from engine.render.mesh import MeshRenderer, textured_background

    H, W = settings.height, settings.width
    # the horizon (wall meets floor) lies 15 % of the image above the lowest ankle (joints 3, 6)
    floor_v = float(camera.project(joints[:, [3, 6]]).max(axis=(0, 1))[1])
    bg = (
        textured_background(H, W, rng, horizon=min(floor_v - 0.15 * H, H - 2.0))
        if settings.background
        else np.full((H, W, 3), 128, dtype=np.uint8)
    )
    frames = np.empty((len(joints), H, W, 3), dtype=np.uint8)
    masks = np.empty((len(joints), H, W), dtype=bool)
    with MeshRenderer(W, H) as renderer:
        for i in range(len(joints)):
            img, masks[i] = renderer.render(joints[i], shape, camera, background=bg)
            if settings.noise_sigma > 0:
                noisy = img + rng.normal(0.0, settings.noise_sigma, img.shape)
                img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
            frames[i] = img
    return frames, masks
