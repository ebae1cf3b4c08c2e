"""The package's version, in a leaf module of its own: every layer (and the FMUs' bundled copy)
reads it from here, so no lower layer imports the root package (whose lazy facade imports api)."""

__version__ = "0.1.0"
