"""The frozen benchmark episodes: the val and test episodes of ``DepthNav-v0`` as a
committed data file, which :func:`sim.rl.evaluate.evaluate` (``depthnav eval``) runs and
checks.

:func:`sim.rl.splits.episode_specs` derives each evaluation episode (its building and
reset seed) from seed hashing, and the env draws the episode's furniture, people, start
and goal from the reset seed: a change to the generator, the sampler or the task would
change the benchmark without a word while its id stays the same. The file
``sim/rl/episodes/DepthNav-v0.json`` fixes the first :data:`FROZEN_EPISODES` episodes of
seed :data:`FROZEN_SEED` of each of ``val`` and ``test``: the building seed, the reset
seed, and what the env produced at that reset (:func:`reset_record`: the start pose, the
goal and its graph node, the start-goal geodesic distance, the furniture and the people).
The evaluation takes the building and reset seed of these episodes from the file and,
after every reset, checks that the env produced the same (to :data:`TOLERANCE`); where
it did not, it stops with a one-line :class:`FrozenEpisodeError` naming the file, the
split, the episode and what differed. A change that alters them is a new version of the
task, with its own file, never a rewrite of this one. ``python -m sim.rl.freeze_episodes``
writes the file (:mod:`sim.rl.freeze_episodes`); docs/rl.md describes it.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from autonomy.common.errors import InputError
from sim.experiments.report_file import json_safe
from sim.rl.splits import BENCHMARK_TASK, SPLITS, EpisodeSpec, Split, episode_specs, get_split

#: The task whose episodes are frozen (a new version of it is a new id and a new file).
TASK_ID = "DepthNav-v0"

#: Where the frozen episode files are: one ``<task id>.json`` per task.
EPISODES_DIR = Path(__file__).resolve().parent / "episodes"

#: The folder holding the ``sim`` package (the repository root in a checkout).
_PACKAGE_ROOT = Path(__file__).resolve().parents[2]

#: The file's format name and version (of the layout, not of the task).
FORMAT = "depthnav-frozen-episodes"
FORMAT_VERSION = 1

#: The splits, the episode seed and the number of episodes of each split the file holds.
FROZEN_SPLITS = ("val", "test")
FROZEN_SEED = 0
FROZEN_EPISODES = 100

#: Largest difference (metres, radians) between a frozen number and the env's.
TOLERANCE = 1e-6

#: Decimals of the numbers written (well below the tolerance).
DECIMALS = 7

#: What each episode record holds (written into the file as its legend).
FIELDS = {
    "index": "the episode's index k in episode_specs(split, N, seed)",
    "building_seed": "the procedural building (blueprints.generate_building's seed)",
    "reset_seed": "the env.reset seed; the env's streams (EpisodeSeeds.from_seed) come from it: "
    "'actors' draws the furniture and the people, 'mission' the start and goal",
    "start": "true pose at reset: x, y (m), yaw (rad)",
    "goal": "goal position: x, y (m)",
    "goal_node": "navigation-graph node of the goal",
    "goal_distance_m": "start-goal geodesic distance at reset (l in SPL)",
    "furniture": "each piece: kind, x, y (m), yaw (rad)",
    "people": "each person: route start x, y, route end x, y (m), route points, speed (m/s), "
    "start offset along the route (m)",
}


class FrozenEpisodeError(InputError):
    """The frozen episodes cannot be used: the file is missing or malformed, the code's
    task or splits differ from the frozen ones, or the env no longer produces a frozen
    episode. ``str(err)`` is one line naming the file."""


class UnfrozenEpisodesWarning(UserWarning):
    """An evaluation on val or test runs episodes the file does not hold (another seed,
    or more episodes than it has): drawn from the current code, not the frozen benchmark."""


@dataclass(frozen=True)
class FrozenEpisode(EpisodeSpec):
    """An evaluation episode read from the frozen file: its spec, and what the env must
    produce at its reset (:meth:`check`)."""

    split: str
    record: str
    """The episode's record as written (JSON), what :func:`reset_record` must reproduce."""
    source: str
    """The file, as error messages name it."""

    def expected(self) -> dict[str, Any]:
        """The frozen record (a dict like :func:`reset_record`'s)."""
        return json.loads(self.record)

    def check(self, env: Any, info: Mapping[str, Any]) -> None:
        """Raise a :class:`FrozenEpisodeError` unless the env, just reset with this
        episode's seed (``info`` its reset info), produced the frozen episode."""
        diff = first_difference(self.expected(), reset_record(env, info, self))
        if diff is not None:
            raise FrozenEpisodeError(
                f"{self.source}: {self.split} episode {self.index}: {diff}: the generator, the sampler or the task "
                "changed; freeze a new version (docs/rl.md)"
            )


