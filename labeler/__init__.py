"""rally3d labeler: the viser apps for annotation and 3D review. Builds on :mod:`inference`."""
