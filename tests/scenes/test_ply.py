import numpy as np
import pytest

from scenes.splats import GaussianCloud, PlyError, read_ply, write_ply


def _random_cloud(n: int, degree: int, seed: int = 0) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return GaussianCloud(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 4)),
                         rng.normal(size=n), rng.normal(size=(n, k, 3)), rng.integers(0, 5, n))


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_round_trip_is_exact(tmp_path, degree):
    cloud = _random_cloud(257, degree, degree)
    write_ply(tmp_path / "c.ply", cloud)
    back = read_ply(tmp_path / "c.ply")
    assert back.sh_degree == degree
    for name in ("means", "log_scales", "quats", "opacity_logits", "sh", "labels"):
        assert np.array_equal(getattr(back, name), getattr(cloud, name)), name


def test_hand_built_degree3_header_loads(tmp_path):
    """The reference 3DGS layout: 62 float properties, f_rest channel-major (R coefficients, then G, then B)."""
    n = 5
    props = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(45)]
             + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])
    assert len(props) == 62
    header = "ply\nformat binary_little_endian 1.0\ncomment written by hand\nelement vertex 5\n"
    header += "".join(f"property float {p}\n" for p in props) + "end_header\n"
    data = np.arange(n * 62, dtype="<f4").reshape(n, 62)
    (tmp_path / "h.ply").write_bytes(header.encode() + data.tobytes())
    c = read_ply(tmp_path / "h.ply")
    assert len(c) == n and c.sh_degree == 3
    assert np.array_equal(c.means, data[:, 0:3])
    assert np.array_equal(c.sh[:, 0, :], data[:, 6:9])
    rest = data[:, 9:54]
    # coefficient j (1..15) of channel ch is f_rest_{ch * 15 + j - 1}
    for ch in range(3):
        for j in range(1, 16):
            assert np.array_equal(c.sh[:, j, ch], rest[:, ch * 15 + j - 1])
    assert np.array_equal(c.opacity_logits, data[:, 54])
    assert np.array_equal(c.log_scales, data[:, 55:58])
    assert np.array_equal(c.quats, data[:, 58:62])


def test_double_properties_and_extra_elements(tmp_path):
    props = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0",
             "rot_1", "rot_2", "rot_3"]
    header = "ply\nformat binary_little_endian 1.0\nelement vertex 2\n"
    header += "".join(f"property double {p}\n" for p in props) + "property uchar label\nelement camera 1\n"
    header += "property float fx\nend_header\n"
    rec = np.zeros(2, dtype=[(p, "<f8") for p in props] + [("label", "u1")])
    rec["x"] = [1.5, 2.5]
    rec["label"] = [1, 3]
    (tmp_path / "d.ply").write_bytes(header.encode() + rec.tobytes() + np.float32(1).tobytes())
    c = read_ply(tmp_path / "d.ply")
    assert c.means[:, 0].tolist() == [1.5, 2.5] and c.labels.tolist() == [1, 3] and c.sh_degree == 0


def test_element_before_vertex_is_skipped(tmp_path):
    props = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0",
             "rot_1", "rot_2", "rot_3"]
    header = "ply\nformat binary_little_endian 1.0\nelement chunk 2\nproperty float a\nproperty uint b\n"
    header += "element vertex 1\n" + "".join(f"property float {p}\n" for p in props)
    header += "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    vert = np.arange(len(props), dtype="<f4")
    (tmp_path / "c.ply").write_bytes(header.encode() + bytes(16) + vert.tobytes() + bytes(13))
    c = read_ply(tmp_path / "c.ply")
    assert c.means.tolist() == [[0.0, 1.0, 2.0]] and c.quats.tolist() == [[10.0, 11.0, 12.0, 13.0]]


def test_nerfstudio_degree0_rgb_colours(tmp_path):
    """nerfstudio's exporter writes degree-0 splats with uchar red/green/blue instead of f_dc_*."""
    floats = ["x", "y", "z", "nx", "ny", "nz", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1",
              "rot_2", "rot_3"]
    header = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
    header += "".join(f"property float {p}\n" for p in floats[:6])
    header += "property uchar red\nproperty uchar green\nproperty uchar blue\n"
    header += "".join(f"property float {p}\n" for p in floats[6:]) + "end_header\n"
    rec = np.zeros(1, dtype=[(p, "<f4") for p in floats[:6]] + [(c, "u1") for c in ("red", "green", "blue")]
                   + [(p, "<f4") for p in floats[6:]])
    rec["red"], rec["green"], rec["blue"], rec["rot_0"] = 255, 0, 51, 1.0
    (tmp_path / "n.ply").write_bytes(header.encode() + rec.tobytes())
    c = read_ply(tmp_path / "n.ply")
    assert c.sh_degree == 0
    assert (c.sh[0, 0] * 0.28209479177387814 + 0.5) == pytest.approx([1.0, 0.0, 0.2], abs=1e-6)


def _one_line(exc: PlyError) -> str:
    msg = str(exc)
    assert "\n" not in msg
    return msg


def test_truncated_file(tmp_path):
    write_ply(tmp_path / "t.ply", _random_cloud(100, 1), write_labels=False)
    raw = (tmp_path / "t.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(raw[:-10])
    with pytest.raises(PlyError) as e:
        read_ply(tmp_path / "t.ply")
    assert "truncated" in _one_line(e.value)


@pytest.mark.parametrize("content, words", [
    (b"hello", "not a PLY"),
    (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n1\n", "binary_little_endian"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n\0\0\0\0",
     "not a 3DGS"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n", "truncated"),
])
def test_corrupt_files(tmp_path, content, words):
    (tmp_path / "bad.ply").write_bytes(content)
    with pytest.raises(PlyError) as e:
        read_ply(tmp_path / "bad.ply")
    assert words in _one_line(e.value)


def test_unsupported_sh_count(tmp_path):
    props = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0",
             "rot_1", "rot_2", "rot_3"] + [f"f_rest_{i}" for i in range(7)]
    header = "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
    header += "".join(f"property float {p}\n" for p in props) + "end_header\n"
    (tmp_path / "s.ply").write_bytes(header.encode() + bytes(4 * len(props)))
    with pytest.raises(PlyError, match="SH degree"):
        read_ply(tmp_path / "s.ply")


def test_missing_file(tmp_path):
    with pytest.raises(PlyError, match="cannot open"):
        read_ply(tmp_path / "nope.ply")
