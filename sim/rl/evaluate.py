"""The standard evaluation of a policy on a building split: success, SPL, soft-SPL,
collisions, path length and localization error over fixed episodes.

SPL (Anderson et al. 2018, "On Evaluation of Embodied Navigation Agents"):
``SPL_i = S_i * l_i / max(p_i, l_i)`` with ``S_i`` success, ``l_i`` the start-goal
geodesic distance the env reports at reset (``info["goal_distance_m"]``) and ``p_i`` the
length of the true trajectory (the sum of the steps of ``info["pose"]``). Soft-SPL
(Habitat): ``max(0, 1 - d_T / l_i) * l_i / max(p_i, l_i)`` with ``d_T`` the final
geodesic distance to the goal. Every policy runs the same :class:`EpisodeSpec` list
(:func:`sim.rl.benchmark_episodes.benchmark_specs`: on val and test the frozen benchmark
episodes of ``sim/rl/episodes/DepthNav-v0.json``, each reset checked against the file;
otherwise :func:`sim.rl.splits.episode_specs`), so it meets the same buildings,
furniture, people, starts and goals. docs/rl.md describes the numbers and the JSON report.
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.files import output_path
from sim.experiments.report_file import json_safe, write_json
from sim.rl.benchmark_episodes import FrozenEpisode, benchmark_specs, frozen_count
from sim.rl.policies import Policy
from sim.rl.policy_specs import make_policy
from sim.rl.splits import TASK_KEYS, EpisodeSpec, Split, benchmark_task, get_split

#: 95 % two-sided normal quantile, for the confidence half-widths of the summary.
Z95 = 1.959963984540054

#: Per-episode quantities summarised as mean and 95 % half-width (summary key: EpisodeResult field).
SUMMARY_METRICS = {
    "success": "success",
    "spl": "spl",
    "soft_spl": "soft_spl",
    "collisions": "collisions",
    "path_length_m": "path_length_m",
    "loc_error_m": "loc_error_mean_m",
    "geodesic_m": "geodesic_m",
    "final_distance_m": "final_distance_m",
    "loc_resets": "loc_resets",
    "steps": "steps",
}

OnStep = Callable[[dict, np.ndarray, float, dict, bool, bool, dict], None]


# -- metrics -------------------------------------------------------------------------------
def spl(success: bool, geodesic_m: float, path_length_m: float) -> float:
    """Success weighted by path length (Anderson et al. 2018): S * l / max(p, l)."""
    if not success:
        return 0.0
    if geodesic_m <= 0.0:
        return 1.0
    return float(geodesic_m / max(path_length_m, geodesic_m))


def soft_spl(final_distance_m: float, geodesic_m: float, path_length_m: float) -> float:
    """Habitat's soft-SPL: max(0, 1 - d_T / l) * l / max(p, l); progress instead of success."""
    if geodesic_m <= 0.0:
        return 1.0
    progress = max(0.0, 1.0 - final_distance_m / geodesic_m)
    return float(progress * geodesic_m / max(path_length_m, geodesic_m))


def path_length(xy: np.ndarray) -> float:
    """Length of a polyline of (N, 2) positions: the sum of |delta xy|."""
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) < 2:
        return 0.0
    return float(np.hypot(*np.diff(xy[:, :2], axis=0).T).sum())


def mean_ci95(values: Iterable[float]) -> tuple[float, float]:
    """Mean and the 95 % confidence half-width of the mean (normal approximation,
    1.96 s / sqrt(n) with the sample standard deviation); NaN half-width for n < 2."""
    v = np.asarray(list(values), dtype=np.float64)
    if v.size == 0:
        return math.nan, math.nan
    if v.size < 2:
        return float(v[0]), math.nan
    return float(v.mean()), float(Z95 * v.std(ddof=1) / math.sqrt(v.size))


# -- one episode ---------------------------------------------------------------------------
@dataclass(frozen=True)
class EpisodeResult:
    """The outcome of one episode."""

    index: int
    building_seed: int
    reset_seed: int
    success: bool
    spl: float
    soft_spl: float
    geodesic_m: float
    """Start-goal geodesic distance at reset (l in SPL)."""
    path_length_m: float
    """Length of the true trajectory (p in SPL)."""
    final_distance_m: float
    """Geodesic distance to the goal at the end (d_T in soft-SPL)."""
    collisions: int
    steps: int
    loc_error_mean_m: float
    """Mean over the steps of the distance between the pose estimate and the true pose."""
    loc_resets: int
    wall_s: float
    """Reset and steps, including the policy."""
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """True (x, y, theta) at reset."""
    goal_xy: tuple[float, float] = (0.0, 0.0)


