"""The collision field of a capture: built from its opaque splats in the region of interest, it agrees with the
procedural collision geometry within its resolution, ignores floaters far out, and is cached beside the scene."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from scenes.build import load_scene
from scenes.camera import PinholeCamera, Pose, euler_to_quat
from scenes.capture import Gate, load_capture
from scenes.collision import SceneCollision, load_collision
from scenes.library import suite_spec
from scenes.occupancy import DistanceField, cache_paths, clearance_grid, region_of_interest
from scenes.render import render_splats
from scenes.splats import read_ply_header
from scenes.synthetic_capture import write_reexpressed_capture


def test_the_field_agrees_with_the_procedural_geometry_within_its_resolution(reexpressed, light_spec):
    """Free points in front of the wall and in the opening, inside the region of interest: the splat field's
    clearance is the exact one within a voxel (99 % within 0.6 voxel)."""
    spec = load_capture(reexpressed.json)
    world = load_collision(reexpressed.json)
    exact = SceneCollision(light_spec)
    voxel = world.field.voxel_m
    rng = np.random.default_rng(0)
    n = 10_000
    pts = np.column_stack([rng.uniform(-1.5, light_spec.wall_back_x, n), rng.uniform(-2.5, 2.5, n),
                           rng.uniform(-3.6, -0.4, n)])
    turned = reexpressed.turn.apply(pts)
    lo, hi = np.asarray(world.field.origin), np.asarray(world.field.upper)
    inside = np.all((turned > lo + 0.1) & (turned < hi - 0.1), 1)
    d_exact = np.array([exact.clearance(p) for p in pts])
    d_field = np.array([world.clearance(p) for p in turned])
    # free space; behind the front face only inside the opening (the splats have no back face to the slab)
    keep = inside & (d_exact > 0.02) & ((pts[:, 0] < light_spec.wall_x) | (d_exact < 0.6))
    # the nearest solid must lie within the region too
    keep &= np.array([np.all((t - lo > d + 0.1) & (hi - t > d + 0.1)) for t, d in zip(turned, d_exact, strict=True)])
    assert keep.sum() > 1000
    err = np.abs(d_field[keep] - d_exact[keep])
    assert err.max() <= voxel and np.percentile(err, 99) <= 0.6 * voxel, (err.max(), np.percentile(err, 99))
    assert world.gate == spec.gate and world.wall_x is None


def test_the_region_of_interest_covers_start_and_gate_and_stops_at_the_floor():
    gate = Gate((3.0, 1.0, -1.5), (1.0, 0.0, 0.0), (1.0, 0.8), (0.0, 0.0, 0.0))
    lo, hi = region_of_interest((0.0, 0.0, 0.0), 1.5, gate, 2.0)
    assert lo == pytest.approx((-2.0, -2.0, -3.9)) and hi == pytest.approx((5.0, 3.5, 0.0))


def test_distance_field_interpolates_and_extends_beyond_its_box():
    occ = np.zeros((20, 20, 20), np.uint8)
    occ[10, :, :] = 1                                   # a wall at x = 0.525 (voxel centres 0.025 + 0.05 i)
    field = DistanceField(clearance_grid(occ, 0.05), (0.0, 0.0, 0.0), 0.05)
    assert field.clearance((0.525, 0.5, 0.5)) == pytest.approx(0.0)
    assert field.clearance((0.2, 0.5, 0.5)) == pytest.approx(0.325, abs=1e-6)   # linear between centres
    assert field.clearance((-1.0, 0.5, 0.5)) == pytest.approx(0.5 + 1.0, abs=1e-6)   # box edge + outside


def test_the_field_is_cached_beside_the_scene_and_rebuilt_when_the_scene_changes(tmp_path, reexpressed):
    doc = json.loads(reexpressed.json.read_text())
    doc["ply"] = os.path.relpath(reexpressed.ply, tmp_path)
    path = tmp_path / "room.json"
    path.write_text(json.dumps(doc))
    first = load_collision(path)
    cached = tmp_path / "room.collision.npz"
    assert cache_paths(load_capture(path))[0] == cached and cached.exists()
    again = load_collision(path)
    np.testing.assert_array_equal(again.field.grid, first.field.grid)
    doc["collision"] = {"voxel_m": 0.1}
    path.write_text(json.dumps(doc))
    coarse = load_collision(path)
    assert coarse.field.voxel_m == 0.1 and coarse.field.shape != first.field.shape


def test_an_inria_layout_sh3_capture_with_floaters_to_470_m_loads_renders_and_builds_its_field(tmp_path):
    """A small twin of the 1M-Gaussian acceptance case (measured in docs/scenes.md and by tools/benchmarks)."""
    made = write_reexpressed_capture(suite_spec("window3", "stone"), tmp_path, np.random.default_rng(470),
                                     gaussians=30_000, floater_count=600, floater_far_m=470.0)
    names = [name for name, _ in read_ply_header(made.ply)[1]]
    assert names == (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
                     + [f"f_rest_{i}" for i in range(45)] + ["opacity", "scale_0", "scale_1", "scale_2",
                                                              "rot_0", "rot_1", "rot_2", "rot_3"])
    assert not made.ply.with_name(made.ply.name + ".labels.npy").exists()
    spec, cloud = load_scene(made.json)
    assert np.abs(cloud.means).max() > 200.0
    start = np.asarray(spec.start_ned) - (0.0, 0.0, spec.altitude_m)
    frame = render_splats(cloud, PinholeCamera(80, 60),
                          Pose(tuple(start), euler_to_quat(0.0, 0.0, np.radians(spec.start_yaw_deg))))
    assert (frame.alpha > 0.9).mean() > 0.95 and 1.5 < np.median(frame.depth[frame.depth > 0]) < 6.0
    world = load_collision(made.json)
    assert world.solid_voxels > 1000
    assert world.clearance(spec.gate.center_ned) > 0.25 and world.clearance(tuple(start)) > 1.0
