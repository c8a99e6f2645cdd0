"""Shared fixtures for the scenes tests: small images and scenes built once per session (no disk cache)."""

from __future__ import annotations

import dataclasses

import pytest

from scenes.build import build_scene
from scenes.library import suite_spec
from scenes.spec import SplatDensity


@pytest.fixture(scope="session")
def brick_spec():
    return suite_spec("window1", "brick")


@pytest.fixture(scope="session")
def brick_cloud(brick_spec):
    return build_scene(brick_spec)


@pytest.fixture(scope="session")
def light_spec():
    """A suite scene with coarser splats (fewer Gaussians) for tests at small image sizes."""
    spec = suite_spec("window2", "granite")
    return dataclasses.replace(spec, name="light", density=SplatDensity(wall_spacing=0.02, background_spacing=0.03,
                                                                        floor_spacing=0.04))


@pytest.fixture(scope="session")
def light_cloud(light_spec):
    return build_scene(light_spec)


@pytest.fixture(scope="session")
def reexpressed(tmp_path_factory, light_spec):
    """``light_spec`` written as a third-party capture (random frame, scale 0.2-5, SH degree 3, floaters out to
    200 m, the NED world turned by a yaw; :mod:`scenes.synthetic_capture`), with the procedural cloud to compare."""
    import numpy as np

    from scenes.synthetic_capture import write_reexpressed_capture

    return write_reexpressed_capture(light_spec, tmp_path_factory.mktemp("capture"), np.random.default_rng(19),
                                     floater_count=800, keep_procedural=True)
