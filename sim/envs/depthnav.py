"""Gymnasium environment ``DepthNav-v0``: point-goal navigation with a Kinect-model depth camera.

:class:`sim.envs.config.EnvConfig` holds every parameter; :class:`DepthNavEnv` (registered
as ``DepthNav-v0`` by ``import sim``) documents the action and observation spaces, rewards,
episode ends, info, seeding and rendering, and is the gymnasium API over the pieces beside
it: the simulated building and which one each episode uses (:mod:`sim.envs.site`), the
episode's task and its start (:mod:`sim.envs.task`), the closed loop of one episode
(:mod:`sim.envs.loop`: the one simulator step, :class:`sim.simulator.step.SimStep`, and the
one robot stack, :class:`autonomy.stack.RobotStack`, that scenario runs use), the
observations (:mod:`sim.envs.observation`), the reward and episode end
(:mod:`sim.envs.reward`), the rendered views (:mod:`sim.envs.render`) and the rerun
recording (:mod:`sim.envs.recording`). docs/env.md has examples.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from autonomy.common.errors import InputError
from autonomy.navigation.safety import safe_command
from sim.envs.config import EnvConfig
from sim.envs.loop import EpisodeLoop, LoopConfig, Reading
from sim.envs.observation import Observations
from sim.envs.recording import EnvRecording
from sim.envs.render import depth_to_rgb, top_view
from sim.envs.reward import REWARD_TERMS, PointGoalReward, RewardConfig
from sim.envs.site import Site, SiteSchedule
from sim.envs.task import Episode, begin_episode
from sim.envs.tasks import TASKS
from sim.simulator.step import EpisodeSeeds

ENV_ID = "DepthNav-v0"

RENDER_MODES = ("rgb_array", "depth")


class DepthNavEnv(gym.Env):
    """Point-goal navigation in an office building from Kinect depth (``DepthNav-v0``).

    The robot (an omnidirectional base, :mod:`sim.simulator.robot`) starts at a random node of a
    building's navigation graph and must reach a goal node drawn at a geodesic distance in
    ``[min_goal_distance_m, max_goal_distance_m]``. One env step is ``frames_per_step``
    camera frames (one by default: ``1 / kinect.rate_hz`` s, 30 Hz): the action sets the
    velocity command, held over the step (with ``safety_layer=True`` it first passes the
    robot's safety layer, :mod:`autonomy.navigation.safety`, which replaces it by the
    nearest velocity from which the robot stops short of what the stack knows round it);
    people walk and physics advances every frame;
    on the step's last frame a noisy depth frame is rendered at the observation size, and
    (if enabled) FSPF and CGR localization run on it with the odometry of all the step's
    frames. The goal is observed in the robot frame of the pose *estimate* (CGR, or dead
    reckoning when localization is off), or of the true pose with ``goal_from_truth=True``.

    The registered tasks (:mod:`sim.envs.tasks`): ``DepthNav-v0``, a decision every frame
    with the depth image; ``DepthNavPointGoal-v0`` and ``DepthNavLocal-v0``, a decision
    every six frames (5 Hz) with ``ranges``, ``velocity``, a 'unit' goal and (Local) the
    ``plan``.

    Buildings come from the shipped assets (``building="small_floor"``, the default, or
    ``"corridor_loop"``), from blueprint or vector-map files, from a scenario file
    (``scenario="scenarios/demo.toml"``), or from the procedural generator
    (``building="procedural"``: a new building from ``np_random`` every
    ``new_building_every`` episodes). A building's MuJoCo world is compiled once and reused
    across resets: furniture is moved and people are re-routed in place.

    ## Action space

    ``Box(-1, 1, (3,), float32)``, a body-frame velocity command scaled to the robot's limits
    (the translational speed is limited on the norm, and the change of the command by the
    acceleration limits, as :meth:`sim.simulator.robot.RobotHandle.command` does):

    | Num | Action | Min | Max | Scaled to |
    | --- | --- | --- | --- | --- |
    | 0 | forward velocity vx | -1 | 1 | ``robot.max_speed_mps`` (0.75 m/s) |
    | 1 | leftward velocity vy | -1 | 1 | ``robot.max_speed_mps`` |
    | 2 | yaw rate omega (counter-clockwise) | -1 | 1 | ``robot.max_angular_rad_s`` (1.5 rad/s) |

    ## Observation space

    A ``Dict`` of float32 boxes. Always present (``depth`` unless ``observe_depth=False``):

    | Key | Shape | Range | Meaning |
    | --- | --- | --- | --- |
    | ``depth`` | (120, 160, 1): ``depth_shape`` with a channel axis (``depth_layout``: 'hwc', 'chw' (1, 120, 160) or 'hw') | [0, max range (4 m)] float32, or [0, 255] uint8 (``depth_dtype``) | Kinect-model planar depth in metres (noise at this size), 0 = invalid: nothing in range, or closer than the camera's 0.8 m |
    | ``goal`` | (2,); unit: (3,) | [-1000, 1000] m; polar: [0, 1000] m, [-pi, pi]; unit: [0, 1], [-1, 1], [-1, 1] | goal (x forward, y left) in the robot frame of the pose estimate (or of the true pose); ``goal_format='polar'``: (distance, bearing); ``'unit'``: (distance / ``goal_scale_m`` capped at 1, cos, sin of the bearing) |
    | ``odometry`` | (3,) | [-1, 1] m, [-pi, pi] rad | the step's noisy odometry increment (dx, dy, dtheta) in the previous robot frame; 0 after reset |

    Optional, chosen by constructor arguments:

    | Key | Argument | Shape | Meaning |
    | --- | --- | --- | --- |
    | ``points`` | ``observe_points=N`` | (N, 8) | FSPF points in the robot frame, one per row: x, y, z (m), normal nx, ny, nz (0 for outliers), ``plane`` (1 plane-filtered point, 0 outlier), ``valid`` (1 real point, 0 padding); plane points first, then outliers; a random subset when there are more than N |
    | ``scan`` | ``observe_scan=B`` | (B,) | KC-style laser scan: nearest return per azimuth bin over the camera's horizontal field of view (bin 0 rightmost), from the camera's floor position, points between ``scan_min_height_m`` and ``scan_max_height_m``; 0 = no return |
    | ``pose_estimate`` | ``observe_pose_estimate=True`` | (5,) | CGR estimate in the world frame: x, y (m, clipped to +-1e4), theta, position spread ``std_xy_m``, heading spread ``std_theta_rad`` |
    | ``ranges`` | ``observe_ranges=B`` | (``history``, B) | the nearest obstacle per bearing bin all round the robot (bin 0 from straight behind, counter-clockwise; the heading starts bin B/2), as the robot stack knows it: the map's walls through the pose estimate, the obstacle memory (what the camera saw, kept where it no longer looks) and the near field (closer than the camera's 0.8 m); range / ``ranges_max_m`` in [0, 1], 1 = nothing within it; row 0 this step, row k the step k before (the first repeated after a reset) |
    | ``plan`` | ``observe_plan=K`` | (K, 2) | the robot stack's plan on the navigation graph: K points ``plan_spacing_m`` apart ahead of the estimate's place on it (the last repeated past its end), robot frame of the estimate, / ``ranges_max_m``, clipped to +-10 |
    | ``velocity`` | ``observe_velocity=True`` | (3,) | the base's body-frame velocity (vx, vy, omega) / the action's scale, clipped to +-2 (the acceleration limits make it lag the action) |

    ## Rewards

    ``reward = progress + success + collision + time + clearance`` (exactly, in that order),
    each term in ``info["reward_terms"]``:

    - ``progress``: ``progress_reward_per_m`` times the decrease of the geodesic distance to
      the goal (shortest route over the navigation graph, straight where the goal or a node
      is in sight; see :mod:`sim.envs.geometry`), on the true pose;
    - ``success``: ``success_reward`` once, when the true position comes within
      ``goal_radius_m`` of the goal;
    - ``collision``: ``collision_reward`` per new contact episode (the robot starting to touch
      a wall, furniture or a person, counted as :meth:`sim.simulator.world.World.step_frame` does),
      none again within ``collision_debounce_s`` of the last penalised one and at most
      ``collision_penalties`` an episode (0: no limit; ``collisions`` counts them all);
    - ``time``: ``time_reward`` every step;
    - ``clearance``: ``clearance_reward`` times how far inside ``clearance_m`` of the robot's
      surface the nearest thing the robot stack knows of is (0 outside, 1 touching); off
      (0) by default.

    ## Episode end

    Terminated on success (``terminate_on_success``) or on a collision
    (``terminate_on_collision``); truncated after ``max_steps`` steps. ``gymnasium.make``
    also wraps the env in a ``TimeLimit`` of the registration's ``max_episode_steps``, 1000
    (the benchmark task's ``max_steps``, and the default): with a ``max_steps`` above it,
    pass ``max_episode_steps`` too, or make the env with :func:`make`, which sets it to
    ``max_steps``. Where both limits fall on the same step, an arrival on that step is
    terminated and (by the wrapper) truncated.

    ## Info

    ``pose`` (true x, y, theta), ``pose_estimate``, ``loc_error_m``, ``loc_resets``,
    ``goal`` (world x, y), ``goal_distance_m`` (geodesic), ``collisions`` (this episode),
    ``collided`` (this step), ``success`` and its alias ``is_success``, ``steps``, and after
    a step ``reward_terms``; with ``stack_policy=True`` also ``stack_command`` (the robot
    stack's velocity, m/s and rad/s) and ``stack_action`` (the same scaled as an action).

    ## Randomness

    A procedural building is drawn from ``self.np_random``; each episode's streams
    (furniture and people, start and goal, odometry noise, Kinect noise seeds, FSPF seeds,
    CGR) come from :class:`sim.simulator.step.EpisodeSeeds`, of the reset's seed or, without
    one, of a seed drawn from ``self.np_random``. ``reset(seed=s)`` then the same actions
    give the same observations, bit for bit. With ``stack_policy`` and the same start and
    goal (reset options), stepping with ``info["stack_action"]`` retraces a scenario run of
    seed ``s`` frame for frame (the runner draws its streams the same way), as long as
    neither has random furniture: the env keeps each random piece's kind for its building
    and draws only where it stands. A seeded reset also restarts the procedural building
    schedule.

    ## Rendering

    ``render_mode="rgb_array"``: a ``render_size`` (480 x 640) top-down view of the building
    with the walls, navigation graph, furniture, people, the planned route, the goal, the
    camera's field of view, the CGR particles and estimate, and the robot.
    ``render_mode="depth"``: the last depth observation, Turbo-coloured (invalid black),
    upscaled to at least 240 rows. The renderers (and the GL context) are made lazily, so
    the env works in ``gymnasium.vector.AsyncVectorEnv`` workers.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 30}

    def __init__(
        self,
        config: EnvConfig | None = None,
        *,
        scenario: str | Path | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        cfg = env_config(config, scenario=scenario, **overrides)
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise InputError(f"DepthNav: argument 'render_mode' expected None or one of {', '.join(RENDER_MODES)}, got {render_mode!r}")
        self.config = cfg
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": max(1, int(round(cfg.kinect.rate_hz / cfg.frames_per_step)))}

        self._loop_config = LoopConfig.from_config(cfg)
        self.intrinsics = self._loop_config.kinect.intrinsics
        """The camera's intrinsics at the observation's size."""
        self.frame_dt = 1.0 / cfg.kinect.rate_hz
        self.step_dt = cfg.frames_per_step * self.frame_dt
        """Simulated seconds per step (``frames_per_step`` camera frames)."""
        self.depth_max_m = self._loop_config.depth_max_m
        self._observations = Observations.from_config(cfg, self.intrinsics, self.depth_max_m)
        self._reward = PointGoalReward(RewardConfig.from_config(cfg))
        self._sites = SiteSchedule(cfg, self._loop_config.kinect)
        self._action_scale = cfg.action_scale
        self._safety = cfg.avoidance if cfg.safety_layer else None
        """The robot stack's avoidance settings the safety layer brakes with (None: off)."""
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = self._observations.space()
        self._recording = EnvRecording(cfg, self.intrinsics, self.step_dt) if cfg.rrd else None

        # Made in reset (nothing unpicklable is created here).
        self._episode: Episode | None = None
        self._loop: EpisodeLoop | None = None
        self._reading: Reading | None = None
        """The last frame (None before the first reset and after close)."""
        self._obs: dict[str, np.ndarray] | None = None
        """The last observation (its ``ranges`` history goes on into the next)."""

    @property
    def site(self) -> Site | None:
        """The compiled building of the current episode (None before the first reset)."""
        return self._sites.site

    @property
    def goal(self) -> np.ndarray | None:
        """The current episode's goal (world x, y; None before the first reset)."""
        return None if self._episode is None else self._episode.goal

    @property
    def goal_node(self) -> int | None:
        """The navigation-graph node of the current episode's goal (None before the first reset)."""
        return None if self._episode is None else self._episode.goal_node

    # -- gymnasium API ----------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode. ``options``: ``start_pose`` (x, y, theta) and/or ``goal`` (x, y)."""
        super().reset(seed=seed)
        opts = dict(options or {})
        unknown = set(opts) - {"start_pose", "goal"}
        if unknown:
            raise InputError(f"DepthNav: reset option {sorted(unknown)[0]!r} unknown (expected start_pose, goal)")
        start = _option_array(opts, "start_pose", 3)
        goal = _option_array(opts, "goal", 2)
        site = self._sites.site_for_episode(self.np_random, seeded=seed is not None)
        if start is not None:
            site.check_start_pose(self.config, start)
        self._sites.count_episode()
        seeds = EpisodeSeeds.from_seed(seed if seed is not None else int(self.np_random.integers(0, 2**63)))
        ep = begin_episode(self.config, site, seeds, start, goal)
        self._loop = EpisodeLoop(self._loop_config, site, seeds, ep)
        self._episode = ep
        self._reading = self._loop.first()
        self._reward.begin(ep, self._reading)
        if self._recording is not None:
            self._recording.log(site, ep, self._reading, new_episode=True)
        self._obs = None
        return self._get_obs(), self._get_info(None)

    def step(self, action):
        if self._loop is None or self._episode is None:
            raise gym.error.ResetNeeded("DepthNav: call reset() before step()")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (3,):
            raise InputError(f"DepthNav: action expected shape (3,) (vx, vy, omega in [-1, 1]), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise InputError(f"DepthNav: action expected finite numbers, got {a!r}")
        ep = self._episode
        command = np.clip(a, -1.0, 1.0) * self._action_scale
        known = None if self._reading is None or self._reading.output is None else self._reading.output.known
        if self._safety is not None and known is not None:
            command = safe_command(command, known, self.step_dt, self._safety)
        self._reading = self._loop.step(command)
        score = self._reward.score(ep, self._reading)
        if self._recording is not None:
            self._recording.log(self._loop.site, ep, self._reading, new_episode=False)
        return self._get_obs(), score.reward, score.terminated, score.truncated, self._get_info(score.terms)

    def _get_obs(self) -> dict[str, np.ndarray]:
        assert self._episode is not None and self._reading is not None and self._loop is not None
        obs = self._observations
        out = self._reading.output
        known = None if out is None else out.known
        self._obs = obs.observe(self._reading, self._episode.goal, self.np_random, known, self._obs)
        return {k: v.copy() for k, v in self._obs.items()} if obs.n_ranges else self._obs

    def _get_info(self, reward_terms: dict[str, float] | None) -> dict[str, Any]:
        """The info of a reset (``reward_terms`` None) or of a step."""
        ep, r = self._episode, self._reading
        assert ep is not None and r is not None
        info: dict[str, Any] = {
            "pose": r.pose.copy(),
            "pose_estimate": r.estimate.copy(),
            "loc_error_m": float(math.hypot(*(r.estimate[:2] - r.pose[:2]))),
            "loc_resets": ep.loc_resets,
            "goal": ep.goal.copy(),
            "goal_distance_m": float(ep.phi),
            "collisions": ep.collisions,
            "collided": ep.collided,
            "success": ep.success,
            "is_success": ep.success,
            "steps": ep.steps,
        }
        if r.command is not None:
            info["stack_command"] = r.command.copy()
            # float64: a float32 action would move the robot differently from the command.
            info["stack_action"] = np.clip(r.command / self._action_scale, -1.0, 1.0)
        if reward_terms is not None:
            info["reward_terms"] = {k: float(reward_terms[k]) for k in REWARD_TERMS}
        return info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("DepthNav: render() without a render_mode; pass render_mode='rgb_array' or 'depth'")
            return None
        if self._loop is None or self._episode is None or self._reading is None:
            raise gym.error.ResetNeeded("DepthNav: call reset() before render()")
        if self.render_mode == "depth":
            h = self._reading.depth.shape[0]
            return depth_to_rgb(self._reading.depth, self.depth_max_m, upscale=max(1, math.ceil(240 / h)))
        return top_view(self._loop.site, self.config, self.intrinsics.fov_h_rad, self.depth_max_m, self._episode, self._reading)

    def close(self) -> None:
        if self._recording is not None:
            self._recording.close()
        self._sites.close()
        self._loop = self._episode = self._reading = self._obs = None
        super().close()


def env_config(config: EnvConfig | None = None, *, scenario: str | Path | None = None, **overrides: Any) -> EnvConfig:
    """The :class:`EnvConfig` that ``DepthNavEnv(config, scenario=..., **overrides)`` runs with."""
    if config is not None and scenario is not None:
        raise InputError("DepthNav: give 'config' or 'scenario', not both")
    if config is not None and not isinstance(config, EnvConfig):
        raise InputError(f"DepthNav: argument 'config' expected an EnvConfig, got {type(config).__name__}")
    if scenario is not None:
        return EnvConfig.from_scenario(scenario, **overrides)
    return (config or EnvConfig()).replace(**overrides) if overrides else (config or EnvConfig())


def make(task: str = ENV_ID, **kwargs: Any) -> gym.Env:
    """``gymnasium.make(task, **kwargs)`` (a registered id, :mod:`sim.envs.tasks`) with
    gymnasium's ``TimeLimit`` at the env's own ``max_steps`` (a ``max_episode_steps`` in
    ``kwargs`` still wins).

    The registration's ``max_episode_steps`` is the benchmark task's 1000 steps, and
    ``gymnasium.make`` applies it whatever ``max_steps`` the env is given: a longer episode
    (``max_steps=2000``, or a scenario's mission limit) would be cut at 1000 steps. The env
    truncates at its own ``max_steps``, so here the wrapper and the env agree (``import
    sim``, which this module's import runs first, registered the id)."""
    if task not in TASKS:
        raise InputError(f"DepthNav: task {task!r} unknown (expected one of: {', '.join(TASKS)})")
    if "max_episode_steps" not in kwargs:
        own = {k: v for k, v in kwargs.items() if k not in ("render_mode", "disable_env_checker")}
        kwargs = {**kwargs, "max_episode_steps": env_config(**{**TASKS[task], **own}).max_steps}
    return gym.make(task, **kwargs)


def _option_array(opts: dict[str, Any], key: str, n: int) -> np.ndarray | None:
    if key not in opts or opts[key] is None:
        return None
    try:
        a = np.asarray(opts[key], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (n,) or not np.all(np.isfinite(a)):
        raise InputError(f"DepthNav: reset option '{key}' expected {n} finite numbers, got {opts[key]!r}")
    return a.copy()
