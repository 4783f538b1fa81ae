"""The eval tests' fixtures: `blender`, a Blender-format dataset (dataset_builders.write_blender) of the bundled
scene, one per test module."""

import pytest
from dataset_builders import shots, write_blender


@pytest.fixture(scope="module")
def blender(bundled_scene, tmp_path_factory):
    return write_blender(tmp_path_factory.mktemp("blender"), shots(bundled_scene, vary=False))