def run_episode(env: Any, policy: Policy, spec: EpisodeSpec, on_step: OnStep | None = None) -> EpisodeResult:
    """Run one episode of ``spec`` on ``env`` (a DepthNav env on ``spec.building_seed``)
    until it terminates or truncates. ``on_step(obs, action, reward, next_obs, terminated,
    truncated, info)`` is called after every step, ``obs`` being the observation the
    action was chosen on. A :class:`FrozenEpisode` is checked after the reset: an env that
    did not produce the frozen episode raises a :class:`FrozenEpisodeError` before any
    step."""
    t0 = time.perf_counter()
    obs, info = env.reset(seed=spec.reset_seed)
    site = getattr(env.unwrapped, "site", None)
    if site is not None and site.seed is not None and site.seed != spec.building_seed:
        raise ValueError(f"run_episode: the env is on building {site.seed}, the episode on {spec.building_seed}")
    if isinstance(spec, FrozenEpisode):
        spec.check(env, info)
    policy.reset(spec.reset_seed)
    start = np.asarray(info["pose"], dtype=np.float64).copy()
    goal = np.asarray(info["goal"], dtype=np.float64).copy()
    geodesic = float(info["goal_distance_m"])
    prev = start[:2].copy()
    length = 0.0
    loc_sum = 0.0
    steps = 0
    done = False
    while not done:
        action = np.asarray(policy.act(obs, info))
        next_obs, reward, terminated, truncated, info = env.step(action)
        if on_step is not None:
            on_step(obs, action, float(reward), next_obs, bool(terminated), bool(truncated), info)
        xy = info["pose"]
        length += math.hypot(xy[0] - prev[0], xy[1] - prev[1])
        prev = (xy[0], xy[1])
        loc_sum += info["loc_error_m"]
        steps += 1
        obs = next_obs
        done = terminated or truncated
    success = bool(info["success"])
    final = float(info["goal_distance_m"])
    return EpisodeResult(
        index=spec.index,
        building_seed=spec.building_seed,
        reset_seed=spec.reset_seed,
        success=success,
        spl=spl(success, geodesic, length),
        soft_spl=soft_spl(final, geodesic, length),
        geodesic_m=geodesic,
        path_length_m=length,
        final_distance_m=final,
        collisions=int(info["collisions"]),
        steps=steps,
        loc_error_mean_m=loc_sum / steps,
        loc_resets=int(info["loc_resets"]),
        wall_s=time.perf_counter() - t0,
        start_pose=(float(start[0]), float(start[1]), float(start[2])),
        goal_xy=(float(goal[0]), float(goal[1])),
    )


# -- reports -------------------------------------------------------------------------------
def summarize(results: Sequence[EpisodeResult], wall_s: float) -> dict[str, float]:
    """Mean and 95 % half-width (``<name>_ci95``) of every :data:`SUMMARY_METRICS`, and
    episodes, total steps, wall time and steps per second of wall time."""
    out: dict[str, float] = {"episodes": len(results)}
    for key, attr in SUMMARY_METRICS.items():
        m, h = mean_ci95(float(getattr(r, attr)) for r in results)
        out[key] = m
        out[f"{key}_ci95"] = h
    steps = int(sum(r.steps for r in results))
    out["total_steps"] = steps
    out["wall_s"] = float(wall_s)
    out["steps_per_s"] = steps / wall_s if wall_s > 0 else math.nan
    return out


