"""rfw's built-in passes, one folder each (``passes/<id>/<id>.py`` and its shaders). rfw does
not import this package: each pass is listed in pyproject.toml's ``rfw.passes`` entry points and
loaded from there, as a third-party pass is."""
