"""Morphologies: MJCF building, parsing, graph facts and the suite registry."""
