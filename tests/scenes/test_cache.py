"""The scene cache's size limit (scenes.cache) and its use by build_cached and ``flowgap-scenes cache``."""

from __future__ import annotations

import dataclasses
import os

import pytest

from scenes import cache as scene_cache
from scenes.__main__ import main as scenes_main
from scenes.build import build_cached, cache_paths
from scenes.library import suite_spec
from scenes.spec import SpecError, SplatDensity

NOW = 1_000_000.0


def _fake_scene(root, name, mb, last_used):
    """A cached scene's four files, ``mb`` MB in all, last used at ``last_used``."""
    root.mkdir(parents=True, exist_ok=True)
    for suffix, size in ((".ply", int(mb * 1e6) - 300), (".ply.labels.npy", 100), (".json", 100), (".key", 100)):
        path = root / (name + suffix)
        path.write_bytes(b"x" * size)
        os.utime(path, (last_used, last_used))


def _names(listed):
    return [e.name for e in listed]


def test_entries_are_listed_least_recently_used_first_with_their_sizes(tmp_path):
    _fake_scene(tmp_path, "b", 2, NOW - 100)
    _fake_scene(tmp_path, "a", 1, NOW - 50)
    _fake_scene(tmp_path, "c", 3, NOW - 300)
    (tmp_path / "orphan.ply").write_bytes(b"x" * 10)            # no key: not a built scene
    listed = scene_cache.entries(tmp_path)
    assert _names(listed) == ["c", "b", "a"]
    assert [e.bytes for e in listed] == [3_000_000, 2_000_000, 1_000_000]
    assert len(listed[0].files) == 4


def test_prune_removes_the_least_recently_used_until_within_the_limit(tmp_path):
    for i, name in enumerate("abcd"):
        _fake_scene(tmp_path, name, 1, NOW - 10_000 + i)           # a is the oldest
    removed = scene_cache.prune(tmp_path, 2_500_000, now=NOW)
    assert _names(removed) == ["a", "b"]
    assert _names(scene_cache.entries(tmp_path)) == ["c", "d"]
    assert not list(tmp_path.glob("a.*")) and not list(tmp_path.glob("b.*"))


def test_prune_spares_kept_and_recently_used_scenes_even_over_the_limit(tmp_path):
    _fake_scene(tmp_path, "old", 1, NOW - 10_000)
    _fake_scene(tmp_path, "kept", 1, NOW - 9_000)
    _fake_scene(tmp_path, "in_use", 1, NOW - 60)                 # another flight may be reading it
    removed = scene_cache.prune(tmp_path, 0, keep=("kept",), now=NOW)
    assert _names(removed) == ["old"]
    assert _names(scene_cache.entries(tmp_path)) == ["kept", "in_use"]
    assert scene_cache.prune(tmp_path, None, now=NOW) == []      # no limit: nothing goes


def test_limit_reads_megabytes_from_the_environment_and_refuses_nonsense():
    assert scene_cache.limit_bytes({}) == scene_cache.DEFAULT_LIMIT_MB * 1_000_000
    assert scene_cache.limit_bytes({scene_cache.LIMIT_ENV: "250"}) == 250_000_000
    assert scene_cache.limit_bytes({scene_cache.LIMIT_ENV: "0"}) is None
    for bad in ("lots", "-5", "nan", "inf"):
        with pytest.raises(SpecError, match="FLOWGAP_SCENE_CACHE_MB"):
            scene_cache.limit_bytes({scene_cache.LIMIT_ENV: bad})


def _light(name):
    spec = suite_spec("window2", "granite")
    return dataclasses.replace(spec, name=name, density=SplatDensity(wall_spacing=0.04, background_spacing=0.06,
                                                                     floor_spacing=0.08))


def test_a_build_prunes_old_scenes_beyond_the_limit_and_a_hit_marks_its_scene_used(tmp_path, monkeypatch):
    monkeypatch.setenv(scene_cache.LIMIT_ENV, "0.5")              # smaller than any scene: only the new one stays
    _fake_scene(tmp_path, "stale", 1, NOW - 10_000)
    spec = _light("fresh")
    ply, built = build_cached(spec, tmp_path)
    assert built and ply.exists()
    assert _names(scene_cache.entries(tmp_path)) == ["fresh"]

    key = cache_paths(spec, tmp_path)[2]
    os.utime(key, (NOW, NOW))
    _, built = build_cached(spec, tmp_path)
    assert not built and key.stat().st_mtime > NOW + 1e6       # touched now, not at the fake old time


def test_a_bad_limit_stops_the_build_before_it_starts(tmp_path, monkeypatch):
    monkeypatch.setenv(scene_cache.LIMIT_ENV, "big")
    with pytest.raises(SpecError, match="not a size in MB"):
        build_cached(_light("never"), tmp_path)
    assert not list(tmp_path.iterdir())


def test_cli_reports_prunes_and_clears(tmp_path, monkeypatch, capsys):
    _fake_scene(tmp_path, "a", 2, NOW - 10_000)
    _fake_scene(tmp_path, "b", 2, NOW - 9_000)
    monkeypatch.setenv(scene_cache.LIMIT_ENV, "3")
    assert scenes_main(["cache", "--cache-dir", str(tmp_path)]) == 0
    assert "2 scenes, 4 MB (limit 3 MB" in capsys.readouterr().out
    assert scenes_main(["cache", "--cache-dir", str(tmp_path), "--prune"]) == 0
    out = capsys.readouterr().out
    assert "removed 1 scene (2 MB)" in out and "1 scene, 2 MB" in out
    os.utime(tmp_path / "b.key")                                   # used just now: --clear removes it all the same
    assert scenes_main(["cache", "--cache-dir", str(tmp_path), "--clear"]) == 0
    assert "0 scenes, 0 MB" in capsys.readouterr().out
    assert not list(tmp_path.iterdir())
    monkeypatch.setenv(scene_cache.LIMIT_ENV, "x")
    assert scenes_main(["cache", "--cache-dir", str(tmp_path)]) == 2
    assert "FLOWGAP_SCENE_CACHE_MB" in capsys.readouterr().err
