"""Developer code, not in the extension: synthetic scenes with known truth (layouts, looks,
cameras, the fast renderer and its textures) for the tests and benches."""
