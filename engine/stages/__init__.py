"""The reconstruction's stages, in the order data flows through them: masks (segmentation),
cameras, carving, segment graph, topology, rod fit, and the editable Bézier curve."""
