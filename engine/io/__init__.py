"""What is read and written: results, COLMAP models, image sequences, masks, OBJ meshes,
overlays and the ground-truth format; files are written atomically, never over a user's file."""
