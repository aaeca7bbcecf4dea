"""Behaviour cloning on expert demonstrations (:mod:`sim.rl.demos`): a small network
regressing the expert's actions with a mean-squared error.

On ``DepthNav-v0`` the network sees the learned-policy observations
(:data:`sim.rl.splits.LEARNER_OBS`): the uint8 depth image divided by 255 through a
three-layer CNN (DQN's layer shapes, fewer channels), and the goal (distance, cos
bearing, sin bearing), the odometry increment and the scan, standardised with the
training set's mean and spread, through an MLP; a head joins both and a tanh bounds the
action to [-1, 1]. On the decision-level tasks (:mod:`sim.envs.tasks`: no depth image)
it sees every observation term flattened, in key order, standardised the same way,
through the MLP and the head. The odometry is the robot's last
motion: it tells a network without memory whether the expert is turning in place or
driving, which the goal and one depth frame barely show (the stack follows a route it
does not observe); without it the held-out error of a small dataset hardly beats
predicting the mean action.
:class:`BCPolicy` wraps a trained network as a :class:`sim.rl.policies.Policy`, so
:func:`sim.rl.evaluate.evaluate` runs it. Training is deterministic for a seed (one
torch thread while it runs).
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write, atomic_write_text, output_path
from sim.envs.tasks import POINTNAV_V0, TASKS
from sim.rl.demos import Demonstrations
from sim.rl.policy_files import BC_MODEL_FILE, POLICY_FILE, SB3_FORMAT, SB3_MODEL_FILE
from sim.rl.sb3 import env_value, observation_kwargs

#: Observation settings BC needs (the learned-policy ones); checked against the dataset.
REQUIRED_OBS = {"depth_dtype": "uint8", "goal_format": "polar"}
MODEL_FILE = BC_MODEL_FILE


def goal_features(goal: np.ndarray) -> np.ndarray:
    """(distance, bearing) rows as (distance, cos bearing, sin bearing), float32."""
    g = np.asarray(goal, dtype=np.float32).reshape(-1, 2)
    return np.column_stack([g[:, 0], np.cos(g[:, 1]), np.sin(g[:, 1])]).astype(np.float32)


def depth_chw(depth: np.ndarray, layout: str) -> np.ndarray:
    """A batch of depth observations (N, ...) in ``layout`` as (N, 1, H, W), same dtype."""
    d = np.asarray(depth)
    if layout == "hwc":
        return np.moveaxis(d, -1, 1)
    if layout == "hw":
        return d[:, None]
    return d


class BCNet(nn.Module):
    """Depth CNN + vector MLP -> tanh action (3,); without a depth image (``depth_hw``
    None) the vector MLP alone, wider."""

    def __init__(self, depth_hw: tuple[int, int] | None, n_vec: int, vec_mean: np.ndarray, vec_std: np.ndarray) -> None:
        super().__init__()
        self.depth_hw = None if depth_hw is None else (int(depth_hw[0]), int(depth_hw[1]))
        self.n_vec = int(n_vec)
        if self.depth_hw is None:
            self.vec_fc = nn.Sequential(nn.Linear(n_vec, 256), nn.ReLU(), nn.Linear(256, 128), nn.ReLU())
            self.head = nn.Sequential(nn.Linear(128, 128), nn.ReLU(), nn.Linear(128, 3), nn.Tanh())
        else:
            h, w = self.depth_hw
            self.cnn = nn.Sequential(
                nn.Conv2d(1, 16, 8, stride=4), nn.ReLU(),
                nn.Conv2d(16, 32, 4, stride=2), nn.ReLU(),
                nn.Conv2d(32, 32, 3, stride=1), nn.ReLU(),
                nn.Flatten(),
            )
            with torch.no_grad():
                n_flat = self.cnn(torch.zeros(1, 1, h, w)).shape[1]
            self.depth_fc = nn.Sequential(nn.Linear(n_flat, 128), nn.ReLU())
            self.vec_fc = nn.Sequential(nn.Linear(n_vec, 64), nn.ReLU())
            self.head = nn.Sequential(nn.Linear(128 + 64, 128), nn.ReLU(), nn.Linear(128, 3), nn.Tanh())
        self.register_buffer("vec_mean", torch.as_tensor(np.asarray(vec_mean, np.float32)))
        self.register_buffer("vec_std", torch.as_tensor(np.asarray(vec_std, np.float32)))

    def forward(self, depth_u8: torch.Tensor | None, vec: torch.Tensor) -> torch.Tensor:
        """``depth_u8`` (B, 1, H, W) uint8 (None without a depth image), ``vec`` (B,
        n_vec) raw features (:func:`_inputs`)."""
        v = self.vec_fc((vec - self.vec_mean) / self.vec_std)
        if self.depth_hw is None:
            return self.head(v)
        x = self.depth_fc(self.cnn(depth_u8.float() / 255.0))
        return self.head(torch.cat([x, v], dim=1))


def _check_obs(obs_kwargs: Mapping[str, Any], where: str, task: str = POINTNAV_V0) -> None:
    if task not in TASKS:
        raise InputError(f"{where}: task {task!r} unknown (expected one of: {', '.join(TASKS)})")
    if task != POINTNAV_V0:
        return  # the decision-level tasks fix their own observations
    for k, v in REQUIRED_OBS.items():
        if obs_kwargs.get(k) != v:
            raise InputError(f"{where}: behaviour cloning needs {k}={v!r} observations (sim.rl.splits.LEARNER_OBS), got {obs_kwargs.get(k)!r}")
    if not obs_kwargs.get("observe_scan"):
        raise InputError(f"{where}: behaviour cloning needs the 'scan' observation (observe_scan > 0), got {obs_kwargs.get('observe_scan')!r}")


def _inputs(obs: Mapping[str, np.ndarray], layout: str) -> tuple[np.ndarray | None, np.ndarray]:
    """(depth (N, 1, H, W) uint8, vec (N, 6 + B) float32: goal features, odometry, scan)
    of a batch of observations; without a depth image (the decision-level tasks), (None,
    every term flattened in key order)."""
    if "depth" not in obs:
        keys = sorted(obs)
        n = len(np.asarray(obs[keys[0]]))
        return None, np.concatenate([np.asarray(obs[k], np.float32).reshape(n, -1) for k in keys], axis=1)
    depth = np.ascontiguousarray(depth_chw(obs["depth"], layout), dtype=np.uint8)
    n = len(depth)
    vec = np.concatenate(
        [goal_features(obs["goal"]), np.asarray(obs["odometry"], np.float32).reshape(n, 3), np.asarray(obs["scan"], np.float32).reshape(n, -1)],
        axis=1,
    )
    return depth, vec


@contextlib.contextmanager
def _one_thread() -> Iterator[None]:
    """torch on one thread inside: a small network gains nothing from more, training is
    then deterministic, and on a busy machine a second thread's waiting costs a
    single-observation step tens of milliseconds instead of about one."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(n)


