"""depthseg replay."""
