"""Scene loaders and the courtyard."""
