"""The env's render modes (issue 62): an rgb_array frame of the world drawn with the mission figures' map, human
mode that fails on no headless machine, None with gymnasium's warning, and matplotlib loaded only to draw."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import tssac_core.sim.env  # noqa: F401  (registers tssac/<Role>-v0)

STEP = np.array([0.5, 0.0], dtype=np.float32)


def _frames(seed: int, steps: int) -> tuple[np.ndarray, np.ndarray]:
    env = gym.make("tssac/Decoy-v0", render_mode="rgb_array")
    env.reset(seed=seed)
    first = env.render()
    for _ in range(steps):
        env.step(STEP)
    last = env.render()
    env.close()
    return first, last


def test_rgb_array_is_a_frame_of_the_world_now():
    first, last = _frames(seed=3, steps=15)
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3 and first.shape == last.shape
    assert not np.array_equal(first, last)  # the tracks grew, the clock moved
    assert np.array_equal(_frames(seed=3, steps=15)[1], last)  # the same episode, the same picture
    assert not np.array_equal(_frames(seed=4, steps=0)[0], first)  # another layout, another map
    red = (last[..., 0] > 200) & (last[..., 1] < 210) & (last[..., 1] > 150) & (last[..., 2] > 150)
    assert red.sum() > 500  # the radars' coverage (red at alpha 0.25) is drawn


def test_metadata_and_a_bad_mode():
    env = gym.make("tssac/Detect-v0", render_mode="rgb_array")
    assert set(env.metadata["render_modes"]) == {"rgb_array", "human"}
    assert env.metadata["render_fps"] == pytest.approx(1.0)  # one decision per simulated second
    assert gym.make("tssac/Detect-v0", action_repeat=5).metadata["render_fps"] == pytest.approx(2.0)
    with pytest.raises(ValueError, match="render_mode"), pytest.warns(UserWarning, match="ansi"):
        gym.make("tssac/Detect-v0", render_mode="ansi")


def test_no_render_mode_warns_and_returns_none():
    env = gym.make("tssac/Strike-v0")
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.unwrapped.render() is None


def test_human_mode_on_agg_draws_nothing_and_fails_nowhere():
    env = gym.make("tssac/Strike-v0", render_mode="human")
    env.reset(seed=0)
    obs, *_ = env.step(STEP)
    assert env.render() is None
    env.close()
    assert env.unwrapped._canvas is None and env.unwrapped._window is None


def test_matplotlib_is_imported_only_to_draw():
    code = (
        "import sys, gymnasium as gym, tssac_core.sim.env\n"
        "env = gym.make('tssac/Decoy-v0', render_mode='rgb_array'); env.reset(seed=0)\n"
        "before = 'matplotlib' in sys.modules\n"
        "env.render()\n"
        "print(before, 'matplotlib' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.split() == ["False", "True"], out.stderr