@dataclass(frozen=True)
class FrozenEpisodes:
    """A frozen-episodes file, read and checked against the code's task and splits."""

    path: Path
    task_id: str
    seed: int
    episodes: dict[str, tuple[FrozenEpisode, ...]]
    """Split name -> its episodes, by index."""

    @property
    def source(self) -> str:
        return shown_path(self.path)


def episodes_file(task_id: str = TASK_ID) -> Path:
    """The frozen episodes of a task: ``sim/rl/episodes/<task_id>.json``."""
    return EPISODES_DIR / f"{task_id}.json"


def shown_path(path: Path) -> str:
    """``path`` as messages show it: from the repository root where it is in the package
    (``sim/rl/episodes/DepthNav-v0.json``), else relative to the working directory where
    it is below it, else as it is."""
    p = Path(path).resolve()
    for base in (_PACKAGE_ROOT, Path.cwd()):
        try:
            return p.relative_to(base).as_posix()
        except ValueError:
            continue
    return str(path)


def task_record() -> dict[str, Any]:
    """The benchmark task as the file records it."""
    return json_safe(dict(BENCHMARK_TASK))


def split_record(split: Split) -> dict[str, Any]:
    """A split's buildings and episode seed as the file records them."""
    return {"building_seeds": list(split.building_seeds), "episode_seed": split.episode_seed}


# -- what the env produced ----------------------------------------------------------------
def _num(v: Any) -> float:
    return round(float(v), DECIMALS)


def reset_record(env: Any, info: Mapping[str, Any], spec: EpisodeSpec) -> dict[str, Any]:
    """What the env (a DepthNav env, wrapped or not) produced at its reset for ``spec``,
    ``info`` being the reset's info: the record :data:`FIELDS` describes."""
    u = env.unwrapped
    site = u.site
    return {
        "index": int(spec.index),
        "building_seed": int(spec.building_seed),
        "reset_seed": int(spec.reset_seed),
        "start": [_num(v) for v in info["pose"]],
        "goal": [_num(v) for v in info["goal"]],
        "goal_node": int(u.goal_node),
        "goal_distance_m": _num(info["goal_distance_m"]),
        "furniture": [[f.kind, _num(f.x), _num(f.y), _num(f.yaw)] for f in site.furniture],
        "people": [
            [*(_num(v) for v in p.route[0]), *(_num(v) for v in p.route[-1]), len(p.route), _num(p.speed_mps), _num(p.start_offset_m)]
            for p in site.people
        ],
    }


def _close(a: Sequence[Any], b: Sequence[Any], angles: Sequence[int] = ()) -> bool:
    if len(a) != len(b):
        return False
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        if isinstance(x, str) or isinstance(y, str):
            if x != y:
                return False
            continue
        d = float(x) - float(y)
        if i in angles:
            d = math.remainder(d, 2.0 * math.pi)
        if not abs(d) <= TOLERANCE:
            return False
    return True


def _shown(v: Sequence[Any]) -> str:
    return "(" + ", ".join(x if isinstance(x, str) else f"{float(x):.7g}" for x in v) + ")"


def first_difference(frozen: Mapping[str, Any], env: Mapping[str, Any]) -> str | None:
    """The first way the env's record differs from the frozen one, as words ("the env's
    start (x, y, yaw) ... differs from the frozen one ..."), or None where they agree to
    :data:`TOLERANCE`."""
    for key in ("building_seed", "reset_seed"):
        if int(env[key]) != int(frozen[key]):
            return f"the env's {key.replace('_', ' ')} {env[key]} differs from the frozen one {frozen[key]}"
    if not _close(env["start"], frozen["start"], angles=(2,)):
        return f"the env's start (x, y, yaw) {_shown(env['start'])} differs from the frozen one {_shown(frozen['start'])}"
    if not _close(env["goal"], frozen["goal"]):
        return f"the env's goal (x, y) {_shown(env['goal'])} differs from the frozen one {_shown(frozen['goal'])}"
    if int(env["goal_node"]) != int(frozen["goal_node"]):
        return f"the env's goal node {env['goal_node']} differs from the frozen one {frozen['goal_node']}"
    if not _close([env["goal_distance_m"]], [frozen["goal_distance_m"]]):
        return (f"the env's start-goal geodesic distance {env['goal_distance_m']:.7g} m differs from the frozen one "
                f"{frozen['goal_distance_m']:.7g} m")
    for key, what, angles in (("furniture", "furniture piece", (3,)), ("people", "person", ())):
        mine, theirs = env[key], frozen[key]
        if len(mine) != len(theirs):
            return f"the env has {len(mine)} {key} entries, the frozen episode {len(theirs)}"
        for i, (a, b) in enumerate(zip(mine, theirs, strict=True)):
            if not _close(a, b, angles):
                return f"the env's {what} {i} {_shown(a)} differs from the frozen one {_shown(b)}"
    return None


