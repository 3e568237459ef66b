"""Reference-side analysis: segment boundaries (thesis 2.1.1 item 4, 5.4.2)."""

from engine.reference.boundaries import direction_change, reference_boundaries, segments_from_list

__all__ = ["direction_change", "reference_boundaries", "segments_from_list"]
