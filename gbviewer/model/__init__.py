"""Scenes, cameras, cells and camera paths: the data every renderer and output works on."""
