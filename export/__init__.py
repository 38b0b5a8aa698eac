"""depthseg export."""
