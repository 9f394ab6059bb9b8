"""The plugin system: built-ins by module path, third-party plugins by entry point.

The sample package ``labauto-sample-plugin`` (tests/sample_plugin) is installed by the test
setup (``make install``); its ``sample`` entry point implements every hook and its ``broken``
entry point fails on import. Each hookspec has a test named ``test_hook_<hookspec name>``; the
last test fails when one is missing.
"""

from __future__ import annotations

import inspect
import sys

import numpy as np
import pytest

# installed by the test setup (`make install`); a missing install must fail, not skip
import labauto_sample_plugin
from labauto import hookspecs
from labauto.plugin_manager import load_plugins
from labauto.synthetic.shapes import ellipse, render


@pytest.fixture(scope="module")
def plugins():
    return load_plugins()


@pytest.fixture()
def scene() -> np.ndarray:
    gray = render([ellipse((60.3, 50.7), (30.0, 18.0), 20.0)], 120, 100)
    return np.dstack([gray, gray // 2, gray])


def test_sample_plugin_loads_through_its_entry_point(plugins):
    info = {p.name: p for p in plugins.loaded}
    assert "sample" in info
    assert info["sample"].version == "0.3.1"
    assert info["sample"].source.startswith("entry point labauto_sample_plugin")
    assert set(info["sample"].hooks) == {
        name for name in dir(hookspecs) if name.startswith("labauto_")
    }


def test_broken_plugin_is_reported_by_name_and_skipped(plugins):
    failures = {f.name: f for f in plugins.failed}
    assert "broken" in failures
    assert "RuntimeError" in failures["broken"].error
    assert "broken on purpose" in failures["broken"].error
    assert "broken" not in {p.name for p in plugins.loaded}
    # the rest still works
    assert {"vision", "plate", "devices", "sample"} <= {p.name for p in plugins.loaded}


def test_allow_list_loads_only_named_plugins():
    only = load_plugins(enabled=["vision"])
    assert [p.name for p in only.loaded] == ["vision"]
    assert only.failed == []
    assert set(only.registry.segmenters) == {"canny", "color"}


def test_block_list_skips_named_plugins():
    some = load_plugins(disabled=["sample", "broken"])
    names = {p.name for p in some.loaded}
    assert "sample" not in names and "vision" in names
    assert "sample-threshold" not in some.registry.segmenters
    assert some.failed == []


def test_failing_registration_drops_the_plugin_whole():
    module = type(sys)("half_broken_plugin")

    @hookspecs.hookimpl
    def labauto_register_segmenters(register):
        register("half", lambda image, params: None)
        register("bad", "not callable")

    module.labauto_register_segmenters = labauto_register_segmenters
    sys.modules["half_broken_plugin"] = module
    try:
        loaded = load_plugins(builtins=("half_broken_plugin",), use_entry_points=False)
    finally:
        del sys.modules["half_broken_plugin"]
    assert loaded.loaded == []
    assert loaded.failed[0].name == "half_broken_plugin"
    assert "not callable" in loaded.failed[0].error
    assert "half" not in loaded.registry.segmenters


def test_unknown_component_error_lists_what_is_loaded(plugins):
    from labauto.errors import PluginError

    with pytest.raises(PluginError, match=r"no segmenter named 'nope' \(loaded: .*canny"):
        plugins.registry.get("segmenters", "nope")


def test_hook_labauto_register_segmenters(plugins, scene):
    import labauto

    assert {"canny", "color", "sample-threshold"} <= set(plugins.registry.segmenters)
    result = labauto.detect(scene, "sample-threshold", plugins=plugins)
    assert result.method == "sample-threshold"
    assert len(result.objects) == 1 and result.objects[0].is_des
    builtin = labauto.detect(scene, "canny", plugins=plugins)
    assert builtin.method == "canny" and any(o.is_des for o in builtin.objects)


def test_hook_labauto_register_classifiers(plugins, scene):
    import labauto

    result = labauto.detect(scene, "canny", plugins=plugins)
    labels = plugins.registry.get("classifiers", "sample-size")(scene, result)
    assert len(labels) == len(result.objects) and set(labels) <= {"large", "small"}
    assert plugins.registry.get("classifiers", "des")(scene, result).count("des") >= 1
    shapes = plugins.registry.get("classifiers", "shape")(scene, result)
    assert shapes == [o.shape for o in result.objects]


def test_hook_labauto_register_applications(plugins, scene):
    assert "plate" in plugins.registry.applications
    counted = plugins.registry.get("applications", "sample-count")(scene, None)
    assert counted.to_dict() == {"count": 1}


def test_hook_labauto_register_drivers(plugins):
    camera = plugins.registry.driver("camera", "sample-noise")(None)
    frames = list(camera)
    assert len(frames) == 2 and frames[0][1].shape == (64, 80, 3)
    assert {("robot", "grbl"), ("analyzer", "modbus"), ("camera", "folder")} <= set(
        plugins.registry.drivers
    )


def _events(kind: str) -> list[dict]:
    return [kw for name, kw in labauto_sample_plugin.EVENTS if name == kind]


def test_hook_labauto_detections_stored(plugins):
    before = len(_events("detections_stored"))
    plugins.hook.labauto_detections_stored(run_id=7, image_id=3, plate="p1", count=12)
    assert _events("detections_stored")[before:] == [
        {"run_id": 7, "image_id": 3, "plate": "p1", "count": 12}
    ]


def test_hook_labauto_pick_finished(plugins):
    before = len(_events("pick_finished"))
    plugins.hook.labauto_pick_finished(run_id=7, pick={"id": 1, "state": "analyzed"})
    assert _events("pick_finished")[before:][0]["pick"]["state"] == "analyzed"


def test_hook_labauto_run_finished(plugins):
    before = len(_events("run_finished"))
    plugins.hook.labauto_run_finished(run_id=7, state="succeeded", summary={"picks": 2})
    assert _events("run_finished")[before:] == [
        {"run_id": 7, "state": "succeeded", "summary": {"picks": 2}}
    ]


def test_every_hookspec_has_a_test_of_its_own():
    specs = {name for name, _ in inspect.getmembers(hookspecs) if name.startswith("labauto_")}
    tested = {
        name.removeprefix("test_hook_") for name in globals() if name.startswith("test_hook_")
    }
    missing = specs - tested
    assert not missing, f"hookspecs without a test_hook_<name> test: {sorted(missing)}"
    assert len(specs) == 7
