import cv2
import pytest

from scenes.__main__ import main


def test_build_info_render(tmp_path, capsys):
    cache = tmp_path / "cache"
    assert main(["build", "window1_brick", "--cache-dir", str(cache)]) == 0
    out = capsys.readouterr().out
    assert "window1_brick:" in out and "Gaussians, built in" in out
    assert main(["build", "window1_brick", "--cache-dir", str(cache)]) == 0
    assert "up to date" in capsys.readouterr().out
    ply = cache / "window1_brick.ply"
    assert main(["info", str(ply)]) == 0
    out = capsys.readouterr().out
    assert "SH degree 0" in out and "bounds" in out and "wall:" in out
    png = tmp_path / "r.png"
    assert main(["render", str(ply), "--width", "64", "--height", "48", "--pose", "1", "0", "-1.5", "-o",
                 str(png)]) == 0
    img = cv2.imread(str(png))
    assert img.shape == (48, 64 * 3, 3)


@pytest.mark.parametrize("argv, words", [
    (["info", "{tmp}/missing.ply"], "cannot open"),
    (["info", "{tmp}/bad.ply"], "truncated"),
    (["render", "window9_brick"], "unknown scene"),
    (["build"], "--suite"),
])
def test_errors_are_one_line(tmp_path, capsys, argv, words):
    props = "x y z f_dc_0 f_dc_1 f_dc_2 opacity scale_0 scale_1 scale_2 rot_0 rot_1 rot_2 rot_3".split()
    header = "ply\nformat binary_little_endian 1.0\nelement vertex 10\n"
    header += "".join(f"property float {p}\n" for p in props) + "end_header\n"
    (tmp_path / "bad.ply").write_bytes(header.encode() + bytes(100))
    rc = main([a.format(tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err
    assert rc == 2
    assert words in err and err.count("\n") == 1 and "Traceback" not in err


def test_help(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for cmd in ("build", "render", "info", "montage"):
        assert cmd in out
