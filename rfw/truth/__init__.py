"""Ground truth for rfw's images: independent renders its path tracer is checked against."""