# -- the file ---------------------------------------------------------------------------------
def load_frozen_episodes(path: str | os.PathLike[str] | None = None) -> FrozenEpisodes:
    """Read a frozen-episodes file (default :func:`episodes_file`) and check it against the
    code: the benchmark task and the splits' buildings and episode seeds must be the
    frozen ones, and each split's episodes numbered 0..N-1. Every problem is a one-line
    :class:`FrozenEpisodeError` naming the file."""
    p = Path(path) if path is not None else episodes_file()
    src = shown_path(p)

    def fail(msg: str) -> FrozenEpisodeError:
        return FrozenEpisodeError(f"{src}: {msg}")

    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise fail("frozen benchmark episodes not found (python -m sim.rl.freeze_episodes writes them)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise fail(f"cannot read the frozen benchmark episodes ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise fail(f"not a frozen-episodes file (expected format {FORMAT!r})")
    if doc.get("version") != FORMAT_VERSION:
        raise fail(f"frozen-episodes format version {doc.get('version')!r} unknown (expected {FORMAT_VERSION})")
    if doc.get("task_id") != TASK_ID:
        raise fail(f"frozen episodes of {doc.get('task_id')!r}, expected {TASK_ID!r}")
    if doc.get("task") != task_record():
        diff = sorted(k for k in set(task_record()) | set(doc.get("task") or {}) if (doc.get("task") or {}).get(k) != task_record().get(k))
        raise fail(f"the code's benchmark task differs from the frozen one ({', '.join(diff)}): a changed task is a new "
                   "version; freeze it (docs/rl.md)")
    splits = doc.get("splits")
    if not isinstance(splits, dict) or not isinstance(doc.get("seed"), int):
        raise fail("expected 'seed' and 'splits'")
    out: dict[str, tuple[FrozenEpisode, ...]] = {}
    for name, sp in splits.items():
        if name not in SPLITS:
            raise fail(f"split {name!r} unknown (expected one of: {', '.join(SPLITS)})")
        if not isinstance(sp, dict) or {k: sp.get(k) for k in ("building_seeds", "episode_seed")} != split_record(SPLITS[name]):
            raise fail(f"the code's {name} split (buildings, episode seed) differs from the frozen one: a changed split is "
                       "a new version; freeze it (docs/rl.md)")
        eps = []
        for k, rec in enumerate(sp.get("episodes") or []):
            if not isinstance(rec, dict) or rec.get("index") != k or not set(FIELDS) <= set(rec):
                raise fail(f"{name} episode {k}: expected a record with index {k} and the fields {', '.join(FIELDS)}")
            if rec.get("building_seed") not in SPLITS[name].building_seeds:
                raise fail(f"{name} episode {k}: building {rec.get('building_seed')!r} is not one of the split's")
            try:
                eps.append(FrozenEpisode(k, int(rec["building_seed"]), int(rec["reset_seed"]), name, json.dumps(rec), src))
            except (TypeError, ValueError):
                raise fail(f"{name} episode {k}: building_seed and reset_seed must be integers") from None
        out[name] = tuple(eps)
    return FrozenEpisodes(p, TASK_ID, int(doc["seed"]), out)


def benchmark_specs(
    split: str | Split, episodes: int, seed: int = 0, path: str | os.PathLike[str] | None = None
) -> list[EpisodeSpec]:
    """The evaluation's episodes: :func:`episode_specs` (split, episodes, seed), with every
    episode the frozen file holds (val and test, its seed, its first N) read from it as a
    :class:`FrozenEpisode` (building and reset seed from the file, checked at its reset).
    Val or test episodes the file does not hold are drawn from the current code, with an
    :class:`UnfrozenEpisodesWarning`; the train split and custom splits are not frozen."""
    specs = episode_specs(split, episodes, seed)
    sp = get_split(split)
    if sp.name not in FROZEN_SPLITS or SPLITS.get(sp.name) != sp:
        return specs
    frozen = load_frozen_episodes(path)
    held = frozen.episodes.get(sp.name, ()) if int(seed) == frozen.seed else ()
    out = [held[s.index] if s.index < len(held) else s for s in specs]
    drawn = [s.index for s in out if not isinstance(s, FrozenEpisode)]
    if drawn:
        n = len(frozen.episodes.get(sp.name, ()))
        which = f"episode {drawn[0]}" if len(drawn) == 1 else f"episodes {drawn[0]}-{drawn[-1]}"
        holds = f"episodes 0-{n - 1} of seed {frozen.seed}" if n else "none"
        warnings.warn(
            f"{sp.name} {which} of seed {seed}: not frozen ({frozen.source} holds {holds}), so drawn from "
            "the current code, not from the frozen benchmark",
            UnfrozenEpisodesWarning,
            stacklevel=2,
        )
    return out


def frozen_count(specs: Sequence[EpisodeSpec]) -> int:
    """How many of ``specs`` are frozen episodes."""
    return sum(isinstance(s, FrozenEpisode) for s in specs)
