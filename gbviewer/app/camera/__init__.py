"""The viewer's camera: the orbit/fly control, the camera path and its video."""
