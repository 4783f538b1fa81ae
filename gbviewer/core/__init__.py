"""The bottom layer: errors, value checks, optional extras and cancellation; imports nothing of gbviewer."""
