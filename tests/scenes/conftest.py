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
