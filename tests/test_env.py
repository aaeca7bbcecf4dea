"""The gymnasium environment DepthNav-v0 (sim/env.py): API, seeding, rewards, vector envs."""

from __future__ import annotations

import functools
import math
import subprocess
import sys
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sim  # noqa: F401  (registers DepthNav-v0)
from autonomy.common.errors import InputError
from sim.envs.depthnav import DepthNavEnv, EnvConfig, make
from sim.envs.geometry import GeodesicField, KCScanner
from sim.scenario import SCENARIOS_DIR, LocalizationConfig
from tests.helpers import GL

pytestmark = pytest.mark.skipif(not GL, reason="no OpenGL (EGL/OSMesa) context on this machine")

ROOT = Path(__file__).resolve().parent.parent

VARIANTS = {
    "default": {},
    "all_keys": dict(observe_points=256, observe_scan=165, observe_pose_estimate=True),
    "procedural_actors_truth_goal": dict(building="procedural", n_people=2, n_furniture=3, goal_from_truth=True),
    "dead_reckoning": dict(localization=LocalizationConfig(enabled=False), observe_scan=32),
}


def _rollout(env: gym.Env, seed: int, n: int, action_seed: int = 0) -> tuple[list, list, list]:
    obs, info = env.reset(seed=seed)
    rng = np.random.default_rng(action_seed)
    observations, infos, rewards = [obs], [info], []
    for _ in range(n):
        a = rng.uniform(-1, 1, 3).astype(np.float32)
        a[0] = abs(a[0])
        obs, r, term, trunc, info = env.step(a)
        observations.append(obs)
        infos.append(info)
        rewards.append(r)
        if term or trunc:
            obs, info = env.reset()
            observations.append(obs)
            infos.append(info)
    return observations, infos, rewards


