"""hexmss.view: the browser viewer served from Python."""

import json
import urllib.error
import urllib.request

import pytest

import hexmss

from conftest import small_scene


def get(url):
    with urllib.request.urlopen(url, timeout=30) as r:
        return r.status, r.read().decode()


def test_view_serves_a_scene_behind_its_token():
    url = hexmss.view(hexmss.Scene.from_dict(small_scene()), open_browser=False)
    try:
        assert url.startswith("http://127.0.0.1:") and "?token=" in url
        status, page = get(url)
        assert status == 200 and "viewer.js?token=" in page
        bare = url.split("?")[0]
        with pytest.raises(urllib.error.HTTPError) as e:
            get(bare)
        assert e.value.code == 403
        with pytest.raises(urllib.error.HTTPError) as e:
            get(url.replace("?token=", "?token=x"))
        assert e.value.code == 403
    finally:
        assert hexmss.stop_views() == 1
    with pytest.raises(urllib.error.URLError):
        get(url)


def test_view_replays_a_run_folder(tmp_path):
    hexmss.run(hexmss.Scene.from_dict(small_scene()), out=tmp_path)
    url = hexmss.view(tmp_path, open_browser=False, paused=True)
    try:
        assert get(url)[0] == 200
    finally:
        hexmss.stop_views()


def test_view_refuses_what_it_cannot_show(tmp_path):
    with pytest.raises(hexmss.SceneError, match="no such scene file or run folder"):
        hexmss.view(tmp_path / "missing.toml", open_browser=False)
    with pytest.raises(hexmss.SceneError, match="lattice.pvd"):
        hexmss.view(tmp_path, open_browser=False)
    with pytest.raises(hexmss.SceneError, match="IP address"):
        hexmss.view(None, host="localhost:80", open_browser=False)
    with pytest.raises(hexmss.SceneError):
        hexmss.view(42, open_browser=False)
    assert hexmss.stop_views() == 0
