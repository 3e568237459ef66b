"""Renderers: the camera, the fast capsule rasteriser and the pyrender mesh renderer."""