class BCPolicy:
    """A trained :class:`BCNet` as a :class:`sim.rl.policies.Policy` (deterministic)."""

    def __init__(self, net: BCNet, obs_kwargs: Mapping[str, Any], name: str = "bc", task: str = POINTNAV_V0) -> None:
        self.net = net.eval()
        self.obs_kwargs = {k: env_value(v) for k, v in obs_kwargs.items()}
        self.name = name
        self.task = task
        """The registered task it was trained on (:mod:`sim.envs.tasks`), evaluated on by default."""
        self._layout = self.obs_kwargs.get("depth_layout", "hwc")

    def env_kwargs(self) -> dict[str, Any]:
        return dict(self.obs_kwargs)

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: dict[str, np.ndarray], info: dict[str, Any]) -> np.ndarray:
        return self.predict({k: np.asarray(v)[None] for k, v in obs.items()})[0]

    def predict(self, obs: Mapping[str, np.ndarray]) -> np.ndarray:
        """Actions (N, 3) float32 for a batch of observations (N, ...) per key."""
        depth, vec = _inputs(obs, self._layout)
        if vec.shape[1] != self.net.n_vec:
            raise InputError(
                f"policy {self.name}: the observations give {vec.shape[1]} features, the network was trained on "
                f"{self.net.n_vec} (evaluate it with the observation settings it was trained with, {self.task})"
            )
        with _one_thread(), torch.inference_mode():
            return self.net(_tensor(depth), torch.from_numpy(vec)).numpy().astype(np.float32)

    def save(self, directory: str | Path, history: Mapping[str, Any] | None = None) -> Path:
        """Write ``model.pt`` (the weights) and ``policy.json`` (observation settings,
        network shape, training history) into ``directory``."""
        d = Path(directory)
        if (d / SB3_MODEL_FILE).exists():
            raise InputError(f"{d}: holds a stable-baselines3 policy ({SB3_MODEL_FILE}); save the behaviour-cloning model elsewhere")
        output_path(d, "directory", directory=True)
        atomic_write(d / MODEL_FILE, lambda f: torch.save(self.net.state_dict(), f))
        doc = {
            "kind": "bc",
            "task": self.task,
            "env_kwargs": self.obs_kwargs,
            "depth_hw": None if self.net.depth_hw is None else list(self.net.depth_hw),
            "n_vec": self.net.n_vec,
            "history": dict(history or {}),
        }
        atomic_write_text(d / POLICY_FILE, json.dumps(doc, indent=2) + "\n")
        return d

    @classmethod
    def load(cls, directory: str | Path) -> BCPolicy:
        """Read a directory written by :meth:`save`; a missing or malformed one is an InputError."""
        d = Path(directory)
        if not d.is_dir():
            raise InputError(f"{d}: no such behaviour-cloning model directory (expected one with {MODEL_FILE} and {POLICY_FILE}, as `depthnav demos bc` writes)")
        try:
            doc = json.loads((d / POLICY_FILE).read_text(encoding="utf-8"))
            if doc.get("format") == SB3_FORMAT:
                raise InputError(f"{d}: a stable-baselines3 policy, not a behaviour-cloning model (evaluate it as ppo:{d})")
            if doc.get("kind") != "bc":
                raise InputError(f"{d}: not a behaviour-cloning model (policy.json kind {doc.get('kind')!r})")
            state = torch.load(d / MODEL_FILE, map_location="cpu", weights_only=True)
            n = int(doc["n_vec"])
            task = str(doc.get("task", POINTNAV_V0))
            _check_obs(dict(doc["env_kwargs"]), str(d / POLICY_FILE), task)
            net = BCNet(None if doc["depth_hw"] is None else tuple(doc["depth_hw"]), n, np.zeros(n), np.ones(n))
            net.load_state_dict(state)
            obs_kwargs = dict(doc["env_kwargs"])
        except InputError:
            raise
        except FileNotFoundError as e:
            raise InputError(f"{d}: not a behaviour-cloning model directory ({Path(e.filename).name} missing)") from None
        except Exception as e:
            raise InputError(f"{d}: not a behaviour-cloning model directory ({type(e).__name__}: {e})") from None
        return cls(net, obs_kwargs, name=f"bc:{d}", task=task)