def _same_obs(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_import_sim_registers_without_importing_mujoco() -> None:
    code = (
        "import sys, sim, gymnasium as gym; "
        "assert 'DepthNav-v0' in gym.registry, 'not registered'; "
        "assert gym.registry['DepthNav-v0'].entry_point == 'sim.envs.depthnav:DepthNavEnv'; "
        "assert 'mujoco' not in sys.modules, 'mujoco imported eagerly'"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_check_env_passes(variant: str) -> None:
    env = gym.make("DepthNav-v0", **VARIANTS[variant])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    msgs = [str(w.message) for w in caught if "gymnasium" in str(w.filename) or "env_checker" in str(w.message)]
    assert not msgs, msgs
    env.close()


def test_spaces_and_docstring_tables() -> None:
    env = DepthNavEnv(observe_points=64, observe_scan=40, observe_pose_estimate=True)
    obs_space = env.observation_space
    assert set(obs_space.spaces) == {"depth", "goal", "odometry", "points", "scan", "pose_estimate"}
    assert obs_space["depth"].shape == (120, 160, 1) and obs_space["depth"].dtype == np.float32
    assert obs_space["points"].shape == (64, 8) and obs_space["scan"].shape == (40,)
    assert env.action_space.shape == (3,) and float(env.action_space.low.min()) == -1.0
    assert env.metadata["render_fps"] == 30 and set(env.metadata["render_modes"]) == {"rgb_array", "depth"}
    doc = DepthNavEnv.__doc__
    for heading in ("## Action space", "## Observation space", "## Rewards", "## Info"):
        assert heading in doc
    for key in obs_space.spaces:
        assert f"``{key}``" in doc
    env.close()


def test_same_seed_same_episode_and_different_seed_differs() -> None:
    kw = dict(building="procedural", n_people=2, n_furniture=2, observe_points=128, observe_scan=50, observe_pose_estimate=True, max_steps=40)
    env = gym.make("DepthNav-v0", **kw)
    o1, i1, r1 = _rollout(env, 5, 60)
    o2, i2, r2 = _rollout(env, 5, 60)
    other = gym.make("DepthNav-v0", **kw)  # a fresh instance, too
    o3, i3, r3 = _rollout(other, 5, 60)
    assert len(o1) == len(o2) == len(o3) and len(o1) > 61  # one reset after the 40-step limit
    for a, b, c in zip(o1, o2, o3, strict=True):
        assert _same_obs(a, b) and _same_obs(a, c)
    for a, b, c in zip(i1, i2, i3, strict=True):
        assert np.array_equal(a["pose"], b["pose"]) and np.array_equal(a["pose"], c["pose"])
        assert np.array_equal(a["pose_estimate"], b["pose_estimate"])
    assert r1 == r2 == r3
    o4, i4, _ = _rollout(env, 6, 5)
    assert not np.array_equal(o4[0]["depth"], o1[0]["depth"]) or not np.array_equal(i4[0]["pose"], i1[0]["pose"])
    env.close()
    other.close()


def test_noise_draws_come_from_np_random() -> None:
    """The same state twice in a row (generator not re-seeded): a different noisy frame."""
    env = DepthNavEnv()
    opts = {"start_pose": (3.0, 5.1, 0.3), "goal": (8.0, 5.1)}
    obs_a, info_a = env.reset(seed=1, options=opts)
    obs_b, info_b = env.reset(options=opts)
    assert np.array_equal(info_a["pose"], info_b["pose"])
    assert not np.array_equal(obs_a["depth"], obs_b["depth"])
    obs_c, _ = env.reset(seed=1, options=opts)
    assert np.array_equal(obs_a["depth"], obs_c["depth"])
    env.close()


def test_reward_is_exactly_the_sum_of_its_terms() -> None:
    env = gym.make("DepthNav-v0", n_people=2, max_steps=80)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(150):
        obs, reward, term, trunc, info = env.step(rng.uniform(-1, 1, 3).astype(np.float32))
        terms = info["reward_terms"]
        assert list(terms) == ["progress", "success", "collision", "time", "clearance"] and terms["clearance"] == 0.0
        assert reward == sum(terms.values())
        assert terms["time"] == -0.01
        assert terms["collision"] == (-10.0 if info["collided"] else 0.0)
        if term or trunc:
            env.reset()
    env.close()


def test_progress_term_follows_the_geodesic_distance() -> None:
    env = DepthNavEnv(goal_from_truth=True)
    _, info = env.reset(seed=0, options={"start_pose": (2.0, 5.1, 0.0), "goal": (8.0, 5.1)})
    d0 = info["goal_distance_m"]
    assert d0 == pytest.approx(6.0, abs=1e-9)
    total = 0.0
    for _ in range(30):
        obs, r, term, trunc, info = env.step(np.array([1.0, 0.0, 0.0], np.float32))
        total += info["reward_terms"]["progress"]
        assert not term
    assert total == pytest.approx(d0 - info["goal_distance_m"], abs=1e-9)
    assert 0.3 < total < 1.0  # about 0.5 m in 1 s from standstill at 1 m/s^2
    # The goal observation is the goal in the robot frame (here of the true pose).
    x, y, th = info["pose"]
    c, s = math.cos(th), math.sin(th)
    gx, gy = 8.0 - x, 5.1 - y
    np.testing.assert_allclose(obs["goal"], [c * gx + s * gy, -s * gx + c * gy], atol=1e-5)
    env.close()


def test_geodesic_distance_goes_around_walls() -> None:
    from sim.simulator import blueprints

    bp = blueprints.load_blueprint("small_floor")
    # Goal inside the north-west office (door near x = 3.9 on the wall y = 6.2).
    f = GeodesicField(bp.navgraph, np.asarray(bp.vectormap.segments), np.array([2.0, 8.0]), 8.0)
    d_corr, _ = f.distance(np.array([2.0, 5.1]))  # just across the wall, 2.9 m in a straight line
    assert d_corr > 2.9 + 1.0
    path = f.path(np.array([2.0, 5.1]))
    assert np.allclose(path[0], [2.0, 5.1]) and np.allclose(path[-1], [2.0, 8.0])
    d_in, _ = f.distance(np.array([2.5, 8.5]))
    assert d_in == pytest.approx(math.hypot(0.5, 0.5))


@pytest.mark.parametrize("terminate", [True, False])
def test_a_collision_terminates(terminate: bool) -> None:
    env = DepthNavEnv(terminate_on_collision=terminate, max_steps=200)
    # In the corridor, facing the west wall (x = 0) 0.7 m from the base's edge.
    env.reset(seed=0, options={"start_pose": (1.0, 5.1, math.pi), "goal": (8.0, 5.1)})
    hit = None
    for k in range(150):
        obs, r, term, trunc, info = env.step(np.array([1.0, 0.0, 0.0], np.float32))
        if info["collided"]:
            hit = k
            assert info["collisions"] == 1
            assert info["reward_terms"]["collision"] == -10.0
            assert term is terminate
            break
        assert not term
    assert hit is not None and hit < 90
    assert 0.3 - 0.02 < info["pose"][0] < 0.35
    env.close()


def test_success_terminates_with_the_success_reward() -> None:
    env = DepthNavEnv()
    env.reset(seed=0, options={"start_pose": (3.0, 5.1, 0.0), "goal": (3.3, 5.1)})
    obs, r, term, trunc, info = env.step(np.zeros(3, np.float32))
    assert term and not trunc and info["success"] and info["is_success"]
    assert info["reward_terms"]["success"] == 10.0
    env.close()
    env = DepthNavEnv(terminate_on_success=False)
    env.reset(seed=0, options={"start_pose": (3.0, 5.1, 0.0), "goal": (3.3, 5.1)})
    rewards = [env.step(np.zeros(3, np.float32))[4]["reward_terms"]["success"] for _ in range(3)]
    assert rewards == [10.0, 0.0, 0.0]  # once per episode
    env.close()


def test_truncates_at_the_step_limit() -> None:
    env = DepthNavEnv(max_steps=5)
    env.reset(seed=2, options={"start_pose": (3.0, 5.1, 0.0), "goal": (8.0, 5.1)})
    flags = [env.step(np.zeros(3, np.float32))[2:4] for _ in range(5)]
    assert flags == [(False, False)] * 4 + [(False, True)]
    env.close()


def test_registration_time_limit_is_the_benchmark_max_steps() -> None:
    from sim.rl.splits import BENCHMARK_TASK

    assert gym.spec("DepthNav-v0").max_episode_steps == sim.MAX_EPISODE_STEPS == 1000
    assert BENCHMARK_TASK["max_steps"] == EnvConfig().max_steps == sim.MAX_EPISODE_STEPS


def _flags(env: gym.Env, n: int) -> list[tuple[bool, bool]]:
    """(terminated, truncated) of standing still from a fixed start, until the episode ends."""
    env.reset(seed=2, options={"start_pose": (3.0, 5.1, 0.0), "goal": (8.0, 5.1)})
    out = []
    for _ in range(n):
        out.append(tuple(bool(f) for f in env.step(np.zeros(3, np.float32))[2:4]))
        if any(out[-1]):
            break
    return out


def test_time_limit_and_max_steps_agree() -> None:
    """gym.make's TimeLimit (the registered 1000 steps) never cuts an episode the env
    would not: a shorter max_steps truncates as the bare env does, and make() puts the
    wrapper at the env's own max_steps, a longer one included."""
    kw = dict(max_steps=6, localization=LocalizationConfig(enabled=False))
    bare = DepthNavEnv(**kw)
    expected = _flags(bare, 20)
    bare.close()
    assert expected == [(False, False)] * 5 + [(False, True)]
    made = gym.make("DepthNav-v0", **kw)
    own = make(**kw)
    try:
        assert made.spec.max_episode_steps == 1000 and own.spec.max_episode_steps == 6
        assert _flags(made, 20) == _flags(own, 20) == expected
    finally:
        made.close()
        own.close()
    # a max_episode_steps given to gymnasium still wins: the wrapper then cuts first
    cut = make(max_steps=6, max_episode_steps=4, localization=LocalizationConfig(enabled=False))
    try:
        assert _flags(cut, 20) == [(False, False)] * 3 + [(False, True)]
    finally:
        cut.close()
    # longer than the registration: a scenario's mission limit is kept, not cut at 1000
    long = make(scenario=SCENARIOS_DIR / "demo.toml")
    assert long.spec.max_episode_steps == long.unwrapped.config.max_steps == 36000
    long.close()
    assert make(scenario=SCENARIOS_DIR / "demo.toml", max_steps=10).spec.max_episode_steps == 10


def test_check_env_passes_on_the_made_env() -> None:
    """check_env on what gym.make returns (the TimeLimit and checker wrappers included),
    not only on the bare env; its one advice about wrappers aside."""
    env = gym.make("DepthNav-v0")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env)
    msgs = [str(w.message) for w in caught if "gymnasium" in str(w.filename) or "env_checker" in str(w.message)]
    assert any("different from the unwrapped version" in m for m in msgs)  # the wrappers are there
    msgs = [m for m in msgs if "different from the unwrapped version" not in m]
    assert not msgs, msgs
    env.close()


def test_random_steps_on_procedural_buildings_stay_in_their_spaces() -> None:
    env = gym.make(
        "DepthNav-v0",
        building="procedural",
        n_people=2,
        n_furniture=2,
        observe_points=128,
        observe_scan=64,
        observe_pose_estimate=True,
        max_steps=60,
        terminate_on_collision=False,
    )
    space = env.observation_space
    obs, info = env.reset(seed=11)
    buildings = {env.unwrapped.site.seed}
    for _ in range(300):
        assert space.contains(obs), {k: space[k].contains(v) for k, v in obs.items()}
        for v in obs.values():
            assert not np.isnan(v).any()
        assert np.all(np.isfinite(info["pose"])) and math.isfinite(info["loc_error_m"])
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert math.isfinite(r)
        if term or trunc:
            obs, info = env.reset()
            buildings.add(env.unwrapped.site.seed)
    assert len(buildings) >= 4  # a new building every episode
    assert (obs["depth"] > 0).any()
    env.close()


def test_building_schedule() -> None:
    env = DepthNavEnv(building="procedural", new_building_every=2)
    seeds = []
    env.reset(seed=1)
    seeds.append(env.site.seed)
    for _ in range(4):
        env.reset()
        seeds.append(env.site.seed)
    assert seeds[0] == seeds[1] and seeds[1] != seeds[2] and seeds[2] == seeds[3] and seeds[3] != seeds[4]
    env.reset(seed=1)
    assert env.site.seed == seeds[0]
    fixed = DepthNavEnv(building="procedural", building_seed=4)
    fixed.reset(seed=1)
    site = fixed.site
    fixed.reset(seed=2)
    assert fixed.site is site
    env.close()
    fixed.close()


def test_scan_and_points_see_a_wall_at_the_right_distance() -> None:
    env = DepthNavEnv(observe_scan=80, observe_points=2000, goal_from_truth=True)
    # Facing the west wall (x = 0) from x = 3 in the corridor: the camera is 0.22 m ahead.
    obs, _ = env.reset(seed=0, options={"start_pose": (3.0, 5.1, math.pi), "goal": (8.0, 5.1)})
    scan = obs["scan"]
    centre = scan[30:50]
    assert (centre > 0).all()
    assert np.median(centre) == pytest.approx(3.0 - 0.22, abs=0.05)  # the seen face lies on the map line
    pts = obs["points"]
    # Plane points on the corridor's side walls (y = 4 and 6.2, faces 1 cm inside).
    side = pts[(pts[:, 7] == 1) & (pts[:, 6] == 1) & (np.abs(pts[:, 4]) > 0.9)]
    assert len(side) > 20
    np.testing.assert_allclose(np.abs(side[:, 1]), 1.09, atol=0.05)
    # The scanner's own geometry: bins span the horizontal field of view.
    sc = env._observations.scanner
    assert isinstance(sc, KCScanner)
    assert sc.angles[0] == pytest.approx(-env.intrinsics.fov_h_rad / 2 + env.intrinsics.fov_h_rad / 160)
    env.close()


def test_render_modes() -> None:
    env = DepthNavEnv(render_mode="rgb_array", n_people=2, n_furniture=2)
    env.reset(seed=4)
    env.step(env.action_space.sample())
    img = env.render()
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 5
    env.close()
    env = DepthNavEnv(render_mode="depth")
    obs, _ = env.reset(seed=4)
    img = env.render()
    assert img.shape == (240, 320, 3) and img.dtype == np.uint8
    assert ((img.sum(axis=2) == 0)[::2, ::2] == (obs["depth"][..., 0] <= 0)).all()
    env.close()
    env = DepthNavEnv()
    env.reset(seed=4)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None
    env.close()


def test_from_scenario() -> None:
    cfg = EnvConfig.from_scenario(SCENARIOS_DIR / "demo.toml", ['map.name="small_floor"'], observe_scan=8)
    assert cfg.building == "small_floor" and cfg.n_people == 6 and cfg.n_furniture == 8
    assert cfg.odometry.translation_noise == 0.05 and cfg.max_steps == 36000 and cfg.observe_scan == 8
    env = DepthNavEnv(scenario=SCENARIOS_DIR / "demo.toml", max_steps=10)
    assert env.config.building == "corridor_loop"
    obs, info = env.reset(seed=0)
    assert obs["depth"].shape == (120, 160, 1)
    env.step(env.action_space.sample())
    env.close()


def test_buildings_from_files(tmp_path: Path) -> None:
    from sim.simulator import blueprints

    bp = blueprints.generate_building(blueprints.BuildingConfig(width_m=30.0, height_m=24.0), 9)
    blueprints.save_blueprint(bp, tmp_path / "b9")
    env = DepthNavEnv(building=str(tmp_path / "b9"), n_furniture=2)
    _, info = env.reset(seed=0)
    assert env.site.building.vectormap.n_segments == bp.vectormap.n_segments
    env.step(env.action_space.sample())
    env.close()
    env = DepthNavEnv(building="", vectormap=str(tmp_path / "b9.vectormap.txt"), navgraph=str(tmp_path / "b9.navigation.json"))
    env.reset(seed=0)
    env.step(env.action_space.sample())
    env.close()
    # A map without zones takes random furniture in its free space.
    env = DepthNavEnv(building="", vectormap=str(tmp_path / "b9.vectormap.txt"), navgraph=str(tmp_path / "b9.navigation.json"), n_furniture=1)
    env.reset(seed=0)
    assert abs(env.site.furniture[0].x) < 100.0
    env.close()


def test_env_pickles_before_reset() -> None:
    import pickle

    env = DepthNavEnv(observe_scan=8, observe_points=8)
    clone = pickle.loads(pickle.dumps(env))
    obs, _ = clone.reset(seed=0)
    assert clone.observation_space.contains(obs)
    clone.close()


@pytest.mark.parametrize(
    ("kwargs", "needle"),
    [
        (dict(bogus=1), "unknown argument 'bogus'"),
        (dict(depth_shape=(100, 160)), "'depth_shape'"),
        (dict(max_steps=0), "'max_steps'"),
        (dict(max_steps=2.5), "'max_steps' expected an integer"),
        (dict(building="no_such_building"), "'building'"),
        (dict(observe_pose_estimate=True, localization=LocalizationConfig(enabled=False)), "'observe_pose_estimate'"),
        (dict(start_nodes=(99999,)), "'start_nodes'"),
        (dict(render_mode="human"), "'render_mode'"),
        (dict(building="", navgraph="x.json"), "'vectormap', optionally with 'navgraph'"),
        (dict(building="", vectormap="x.txt"), "argument 'vectormap' expected an existing file"),
    ],
)
def test_bad_arguments_are_input_errors(kwargs: dict, needle: str) -> None:
    with pytest.raises(InputError, match=needle) as exc:
        DepthNavEnv(**kwargs)
    assert "\n" not in str(exc.value)


def test_bad_actions_and_options() -> None:
    env = DepthNavEnv()
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(3))
    env.reset(seed=0)
    with pytest.raises(InputError, match="shape"):
        env.step(np.zeros(2))
    with pytest.raises(InputError, match="finite"):
        env.step(np.array([np.nan, 0, 0]))
    with pytest.raises(InputError, match="start_pose"):
        env.reset(options={"start_pose": (1, 2)})
    with pytest.raises(InputError, match="'teleport'"):
        env.reset(options={"teleport": 1})
    env.close()
    env.close()  # closing twice is fine


