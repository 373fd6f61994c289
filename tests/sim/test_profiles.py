"""The demo-short profile is demo with many short scenes and dense traffic, and nothing else changed."""

from __future__ import annotations

import numpy as np

from zendar_dataset.sim.profiles import PROFILES, get_profile
from zendar_dataset.sim.scene import build_scene


def test_demo_short_differs_from_demo_only_in_scenes_and_traffic():
    demo, short = get_profile("demo").to_json(), get_profile("demo-short").to_json()
    changed = {key for key in demo if demo[key] != short[key]}
    assert changed == {"name", "scene_duration_s", "default_scenes", "n_moving_cars", "reductions"}
    assert short["scene_duration_s"] == 1.0 and short["n_moving_cars"] == [20, 30]
    assert short["reductions"][:-1] == demo["reductions"][:-1]  # every sensor reduction of demo kept
    # demo itself, whose datasets other code reads, is as it was.
    assert demo["scene_duration_s"] == 6.0 and demo["n_moving_cars"] == [5, 10] and demo["default_scenes"] == 5


def test_demo_short_places_more_moving_cars_than_demo():
    placed = {name: [len(build_scene(PROFILES[name], 0, index).world.cars) for index in range(3)]
              for name in ("demo", "demo-short")}
    assert all(5 <= n <= 10 for n in placed["demo"])
    assert all(n <= 30 for n in placed["demo-short"]) and np.mean(placed["demo-short"]) > np.mean(placed["demo"]) + 5
