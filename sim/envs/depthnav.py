"""Gymnasium environment ``DepthNav-v0``: point-goal navigation with a Kinect-model depth camera.

:class:`sim.envs.config.EnvConfig` holds every parameter; :class:`DepthNavEnv` (registered
as ``DepthNav-v0`` by ``import sim``) documents the action and observation spaces, rewards,
episode ends, info, seeding and rendering. The simulated building is a
:class:`sim.envs.site.Site`, the task's sampling, reward terms and observations are in
:mod:`sim.envs.task`; a step goes through the one simulator step
(:class:`sim.simulator.step.SimStep`) and the one robot stack
(:class:`autonomy.stack.RobotStack`) that scenario runs use. docs/env.md has examples.
"""

from __future__ import annotations

import math
import os
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from autonomy.common.errors import InputError
from autonomy.common.geometry import wrap_angle
from autonomy.perception.camera import CameraIntrinsics
from autonomy.stack import RobotStack, StackOutput
from sim.envs.config import EnvConfig
from sim.envs.geometry import GeodesicField, KCScanner
from sim.envs.render import (
    ESTIMATE,
    FRUSTUM,
    FURNITURE,
    GOAL,
    PARTICLE,
    PATH,
    PERSON,
    ROBOT,
    MapCanvas,
    depth_to_rgb,
    draw_disk,
    draw_points,
    draw_segments,
    fill_convex,
)
from sim.envs.site import Site, check_building, load_fixed_building, procedural_building
from sim.envs.task import (
    GOAL_LIMIT_M,
    POSITION_LIMIT_M,
    REWARD_TERMS,
    Episode,
    collision_reward,
    depth_observation,
    goal_observation,
    nearest_node,
    odometry_observation,
    points_observation,
    pose_estimate_observation,
    progress_reward,
    sample_task,
    success_reward,
    time_reward,
)
from sim.simulator.robot import Odometry
from sim.simulator.step import EpisodeSeeds, SimFrame, SimStep

ENV_ID = "DepthNav-v0"

#: Depth beyond the GL far plane cannot occur (sim.simulator.world sets it at 60 m).
FAR_PLANE_M = 60.0
RENDER_MODES = ("rgb_array", "depth")

#: True in a process forked from one that had already opened an EGL display itself
#: (``kinect.render_process=False``): Mesa's renderer threads do not survive fork(), and
#: rendering there would hang for ever. The default render server is not affected.
_GL_INHERITED = False


def _after_fork_in_child() -> None:
    global _GL_INHERITED
    egl = sys.modules.get("mujoco.egl")
    if egl is not None and getattr(egl, "EGL_DISPLAY", None) is not None:
        _GL_INHERITED = True


os.register_at_fork(after_in_child=_after_fork_in_child)