def test_sync_vector_env_steps() -> None:
    venv = gym.vector.SyncVectorEnv([functools.partial(DepthNavEnv, observe_scan=16)] * 2)
    obs, info = venv.reset(seed=[1, 2])
    assert obs["depth"].shape == (2, 120, 160, 1) and obs["scan"].shape == (2, 16)
    for _ in range(5):
        obs, r, term, trunc, info = venv.step(venv.action_space.sample())
    assert r.shape == (2,) and info["pose"].shape == (2, 3)
    venv.close()


def test_async_vector_env_with_two_workers_steps_like_single_envs() -> None:
    # spawn: the workers start clean of this test process's numba thread pools.
    venv = gym.vector.AsyncVectorEnv([functools.partial(DepthNavEnv, observe_points=32)] * 2, context="spawn")
    single = DepthNavEnv(observe_points=32)
    obs, info = venv.reset(seed=[1, 2])
    o1, i1 = single.reset(seed=1)
    assert np.array_equal(obs["depth"][0], o1["depth"]) and np.array_equal(info["pose"][0], i1["pose"])
    rng = np.random.default_rng(0)
    for _ in range(10):
        actions = rng.uniform(-1, 1, (2, 3)).astype(np.float32)
        obs, r, term, trunc, info = venv.step(actions)
        o1, r1, t1, _, i1 = single.step(actions[0])
        if t1:
            break
        assert np.array_equal(obs["depth"][0], o1["depth"]) and np.array_equal(obs["points"][0], o1["points"])
        assert r[0] == r1
    assert obs["depth"].shape == (2, 120, 160, 1) and obs["points"].shape == (2, 32, 8)
    venv.close()
    single.close()


