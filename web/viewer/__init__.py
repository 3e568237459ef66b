"""The viser 3D view of an analysis (thesis 6.10): reference and performer overlaid, bones
coloured by error, candidates toggleable, a frame slider, play, and a segment list."""

from web.viewer.scene import ViewerScene, build_scene, record_scene

__all__ = ["ViewerScene", "build_scene", "record_scene"]
