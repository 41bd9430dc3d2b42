"""Developer code, not in the extension: ``python -m engine bench STAGE``, each stage and the
whole pipeline measured on ground-truth scenes, printed as tables."""
