"""depthseg sim."""