def train_bc(
    demos: Demonstrations,
    epochs: int = 10,
    batch_size: int = 256,
    seed: int = 0,
    lr: float = 1e-3,
    heldout_fraction: float = 0.2,
) -> tuple[BCPolicy, dict[str, Any]]:
    """Fit a :class:`BCNet` to the expert actions (MSE, Adam) and return the policy and
    its history: ``train_loss`` (mean over each epoch's batches), ``heldout_loss`` (MSE on
    the held-out episodes after each epoch), ``train_mse_initial`` and
    ``heldout_mse_initial`` (before training), ``heldout_mean_baseline`` (the MSE of
    predicting the training set's mean action on the held-out steps), the episodes and
    steps on each side. The held-out set is a ``heldout_fraction`` of the episodes
    (at least one, at most all but one), drawn with ``seed``; whole episodes, so no near-duplicate frame of a
    training step is held out."""
    def need(ok: bool, name: str, what: str, v: Any) -> None:
        if not ok or isinstance(v, bool):
            raise InputError(f"{name}: expected {what}, got {v!r}")

    if not isinstance(demos, Demonstrations):
        raise InputError(f"demos: expected a Demonstrations (sim.rl.demos.load_demonstrations), got {type(demos).__name__}")
    need(isinstance(epochs, int | np.integer) and epochs >= 1, "epochs", "an integer >= 1", epochs)
    need(isinstance(batch_size, int | np.integer) and batch_size >= 1, "batch_size", "an integer >= 1", batch_size)
    need(isinstance(seed, int | np.integer) and seed >= 0, "seed", "an integer >= 0", seed)
    need(isinstance(lr, int | float) and math.isfinite(lr) and lr > 0, "lr", "a positive number", lr)
    need(isinstance(heldout_fraction, int | float) and 0 < heldout_fraction < 1, "heldout_fraction", "a number in (0, 1)", heldout_fraction)
    epochs, batch_size, seed = int(epochs), int(batch_size), int(seed)
    obs_kwargs = observation_kwargs(demos.meta.get("env_kwargs", {}))
    task = str(demos.meta.get("task", POINTNAV_V0))
    _check_obs(obs_kwargs, "demonstrations", task)
    if demos.n_episodes < 2:
        raise InputError(f"demonstrations: behaviour cloning needs at least 2 episodes (one held out), got {demos.n_episodes}")

    rng = np.random.default_rng(seed)
    n_held = min(max(1, round(demos.n_episodes * heldout_fraction)), demos.n_episodes - 1)
    held_eps = np.sort(rng.permutation(demos.n_episodes)[:n_held])
    held = np.zeros(demos.n_steps, dtype=bool)
    for e in held_eps:
        s = int(demos.episode_starts[e])
        held[s : s + int(demos.episode_lengths[e])] = True
    depth, vec = _inputs(demos.observations, obs_kwargs.get("depth_layout", "hwc"))
    actions = np.asarray(demos.actions, np.float32)
    tr, ho = np.flatnonzero(~held), np.flatnonzero(held)
    mean, std = vec[tr].mean(axis=0), vec[tr].std(axis=0)
    std = np.maximum(std, 1e-3)  # constant inputs (e.g. an always-empty scan bin)

    with _one_thread():
        torch.manual_seed(seed)
        net = BCNet(None if depth is None else depth.shape[2:], vec.shape[1], mean, std)
        opt = torch.optim.Adam(net.parameters(), lr=lr)
        t_depth, t_vec, t_act = _tensor(depth), torch.from_numpy(vec), torch.from_numpy(actions)

        def rows(j: torch.Tensor) -> torch.Tensor | None:
            return None if t_depth is None else t_depth[j]
        gen = torch.Generator().manual_seed(seed)

        def mse(idx: np.ndarray) -> float:
            net.eval()
            total = 0.0
            with torch.no_grad():
                for i in range(0, len(idx), 1024):
                    j = torch.from_numpy(idx[i : i + 1024])
                    total += float(((net(rows(j), t_vec[j]) - t_act[j]) ** 2).mean(dim=1).sum())
            return total / len(idx)

        hist: dict[str, Any] = {
            "train_loss": [],
            "heldout_loss": [],
            "train_mse_initial": mse(tr),
            "heldout_mse_initial": mse(ho),
            "heldout_mean_baseline": float(((actions[ho] - actions[tr].mean(axis=0)) ** 2).mean()),
            "train_episodes": int(demos.n_episodes - n_held),
            "heldout_episodes": int(n_held),
            "train_steps": int(len(tr)),
            "heldout_steps": int(len(ho)),
            "epochs": epochs, "batch_size": batch_size, "seed": seed, "lr": lr, "task": task,
        }
        t_tr = torch.from_numpy(tr)
        for _ in range(epochs):
            net.train()
            order = t_tr[torch.randperm(len(tr), generator=gen)]
            losses = []
            for i in range(0, len(order), batch_size):
                j = order[i : i + batch_size]
                loss = ((net(rows(j), t_vec[j]) - t_act[j]) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(float(loss.detach()) * len(j))
            hist["train_loss"].append(sum(losses) / len(tr))
            hist["heldout_loss"].append(mse(ho))
    return BCPolicy(net, obs_kwargs, task=task), hist


def _tensor(a: np.ndarray | None) -> torch.Tensor | None:
    return None if a is None else torch.from_numpy(a)
