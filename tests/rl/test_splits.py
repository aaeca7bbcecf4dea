"""Building splits, episode specs and EnvConfig.building_seeds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import sim  # noqa: F401  (registers DepthNav-v0)
from autonomy.common.errors import InputError
from sim.envs.config import EnvConfig
from sim.rl.splits import (
    BENCHMARK_TASK,
    LEARNER_OBS,
    SPLITS,
    EpisodeSpec,
    Split,
    episode_specs,
    get_split,
    split_env_kwargs,
)
from tests.helpers import GL

needs_gl = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")


def test_splits_are_disjoint_and_sized() -> None:
    assert {k: len(s.building_seeds) for k, s in SPLITS.items()} == {"train": 16, "val": 4, "test": 4}
    seeds = [b for s in SPLITS.values() for b in s.building_seeds]
    assert len(seeds) == len(set(seeds)) == 24
    assert len({s.episode_seed for s in SPLITS.values()}) == 3
    for name, s in SPLITS.items():
        assert s.name == name and get_split(name) is s and get_split(s) is s


def test_get_split_error_names_the_choices() -> None:
    with pytest.raises(InputError, match=r"split 'dev' unknown.*train, val, test"):
        get_split("dev")


def test_episode_specs_cycle_buildings_and_are_deterministic() -> None:
    specs = episode_specs("val", 10, seed=3)
    assert specs == episode_specs("val", 10, seed=3)
    assert [s.index for s in specs] == list(range(10))
    assert [s.building_seed for s in specs] == [2000, 2001, 2002, 2003] * 2 + [2000, 2001]
    assert len({s.reset_seed for s in specs}) == 10
    assert all(0 <= s.reset_seed < 2**63 for s in specs)
    # a prefix of a longer list: 5 episodes are the first 5 of 50
    assert episode_specs("val", 5, seed=3) == specs[:5]
    # another seed or another split: other reset seeds
    assert not {s.reset_seed for s in specs} & {s.reset_seed for s in episode_specs("val", 10, seed=4)}
    assert not {s.reset_seed for s in specs} & {s.reset_seed for s in episode_specs("test", 10, seed=3)}
    # the reset seed is a hash of (episode_seed, seed, k): an independent reference
    ref = np.random.SeedSequence([202, 3, 7]).generate_state(1, np.uint64)[0] >> np.uint64(1)
    assert specs[7] == EpisodeSpec(7, 2003, int(ref))


def test_episode_specs_of_a_custom_split() -> None:
    sp = Split("mine", (5, 9), 1, "two buildings")
    assert [s.building_seed for s in episode_specs(sp, 3)] == [5, 9, 5]


@pytest.mark.parametrize("episodes, seed, pattern", [(0, 0, "episodes"), (2.5, 0, "episodes"), (3, -1, "seed")])
def test_episode_specs_bad_arguments(episodes, seed, pattern) -> None:
    with pytest.raises(InputError, match=pattern):
        episode_specs("val", episodes, seed)


def test_split_env_kwargs() -> None:
    kw = split_env_kwargs("train", **LEARNER_OBS, max_steps=20)
    assert kw["building"] == "procedural" and kw["building_seeds"] == SPLITS["train"].building_seeds
    assert kw["max_steps"] == 20 and kw["depth_dtype"] == "uint8"
    assert {k: kw[k] for k in BENCHMARK_TASK if k != "max_steps"} == {k: v for k, v in BENCHMARK_TASK.items() if k != "max_steps"}
    cfg = EnvConfig(**kw)
    assert cfg.building_seeds == tuple(range(1000, 1016)) and cfg.terminate_on_collision is False


@pytest.mark.parametrize(
    "kw, pattern",
    [
        (dict(building="small_floor", building_seeds=(1,)), "building_seeds"),
        (dict(building="procedural", building_seeds=(1, -2)), "building_seeds.*>= 0"),
        (dict(building="procedural", building_seed=4, building_seeds=(1,)), "building_seeds.*building_seed"),
        (dict(building="procedural", building_seeds=(1.5,)), "building_seeds"),
    ],
)
def test_building_seeds_checks(kw, pattern) -> None:
    with pytest.raises(InputError, match=pattern):
        EnvConfig(**kw)


@needs_gl
def test_building_seeds_draw_from_the_set_reproducibly() -> None:
    seeds = (2000, 2001, 2002)
    env = gym.make("DepthNav-v0", building="procedural", building_seeds=seeds, max_steps=5)
    twin = gym.make("DepthNav-v0", building="procedural", building_seeds=seeds, max_steps=5)
    try:
        drawn = []
        for s in range(8):
            obs, info = env.reset(seed=s)
            drawn.append(env.unwrapped.site.seed)
            obs2, info2 = twin.reset(seed=s)
            assert twin.unwrapped.site.seed == drawn[-1]
            np.testing.assert_array_equal(obs["depth"], obs2["depth"])
            np.testing.assert_array_equal(info["pose"], info2["pose"])
        assert set(drawn) <= set(seeds) and len(set(drawn)) >= 2
        # the same seed again (after other episodes): the same building and start
        obs, info = env.reset(seed=3)
        assert env.unwrapped.site.seed == drawn[3]
        _, info3 = twin.reset(seed=3)
        np.testing.assert_array_equal(info["pose"], info3["pose"])
        np.testing.assert_array_equal(info["goal"], info3["goal"])
        # the building is the generator's for that seed
        from sim.envs.site import procedural_building

        b = procedural_building(env.unwrapped.config, drawn[3])
        np.testing.assert_array_equal(env.unwrapped.site.building.vectormap.segments, b.vectormap.segments)
    finally:
        env.close()
        twin.close()
