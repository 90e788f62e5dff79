"""rfw.truth: the independent renders the path tracer is checked against."""