def test_rrd_flag_records_the_episode(tmp_path) -> None:
    """With ``rrd`` set, every step streams to a rerun recording readable by rerun."""
    import subprocess
    import sys
    from pathlib import Path

    path = tmp_path / "env.rrd"
    env = gym.make("DepthNav-v0", building="small_floor", rrd=str(path), rrd_every=2, max_steps=20)
    env.reset(seed=1)
    for _ in range(6):
        env.step(env.action_space.sample())
    env.close()
    assert path.stat().st_size > 10_000
    rerun = Path(sys.executable).with_name("rerun")
    out = subprocess.run([str(rerun), "rrd", "stats", str(path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    with pytest.raises(InputError, match="rrd_every"):
        gym.make("DepthNav-v0", building="small_floor", rrd_every=0)


def test_depth_layouts_dtypes_and_a_polar_goal() -> None:
    """The depth image in each layout and type holds the same frame; the polar goal is the
    cartesian goal's distance and bearing."""
    obs = {}
    for layout, dtype, goal in (("hw", "float32", "cartesian"), ("hwc", "uint8", "polar"), ("chw", "float32", "polar")):
        env = DepthNavEnv(depth_layout=layout, depth_dtype=dtype, goal_format=goal)
        o, _ = env.reset(seed=3)
        assert env.observation_space.contains(o)
        obs[layout] = o
        env.close()
    hw, hwc, chw = obs["hw"]["depth"], obs["hwc"]["depth"], obs["chw"]["depth"]
    assert chw.shape == (1, 120, 160) and np.array_equal(chw[0], hw)
    assert hwc.shape == (120, 160, 1) and hwc.dtype == np.uint8
    valid = hw > 0
    assert ((hwc[..., 0] > 0) == valid).all()
    assert np.abs(hwc[..., 0][valid] * (4.0 / 255.0) - hw[valid]).max() <= 4.0 / 255.0 + 1e-6
    x, y = obs["hw"]["goal"]
    rho, phi = obs["chw"]["goal"]
    assert rho == pytest.approx(np.hypot(x, y), abs=1e-4) and phi == pytest.approx(np.arctan2(y, x), abs=1e-5)
    with pytest.raises(InputError, match="depth_layout"):
        DepthNavEnv(depth_layout="whc")