class DepthNavEnv(gym.Env):
    """Point-goal navigation in an office building from Kinect depth (``DepthNav-v0``).

    The robot (an omnidirectional base, :mod:`sim.simulator.robot`) starts at a random node of a
    building's navigation graph and must reach a goal node drawn at a geodesic distance in
    ``[min_goal_distance_m, max_goal_distance_m]``. One env step is one camera frame
    (``1 / kinect.rate_hz`` s, 30 Hz by default): the action sets the velocity command,
    people walk, physics advances, a noisy depth frame is rendered at the observation size,
    odometry integrates, and (if enabled) FSPF and CGR localization run on the frame. The
    goal is observed in the robot frame of the pose *estimate* (CGR, or dead reckoning when
    localization is off), or of the true pose with ``goal_from_truth=True``.

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

    A ``Dict`` of float32 boxes. Always present:

    | Key | Shape | Range | Meaning |
    | --- | --- | --- | --- |
    | ``depth`` | (120, 160, 1): ``depth_shape`` with a channel axis (``depth_layout``: 'hwc', 'chw' (1, 120, 160) or 'hw') | [0, max range (4 m)] float32, or [0, 255] uint8 (``depth_dtype``) | Kinect-model planar depth in metres (noise at this size), 0 = invalid |
    | ``goal`` | (2,) | [-1000, 1000] m; polar: [0, 1000] m, [-pi, pi] | goal (x forward, y left) in the robot frame of the pose estimate (or of the true pose); ``goal_format='polar'``: (distance, bearing) |
    | ``odometry`` | (3,) | [-1, 1] m, [-pi, pi] rad | last noisy odometry increment (dx, dy, dtheta) in the previous robot frame; 0 after reset |

    Optional, chosen by constructor arguments:

    | Key | Argument | Shape | Meaning |
    | --- | --- | --- | --- |
    | ``points`` | ``observe_points=N`` | (N, 8) | FSPF points in the robot frame, one per row: x, y, z (m), normal nx, ny, nz (0 for outliers), ``plane`` (1 plane-filtered point, 0 outlier), ``valid`` (1 real point, 0 padding); plane points first, then outliers; a random subset when there are more than N |
    | ``scan`` | ``observe_scan=B`` | (B,) | KC-style laser scan: nearest return per azimuth bin over the camera's horizontal field of view (bin 0 rightmost), from the camera's floor position, points between ``scan_min_height_m`` and ``scan_max_height_m``; 0 = no return |
    | ``pose_estimate`` | ``observe_pose_estimate=True`` | (5,) | CGR estimate in the world frame: x, y (m, clipped to +-1e4), theta, position spread ``std_xy_m``, heading spread ``std_theta_rad`` |

    ## Rewards

    ``reward = progress + success + collision + time`` (exactly, in that order), each term in
    ``info["reward_terms"]``:

    - ``progress``: ``progress_reward_per_m`` times the decrease of the geodesic distance to
      the goal (shortest route over the navigation graph, straight where the goal or a node
      is in sight; see :mod:`sim.envs.geometry`), on the true pose;
    - ``success``: ``success_reward`` once, when the true position comes within
      ``goal_radius_m`` of the goal;
    - ``collision``: ``collision_reward`` per new contact episode (the robot starting to touch
      a wall, furniture or a person, counted as :meth:`sim.simulator.world.World.step_frame` does);
    - ``time``: ``time_reward`` every step.

    ## Episode end

    Terminated on success (``terminate_on_success``) or on a collision
    (``terminate_on_collision``); truncated after ``max_steps`` steps.

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


    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 30}

    def __init__(
        self,
        config: EnvConfig | None = None,
        *,
        scenario: str | Path | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        if config is not None and scenario is not None:
            raise InputError("DepthNav: give 'config' or 'scenario', not both")
        if config is not None and not isinstance(config, EnvConfig):
            raise InputError(f"DepthNav: argument 'config' expected an EnvConfig, got {type(config).__name__}")
        if scenario is not None:
            cfg = EnvConfig.from_scenario(scenario, **overrides)
        else:
            cfg = (config or EnvConfig()).replace(**overrides) if overrides else (config or EnvConfig())
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise InputError(f"DepthNav: argument 'render_mode' expected None or one of {', '.join(RENDER_MODES)}, got {render_mode!r}")
        self.config = cfg
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": int(round(cfg.kinect.rate_hz))}

        h, w = cfg.depth_shape
        self.intrinsics: CameraIntrinsics = cfg.kinect.intrinsics.scaled(w, h)
        self._kinect = replace(cfg.kinect, intrinsics=self.intrinsics, noise=replace(cfg.kinect.noise, threads=1))
        fspf_cfg = replace(cfg.fspf, eta_px=max(2, round(cfg.fspf.eta_px * w / cfg.kinect.intrinsics.width)))
        self._stack_cfg = cfg.stack_config(self._kinect, fspf_cfg)
        self.frame_dt = 1.0 / cfg.kinect.rate_hz
        max_range = cfg.kinect.noise.max_range_m
        self.depth_max_m = float(max_range) if math.isfinite(max_range) else FAR_PLANE_M
        self._need_stack = cfg.localization.enabled or cfg.observe_points > 0 or cfg.stack_policy
        self._scanner = (
            KCScanner(self.intrinsics, cfg.kinect.mount, cfg.observe_scan, cfg.scan_min_height_m, cfg.scan_max_height_m, self.depth_max_m)
            if cfg.observe_scan
            else None
        )
        self._fixed = load_fixed_building(cfg)
        self._action_scale = np.array([cfg.robot.max_speed_mps, cfg.robot.max_speed_mps, cfg.robot.max_angular_rad_s])
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = self._observation_space()

        # Episode state (made in reset; nothing unpicklable is created here).
        self._site: Site | None = None
        self._episodes_on_site = 0
        self._ready = False
        self._sim: SimStep | None = None
        self._stack: RobotStack | None = None
        self._out: StackOutput | None = None
        """The stack's output on the last frame (None without a stack)."""
        self._episode: Episode | None = None
        self._recorder = None
        self._rrd_frame = 0
        self._rrd_time = 0.0
        self._rrd_site: Site | None = None

    def _depth_space(self, h: int, w: int) -> spaces.Box:
        cfg = self.config
        shape = {"hwc": (h, w, 1), "chw": (1, h, w), "hw": (h, w)}[cfg.depth_layout]
        if cfg.depth_dtype == "uint8":
            return spaces.Box(0, 255, shape, np.uint8)
        return spaces.Box(0.0, self.depth_max_m, shape, np.float32)

    def _observation_space(self) -> spaces.Dict:
        cfg = self.config
        h, w = cfg.depth_shape
        obs: dict[str, spaces.Space] = {
            "depth": self._depth_space(h, w),
            "goal": (
                spaces.Box(np.array([0.0, -np.pi], np.float32), np.array([GOAL_LIMIT_M, np.pi], np.float32), dtype=np.float32)
                if cfg.goal_format == "polar"
                else spaces.Box(-GOAL_LIMIT_M, GOAL_LIMIT_M, (2,), np.float32)
            ),
            "odometry": spaces.Box(
                np.array([-1.0, -1.0, -np.pi], np.float32), np.array([1.0, 1.0, np.pi], np.float32), dtype=np.float32
            ),
        }
        if cfg.observe_points:
            rays = np.hypot(1.0, np.hypot(*(np.array([w, h]) / 2 / np.array([self.intrinsics.fx, self.intrinsics.fy]))))
            b = float(self.depth_max_m * rays + np.linalg.norm(cfg.kinect.mount.translation()) + 0.01)
            lo = np.array([-b, -b, -b, -1, -1, -1, 0, 0], np.float32)
            hi = np.array([b, b, b, 1, 1, 1, 1, 1], np.float32)
            self._points_low = np.broadcast_to(lo, (cfg.observe_points, 8)).copy()
            self._points_high = np.broadcast_to(hi, (cfg.observe_points, 8)).copy()
            obs["points"] = spaces.Box(self._points_low, self._points_high, dtype=np.float32)
        if cfg.observe_scan:
            assert self._scanner is not None
            obs["scan"] = spaces.Box(0.0, np.float32(self._scanner.max_range_m), (cfg.observe_scan,), np.float32)
        if cfg.observe_pose_estimate:
            L = POSITION_LIMIT_M
            obs["pose_estimate"] = spaces.Box(
                np.array([-L, -L, -np.pi, 0.0, 0.0], np.float32), np.array([L, L, np.pi, L, 10.0], np.float32), dtype=np.float32
            )
        return spaces.Dict(obs)

    # -- buildings ------------------------------------------------------------------
    def _ensure_site(self, seeded: bool) -> Site:
        cfg = self.config
        if self._fixed is not None:
            if self._site is None:
                self._site = Site.build(cfg, self._kinect, self._fixed, None)
            return self._site
        # Procedural, drawn from np_random (from building_seeds when given): a seeded reset
        # always draws a new building.
        if self._site is None or seeded or self._episodes_on_site >= cfg.new_building_every:
            seeds = cfg.building_seeds
            seed = int(seeds[self.np_random.integers(len(seeds))] if seeds else self.np_random.integers(0, 2**31 - 1))
            if self._site is not None and self._site.seed == seed:
                self._episodes_on_site = 0
                return self._site
            b = procedural_building(cfg, seed)
            check_building(cfg, b)
            if self._site is not None:
                self._site.close()
            self._site = Site.build(cfg, self._kinect, b, seed)
            self._episodes_on_site = 0
        return self._site

    # -- gymnasium API ----------------------------------------------------------------
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """Start an episode. ``options``: ``start_pose`` (x, y, theta) and/or ``goal`` (x, y)."""
        super().reset(seed=seed)
        opts = dict(options or {})
        unknown = set(opts) - {"start_pose", "goal"}
        if unknown:
            raise InputError(f"DepthNav: reset option {sorted(unknown)[0]!r} unknown (expected start_pose, goal)")
        start_opt = _option_array(opts, "start_pose", 3)
        goal_opt = _option_array(opts, "goal", 2)
        cfg = self.config
        site = self._ensure_site(seeded=seed is not None)
        if start_opt is not None:
            _check_start_pose(site, cfg, start_opt)
        self._episodes_on_site += 1
        seeds = EpisodeSeeds.from_seed(seed if seed is not None else int(self.np_random.integers(0, 2**63)))
        if cfg.n_furniture:
            site.place_furniture(cfg, seeds.actors)
        site.route_people(cfg, seeds.actors)
        start, goal, goal_node = sample_task(cfg, site, seeds.mission)
        if start_opt is not None:
            start = start_opt
        if goal_opt is not None:
            goal, goal_node = goal_opt, nearest_node(site, goal_opt)
        start[2] = wrap_angle(start[2])
        site.clear_start(cfg, start[:2], seeds.actors)
        site.world.reset(tuple(start))
        self.goal = goal
        self._field = GeodesicField(site.building.navgraph, site.walls, goal, cfg.geodesic_radius_m)
        self._sim = SimStep(site.world, site.camera, Odometry(cfg.odometry, seeds.odometry, start), seeds.noise_seed)
        self._stack = None
        if self._need_stack:
            g = site.building.navgraph
            self._stack = RobotStack(
                site.building.vectormap, g, self._stack_cfg, rng=seeds.localization, fspf_seed=seeds.fspf_seed, scene=site.query
            )
            self._stack.reset(start)
            if cfg.stack_policy:
                self._stack.set_goal(goal_node, float(site.world.data.time), start)
        self._episode = Episode(start=start.copy(), goal=goal, goal_node=goal_node)
        self._ready = True
        self._sense(self._capture(first=True))
        self._episode.phi, _ = self._field.distance(self._pose[:2])
        if cfg.rrd:
            self._log_rrd(cfg.rrd, new_episode=True)
        return self._observation(), self._info(None)

    def step(self, action):
        if not self._ready:
            raise gym.error.ResetNeeded("DepthNav: call reset() before step()")
        cfg = self.config
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (3,):
            raise InputError(f"DepthNav: action expected shape (3,) (vx, vy, omega in [-1, 1]), got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            raise InputError(f"DepthNav: action expected finite numbers, got {a!r}")
        ep = self._episode
        assert ep is not None
        frame = self._capture(velocity=np.clip(a, -1.0, 1.0) * self._action_scale)
        ep.steps += 1
        ep.collisions += frame.new_contacts
        ep.collided = frame.new_contacts > 0
        self._sense(frame)
        if cfg.rrd:
            self._log_rrd(cfg.rrd, new_episode=False)
        phi, _ = self._field.distance(self._pose[:2])
        reached = math.hypot(*(self._pose[:2] - self.goal)) <= cfg.goal_radius_m
        first_success = reached and not ep.success
        ep.success = ep.success or reached
        terms = {
            "progress": progress_reward(cfg, ep.phi, phi),
            "success": success_reward(cfg, first_success),
            "collision": collision_reward(cfg, frame.new_contacts),
            "time": time_reward(cfg),
        }
        ep.phi = phi
        reward = float(terms["progress"] + terms["success"] + terms["collision"] + terms["time"])
        terminated = bool((cfg.terminate_on_success and reached) or (cfg.terminate_on_collision and frame.new_contacts > 0))
        truncated = bool(ep.steps >= cfg.max_steps and not terminated)
        return self._observation(), reward, terminated, truncated, self._info(terms)

    # -- sensing ----------------------------------------------------------------------
    def _capture(self, first: bool = False, velocity: np.ndarray | None = None) -> SimFrame:
        """The simulator step (or, after a reset, the first frame)."""
        site, sim = self._site, self._sim
        assert site is not None and sim is not None
        kin = self.config.kinect
        if _GL_INHERITED and site.camera._backend is None and kin.backend != "raycast" and not kin.render_process:
            raise RuntimeError(
                "DepthNav: this process was forked from one that had already rendered with EGL, "
                "and OpenGL cannot render after fork(); make AsyncVectorEnv(..., context='spawn') "
                "(or 'forkserver'), or create the vector env before rendering in the parent"
            )
        return sim.first() if first else sim.step(velocity)

    def _sense(self, frame: SimFrame) -> None:
        """The robot stack on the new frame: FSPF, localization (or dead reckoning), and
        with ``stack_policy`` the navigator's command."""
        cfg = self.config
        depth = frame.depth
        if not math.isfinite(cfg.kinect.noise.max_range_m):
            depth = np.where(depth <= self.depth_max_m, depth, np.float32(0.0))
        self._depth = depth  # a new array every frame; observations hand out copies
        self._increment = np.zeros(3) if frame.increment is None else frame.increment
        self._pose = frame.pose
        self._stack_command = None
        self._out = None
        stack = self._stack
        if stack is None:
            assert self._sim is not None
            self._estimate, self._spread = self._sim.odometry.pose.copy(), (0.0, 0.0)
            return
        out = stack.step(self._depth, frame.increment, frame.t, operator=lambda sensed: self._reset_far_belief(sensed, frame.pose))
        self._out = out
        self._estimate, self._spread = out.estimate, out.spread
        if cfg.stack_policy:
            self._stack_command = out.velocity.copy()

    def _reset_far_belief(self, sensed: StackOutput, truth: np.ndarray) -> np.ndarray | None:
        """The episode's localization reset, between the stack's localizing and deciding:
        a belief farther than ``localization.reset_error_m`` from the ``truth`` is
        re-initialised there (counted in ``loc_resets``)."""
        ep = self._episode
        assert ep is not None
        if not sensed.localizing or math.hypot(*(sensed.estimate[:2] - truth[:2])) <= self.config.localization.reset_error_m:
            return None
        ep.loc_resets += 1
        return truth

    def _observation(self) -> dict[str, np.ndarray]:
        cfg = self.config
        ep = self._episode
        assert ep is not None
        obs = {
            "depth": depth_observation(self._depth, cfg.depth_layout, cfg.depth_dtype, self.depth_max_m),
            "goal": goal_observation(self._pose if cfg.goal_from_truth else self._estimate, self.goal, cfg.goal_format == "polar"),
            "odometry": odometry_observation(self._increment),
        }
        if cfg.observe_points:
            planes = None if self._out is None else self._out.perception.planes
            obs["points"] = points_observation(planes, cfg.observe_points, self._points_low, self._points_high, self.np_random)
        if cfg.observe_scan:
            assert self._scanner is not None
            obs["scan"] = self._scanner.scan(self._depth)
        if cfg.observe_pose_estimate:
            obs["pose_estimate"] = pose_estimate_observation(self._estimate, self._spread)
        return obs

    def _info(self, terms: dict[str, float] | None) -> dict[str, Any]:
        ep = self._episode
        assert ep is not None
        info: dict[str, Any] = {
            "pose": self._pose.copy(),
            "pose_estimate": self._estimate.copy(),
            "loc_error_m": float(math.hypot(*(self._estimate[:2] - self._pose[:2]))),
            "loc_resets": ep.loc_resets,
            "goal": self.goal.copy(),
            "goal_distance_m": float(ep.phi),
            "collisions": ep.collisions,
            "collided": ep.collided,
            "success": ep.success,
            "is_success": ep.success,
            "steps": ep.steps,
        }
        if self._stack_command is not None:
            info["stack_command"] = self._stack_command.copy()
            # float64: a float32 action would move the robot differently from the command.
            info["stack_action"] = np.clip(self._stack_command / self._action_scale, -1.0, 1.0)
        if terms is not None:
            info["reward_terms"] = {k: float(terms[k]) for k in REWARD_TERMS}
        return info

    # -- rendering --------------------------------------------------------------------
    def render(self):
        if self.render_mode is None:
            gym.logger.warn("DepthNav: render() without a render_mode; pass render_mode='rgb_array' or 'depth'")
            return None
        if not self._ready:
            raise gym.error.ResetNeeded("DepthNav: call reset() before render()")
        if self.render_mode == "depth":
            h = self._depth.shape[0]
            return depth_to_rgb(self._depth, self.depth_max_m, upscale=max(1, math.ceil(240 / h)))
        return self._render_map()

    def _render_map(self) -> np.ndarray:
        site = self._site
        assert site is not None
        cfg = self.config
        if site.canvas is None:
            site.canvas = MapCanvas(site.building.vectormap, site.building.navgraph, cfg.render_size)
        cv = site.canvas
        img = cv.background.copy()
        s = cv.scale
        pose = self._pose
        # The camera's horizontal field of view out to the maximum range.
        cam = cfg.kinect.mount.translation()
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        cxy = pose[:2] + np.array([c * cam[0] - sn * cam[1], sn * cam[0] + c * cam[1]])
        half = self.intrinsics.fov_h_rad / 2
        r = min(self.depth_max_m, 6.0)
        ends = np.array([cxy + r * np.array([math.cos(pose[2] + a), math.sin(pose[2] + a)]) for a in (-half, half)])
        draw_segments(img, cv.px(np.vstack([cxy, cxy])), cv.px(ends), FRUSTUM)
        for f in site.furniture:
            lx, ly, _ = f.dims
            cf, sf = math.cos(f.yaw), math.sin(f.yaw)
            corners = np.array([[sx * lx / 2, sy * ly / 2] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
            world_c = np.column_stack([f.x + cf * corners[:, 0] - sf * corners[:, 1], f.y + sf * corners[:, 0] + cf * corners[:, 1]])
            fill_convex(img, cv.px(world_c), FURNITURE)
        people = site.world.people.positions()
        for i, p in enumerate(site.people):
            u, v = cv.px(people[i, :2])[0]
            draw_disk(img, u, v, max(2.0, p.radius_m * s), PERSON)
        path = self._field.path(pose[:2])
        draw_segments(img, cv.px(path[:-1]), cv.px(path[1:]), PATH, thickness=2)
        gu, gv = cv.px(self.goal)[0]
        draw_disk(img, gu, gv, max(3.0, 0.15 * s), GOAL)
        draw_disk(img, gu, gv, max(4.0, cfg.goal_radius_m * s), GOAL, ring=True)
        if self._out is not None and self._out.particles is not None:
            draw_points(img, cv.px(self._out.particles[:, :2]), PARTICLE)
        e = self._estimate
        eu, ev = cv.px(e[:2])[0]
        draw_disk(img, eu, ev, max(2.0, 0.1 * s), ESTIMATE)
        ru, rv = cv.px(pose[:2])[0]
        rr = max(3.0, cfg.robot.radius_m * s)
        draw_disk(img, ru, rv, rr, ROBOT, ring=True)
        head = cv.px(pose[:2] + cfg.robot.radius_m * 1.6 * np.array([c, sn]))
        draw_segments(img, np.array([[ru, rv]]), head, ROBOT, thickness=2)
        return img


    def _log_rrd(self, path: str, new_episode: bool) -> None:
        """Stream this step to the rerun recording (sim.viz.recording.Recorder), made on first use."""
        from sim.viz.recording import Recorder

        site, ep, out = self._site, self._episode, self._out
        assert site is not None and ep is not None
        if self._recorder is None:
            self._recorder = Recorder(path, every=self.config.rrd_every, depth_downsample=1, application_id="depthnav-env")
            self._recorder.log_camera_model(self.intrinsics, self.config.kinect.mount)
            self._recorder.log_robot_shape(self.config.robot.radius_m, self.config.robot.height_m)
        rec = self._recorder
        if site is not self._rrd_site:
            rec.log_map(site.building.vectormap, site.building.navgraph, self.config.world.wall_height_m)
            self._rrd_site = site
        if new_episode:
            rec.set_time(self._rrd_frame, self._rrd_time)
            rec.log_waypoints(np.asarray(self.goal, dtype=np.float64).reshape(1, 2), static=False)
            rec.reset_trajectory()
        self._rrd_frame += 1
        self._rrd_time += self.frame_dt
        rec.set_time(self._rrd_frame, self._rrd_time)
        rec.log_pose(self._rrd_frame, self._pose)
        if out is not None and out.localizing:
            rec.log_estimate(self._rrd_frame, self._estimate)
        if rec.heavy(self._rrd_frame):
            rec.log_depth(self._depth)
            if out is not None:
                rec.log_fspf(out.perception.planes)
                if out.refinement is not None:
                    rec.log_localization(out.refinement.before, out.refinement.after, out.refinement.weights)
            rec.log_people(site.world.people.positions())
            rec.log_scalars({"env/steps": float(ep.steps), "env/collisions": float(ep.collisions)})

    def close(self) -> None:
        if self._recorder is not None:
            self._recorder.close()
            self._recorder = None
        if self._site is not None:
            self._site.close()
            self._site = None
        self._ready = False
        super().close()


def _check_start_pose(site: Site, cfg: EnvConfig, start: np.ndarray) -> None:
    """A given start pose must be where the robot fits inside the building."""
    fs = site.building.free_space(cfg.robot.radius_m)
    if int(fs.region_at(start[:2])) < 0:
        pose = ", ".join(f"{v:g}" for v in start)
        raise InputError(
            f"DepthNav: reset option 'start_pose' ({pose}) is outside the building's free space "
            f"(no room there for a robot of radius {cfg.robot.radius_m:g} m inside the walls)"
        )


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
