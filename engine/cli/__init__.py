"""The command line (``python -m engine``): segment, cameras, reconstruct, and the settings
groups as flags; ``bench`` joins it in a developer checkout."""
