"""The registration engine: compares a performer's video with an expert's 3D reference motion.

Pure numpy/scipy/OpenCV (+ trimesh/pyrender for rendering meshes only); imports nothing of
the service layers (app, worker, web).
"""

from engine.errors import EngineError, InvalidInput, RegistrationFailed

__all__ = ["EngineError", "InvalidInput", "RegistrationFailed"]