@dataclass
class EvalReport:
    """What :func:`evaluate` measured: the per-episode results (sorted by index) and
    their summary."""

    policy: str
    split: str
    seed: int
    episodes: int
    """Episodes asked for (``len(results)`` is smaller when interrupted)."""
    results: list[EpisodeResult]
    summary: dict[str, float]
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    """The env arguments besides the building (the benchmark task, the policy's, overrides)."""
    interrupted: bool = False
    frozen_episodes: int = 0
    """How many of the episodes came from the frozen file (and were checked against it)."""
    episodes_file: str | None = None
    """The frozen file they came from (None when none did)."""
    task: str = "DepthNav-v0"
    """The registered task the episodes ran on (:mod:`sim.envs.tasks`)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (non-finite numbers as null)."""
        return json_safe(
            {
                "policy": self.policy,
                "task": self.task,
                "split": self.split,
                "seed": self.seed,
                "episodes": self.episodes,
                "interrupted": self.interrupted,
                "frozen_episodes": self.frozen_episodes,
                "episodes_file": self.episodes_file,
                "env_kwargs": self.env_kwargs,
                "summary": self.summary,
                "results": [dataclasses.asdict(r) for r in self.results],
            }
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"

    def table(self) -> str:
        """A one-row :func:`comparison_table`."""
        return comparison_table([self])


TABLE_COLUMNS = (
    ("policy", None, 1.0, 0),
    ("success", "success", 1.0, 2),
    ("SPL", "spl", 1.0, 2),
    ("soft-SPL", "soft_spl", 1.0, 2),
    ("collisions/ep", "collisions", 1.0, 2),
    ("path m", "path_length_m", 1.0, 1),
    ("loc error cm", "loc_error_m", 100.0, 1),
    ("steps/s", "steps_per_s", 1.0, 0),
)


def comparison_table(reports: Sequence[EvalReport]) -> str:
    """A Markdown table: one row per report, mean ± 95 % half-width."""

    def cell(r: EvalReport, key: str | None, scale: float, digits: int) -> str:
        if key is None:
            return r.policy + (" (interrupted)" if r.interrupted else "")
        m = r.summary.get(key, math.nan) * scale
        h = r.summary.get(f"{key}_ci95", math.nan) * scale
        if key == "steps_per_s" or not math.isfinite(h):
            return f"{m:.{digits}f}"
        return f"{m:.{digits}f} ± {h:.{digits}f}"

    head = [c[0] for c in TABLE_COLUMNS]
    rows = [[cell(r, *c[1:]) for c in TABLE_COLUMNS] for r in reports]
    widths = [max(len(x) for x in col) for col in zip(head, *rows, strict=True)]

    def line(cells: list[str]) -> str:
        return "| " + " | ".join(c.ljust(w) for c, w in zip(cells, widths, strict=True)) + " |"

    n = reports[0].summary.get("episodes", 0) if reports else 0
    caption = f"{reports[0].split} split, {n} episodes, seed {reports[0].seed}" if reports else ""
    return "\n".join([caption, line(head), "| " + " | ".join("-" * w for w in widths) + " |", *map(line, rows)])


# -- the evaluation ------------------------------------------------------------------------
def policy_task(policy: Policy, task: str | None = None) -> str:
    """The registered task a policy is evaluated on: ``task`` when given, else the one it
    was trained on (its ``task`` attribute), else ``DepthNav-v0``. A trained policy on
    another task than its own is an InputError: it was built for that task's observations."""
    own = getattr(policy, "task", None)
    if task and own and task != own:
        raise InputError(f"--task {task}: policy {policy.name} was trained on {own} and observes what that task gives; evaluate it there")
    return task or own or "DepthNav-v0"


def episode_env_kwargs(
    policy: Policy, building_seed: int, env_kwargs: Mapping[str, Any] | None = None, task: str = "DepthNav-v0"
) -> dict[str, Any]:
    """The env arguments of an evaluation episode of ``task`` on one building: the
    policy's own (observations, expert) without task keys, the benchmark task
    (:func:`sim.rl.splits.benchmark_task`) on ``building_seed``, then ``env_kwargs``
    (overrides, e.g. a shorter max_steps for tests)."""
    own = dict(policy.env_kwargs())
    bench = benchmark_task(task)
    for k in sorted(TASK_KEYS & own.keys()):
        v = own.pop(k)
        if k in bench and json_safe(v) != json_safe(bench[k]):
            warnings.warn(
                f"policy {policy.name}: env argument {k}={v!r} ignored; the benchmark task sets {bench[k]!r}",
                stacklevel=3,
            )
    return {**own, "building": "procedural", "building_seeds": (int(building_seed),), **bench, **(env_kwargs or {})}


def evaluate(
    policy: Policy | str,
    split: str | Split = "val",
    episodes: int = 50,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = True,
    out: str | Path | None = None,
    episodes_file: str | Path | None = None,
    task: str | None = None,
) -> EvalReport:
    """Run ``policy`` (a :class:`Policy` or a spec for :func:`make_policy`) on the
    ``episodes`` episodes of :func:`benchmark_specs` (split, seed; on val and test the
    frozen ones of ``episodes_file``, default ``sim/rl/episodes/DepthNav-v0.json``), one
    building's env at a time, and summarise. ``task``: the registered task
    (:func:`policy_task`: default the one the policy was trained on); every task runs the
    same frozen episodes (buildings, starts, goals, people, furniture), each with its
    own step limit. ``out``: write the report's JSON there (atomically), also when
    interrupted (``"interrupted": true``, then the KeyboardInterrupt goes on)."""
    sp = get_split(split)
    if task is not None:
        benchmark_task(task)  # an unknown task fails before any work
    specs = benchmark_specs(sp, episodes, seed, episodes_file)
    if out is not None:
        output_path(out)
    sink = None if out is None else (lambda report: write_json(out, report.to_dict()))
    return _evaluate(policy, sp, specs, seed, env_kwargs, progress, sink, task)


def compare(
    policies: Sequence[Policy | str],
    split: str | Split = "val",
    episodes: int = 50,
    seed: int = 0,
    env_kwargs: Mapping[str, Any] | None = None,
    progress: bool = True,
    out: str | Path | None = None,
    episodes_file: str | Path | None = None,
    task: str | None = None,
) -> list[EvalReport]:
    """:func:`evaluate` each policy on the same episodes, in turn. ``out``: one JSON file
    ``{"split", "seed", "episodes", "reports": [...], "table"}`` rewritten after every
    policy (and on an interrupt, with the unfinished report marked)."""
    sp = get_split(split)
    specs = benchmark_specs(sp, episodes, seed, episodes_file)  # bad arguments fail before any policy is made
    if out is not None:
        output_path(out)
    made = [make_policy(p) if isinstance(p, str) else p for p in policies]
    done: list[EvalReport] = []

    def write(report: EvalReport | None) -> None:
        if out is None:
            return
        reps = done + ([report] if report is not None else [])
        doc = {"split": sp.name, "seed": seed, "episodes": episodes, "table": comparison_table(reps), "reports": [r.to_dict() for r in reps]}
        write_json(out, doc)

    for p in made:
        done.append(_evaluate(p, sp, specs, seed, env_kwargs, progress, write, task))
    return done


def run_episodes(
    policy: Policy,
    specs: Sequence[EpisodeSpec],
    env_kwargs: Mapping[str, Any] | None = None,
    *,
    episode: Callable[[Any, EpisodeSpec], EpisodeResult] | None = None,
    progress: bool = False,
    desc: str = "episodes",
    task: str = "DepthNav-v0",
) -> Iterator[EpisodeResult]:
    """Run the episodes of ``specs`` and yield their results as they finish: grouped by
    building (in order of first appearance), one env per building made with
    :func:`episode_env_kwargs` (through :func:`sim.envs.depthnav.make`: gymnasium's
    ``TimeLimit`` at the env's own ``max_steps``) and closed after its episodes (also on an
    exception, a KeyboardInterrupt included), counted on a tqdm bar (stderr) with the
    success rate so far. ``episode(env, spec)`` runs one episode (default
    :func:`run_episode` with ``policy``)."""
    from tqdm import tqdm

    from sim.envs.depthnav import make

    if episode is None:

        def episode(env: Any, spec: EpisodeSpec) -> EpisodeResult:
            return run_episode(env, policy, spec)

    groups: dict[int, list[EpisodeSpec]] = {}
    for s in specs:
        groups.setdefault(s.building_seed, []).append(s)
    n = successes = 0
    with tqdm(total=len(specs), desc=desc, unit="ep", disable=not progress, file=sys.stderr, leave=False) as bar:
        for b, group in groups.items():
            env = make(task, **episode_env_kwargs(policy, b, env_kwargs, task))
            try:
                for s in group:
                    r = episode(env, s)
                    n += 1
                    successes += bool(r.success)
                    bar.update(1)
                    bar.set_postfix(success=f"{successes / n:.2f}")
                    yield r
            finally:
                env.close()


def _evaluate(
    policy: Policy | str,
    sp: Split,
    specs: Sequence[EpisodeSpec],
    seed: int,
    env_kwargs: Mapping[str, Any] | None,
    progress: bool,
    sink: Callable[[EvalReport], None] | None,
    task: str | None = None,
) -> EvalReport:
    pol = make_policy(policy) if isinstance(policy, str) else policy
    task = policy_task(pol, task)
    shown = {k: v for k, v in episode_env_kwargs(pol, specs[0].building_seed, env_kwargs, task).items() if k != "building_seeds"}
    frozen = [s for s in specs if isinstance(s, FrozenEpisode)]
    source = frozen[0].source if frozen else None
    results: list[EpisodeResult] = []

    def report(interrupted: bool) -> EvalReport:
        rs = sorted(results, key=lambda r: r.index)
        return EvalReport(pol.name, sp.name, int(seed), len(specs), rs, summarize(rs, time.perf_counter() - t0), shown, interrupted,
                          frozen_count(specs), source, task)

    t0 = time.perf_counter()
    try:
        for r in run_episodes(pol, specs, env_kwargs, progress=progress, desc=f"{pol.name} on {sp.name}", task=task):
            results.append(r)
    except KeyboardInterrupt:
        if sink is not None:
            sink(report(True))
        raise
    rep = report(False)
    if sink is not None:
        sink(rep)
    return rep


# -- helpers -------------------------------------------------------------------------------

