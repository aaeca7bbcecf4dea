"""Write the frozen benchmark episodes of ``DepthNav-v0`` (``sim/rl/episodes/DepthNav-v0.json``).

::

    python -m sim.rl.freeze_episodes            # write (or extend) the file
    python -m sim.rl.freeze_episodes --check    # regenerate and compare, write nothing

For each of ``val`` and ``test``, the episodes of ``episode_specs(split, N, seed=0)``
(N = ``--episodes``, default 100) are reset in the env the evaluation makes for them (one
env per building, :func:`sim.rl.evaluate.episode_env_kwargs`: the benchmark task on the
episode's building; a policy's observation settings do not change what a reset draws),
and what the env produced is recorded (:func:`sim.rl.benchmark_episodes.reset_record`:
the building and reset seed, the start pose, the goal and its graph node, the start-goal
geodesic distance, the furniture and the people). ``depthnav eval`` then takes the
episodes from the file and checks every reset against it.

An existing file is the benchmark: it is rewritten only where the regenerated episodes
agree with it (to add episodes, say); where they differ, nothing is written and the
difference is reported, because a change that alters the episodes is a new version of the
task (a new env id and its own file, docs/rl.md), not a new v0. ``--check`` regenerates as
many episodes as the file holds and exits 1 at the first that differs. Resetting the 200
episodes takes under a minute once a process is warm.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write_text
from sim.rl.benchmark_episodes import (
    FIELDS,
    FORMAT,
    FORMAT_VERSION,
    FROZEN_EPISODES,
    FROZEN_SEED,
    FROZEN_SPLITS,
    TASK_ID,
    episodes_file,
    first_difference,
    shown_path,
    split_record,
    task_record,
)
from sim.rl.splits import EpisodeSpec, episode_specs, get_split


def produce(specs: Sequence[EpisodeSpec], on_episode: Callable[[dict[str, Any]], None] | None = None) -> list[dict[str, Any]]:
    """Reset the env of each spec (grouped by building, one env per building, as the
    evaluation runs them) and return what it produced at each reset, in spec order."""
    from sim.envs.depthnav import make
    from sim.rl.benchmark_episodes import reset_record
    from sim.rl.evaluate import episode_env_kwargs
    from sim.rl.policies import RandomPolicy

    groups: dict[int, list[EpisodeSpec]] = {}
    for s in specs:
        groups.setdefault(s.building_seed, []).append(s)
    out: dict[int, dict[str, Any]] = {}
    for b, group in groups.items():
        # RandomPolicy asks for no env arguments: the benchmark task on building b, alone.
        env = make(**episode_env_kwargs(RandomPolicy(), b))
        try:
            for s in group:
                _, info = env.reset(seed=s.reset_seed)
                if env.unwrapped.site.seed != s.building_seed:
                    raise RuntimeError(f"freeze: the env is on building {env.unwrapped.site.seed}, episode {s.index} on {s.building_seed}")
                out[s.index] = reset_record(env, info, s)
                if on_episode is not None:
                    on_episode(out[s.index])
        finally:
            env.close()
    return [out[s.index] for s in specs]


def freeze_document(episodes: int = FROZEN_EPISODES, seed: int = FROZEN_SEED, progress: bool = False) -> dict[str, Any]:
    """The frozen-episodes document of the current code: ``episodes`` episodes of each of
    :data:`FROZEN_SPLITS` for ``seed``."""
    splits = {}
    for name in FROZEN_SPLITS:
        sp = get_split(name)
        specs = episode_specs(sp, episodes, seed)
        done = [0]

        def tick(_rec: dict[str, Any], name: str = name, done: list[int] = done) -> None:
            done[0] += 1
            if progress:
                print(f"\r{name}: {done[0]}/{episodes} episodes", end="", file=sys.stderr, flush=True)

        splits[name] = {**split_record(sp), "episodes": produce(specs, tick)}
        if progress:
            print(file=sys.stderr)
    return {
        "format": FORMAT,
        "version": FORMAT_VERSION,
        "task_id": TASK_ID,
        "written_by": "python -m sim.rl.freeze_episodes",
        "seed": seed,
        "task": task_record(),
        "fields": FIELDS,
        "splits": splits,
    }


def to_text(doc: dict[str, Any]) -> str:
    """The document as JSON with one episode a line (small, and a changed episode is one
    changed line in a diff)."""
    lines = ["{"]
    head = [k for k in doc if k != "splits"]
    for k in head:
        lines.append(f"  {json.dumps(k)}: {json.dumps(doc[k], indent=None)},")
    lines.append('  "splits": {')
    names = list(doc["splits"])
    for i, name in enumerate(names):
        sp = doc["splits"][name]
        lines.append(f"    {json.dumps(name)}: {{")
        for k in sp:
            if k != "episodes":
                lines.append(f"      {json.dumps(k)}: {json.dumps(sp[k])},")
        lines.append('      "episodes": [')
        eps = sp["episodes"]
        lines += [f"        {json.dumps(e, separators=(',', ':'))}" + ("," if j < len(eps) - 1 else "") for j, e in enumerate(eps)]
        lines.append("      ]")
        lines.append("    }" + ("," if i < len(names) - 1 else ""))
    lines += ["  }", "}"]
    text = "\n".join(lines) + "\n"
    assert json.loads(text) == doc
    return text


def differences(old: dict[str, Any], new: dict[str, Any], source: str) -> str | None:
    """The first difference between two documents' common episodes (and task, seed and
    splits), as a one-line message naming ``source``; None where they agree."""
    for key in ("task_id", "seed", "task"):
        if old.get(key) != new.get(key):
            return f"{source}: the frozen {key} {old.get(key)!r} differs from the code's {new.get(key)!r}"
    for name, sp in new["splits"].items():
        frozen = (old.get("splits") or {}).get(name)
        if frozen is None:
            continue
        if {k: frozen.get(k) for k in ("building_seeds", "episode_seed")} != {k: sp[k] for k in ("building_seeds", "episode_seed")}:
            return f"{source}: the frozen {name} split (buildings, episode seed) differs from the code's"
        for a, b in zip(frozen.get("episodes", []), sp["episodes"], strict=False):
            diff = first_difference(a, b)
            if diff is not None:
                return f"{source}: {name} episode {a.get('index')}: {diff}"
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim.rl.freeze_episodes", description=__doc__.split("\n")[0].replace("``", ""))
    ap.add_argument("--episodes", type=int, help=f"episodes of each split (default: as many as the file holds, else {FROZEN_EPISODES})")
    ap.add_argument("--out", type=Path, default=None, help=f"the file (default {shown_path(episodes_file())})")
    ap.add_argument("--check", action="store_true", help="regenerate the file's episodes and compare; write nothing")
    ap.add_argument("--no-progress", action="store_true", help="no progress line on stderr")
    args = ap.parse_args(argv)
    path = args.out or episodes_file()
    src = shown_path(path)
    try:
        old = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else None
        held = min((len(sp.get("episodes", [])) for sp in (old or {}).get("splits", {}).values()), default=0)
        n = args.episodes if args.episodes is not None else (held or FROZEN_EPISODES)
        if n < 1:
            raise InputError(f"--episodes: expected an integer >= 1, got {n}")
        if args.check and old is None:
            raise InputError(f"{src}: no frozen episodes to check")
        if not args.check and held > n:
            raise InputError(f"{src}: holds {held} episodes a split; --episodes {n} would drop some")
        if not args.check and not path.parent.is_dir():
            # Checked before the episodes are made, so a mistyped --out costs nothing.
            raise InputError(f"--out {src}: expected a file in an existing directory, {shown_path(path.parent)} is none")
        doc = freeze_document(n, progress=not args.no_progress)
        diff = None if old is None else differences(old, doc, src)
        if diff is not None:
            print(f"freeze_episodes: {diff}: a changed benchmark is a new version of the task (docs/rl.md); "
                  "nothing written", file=sys.stderr)
            return 1
        if args.check:
            print(f"{src}: the current code produces the {n} frozen episodes of each of {', '.join(FROZEN_SPLITS)}")
            return 0
        text = to_text(doc)
        atomic_write_text(path, text)
        print(f"wrote {src}: {n} episodes of each of {', '.join(FROZEN_SPLITS)} (seed {FROZEN_SEED}), {len(text.encode())} bytes")
        return 0
    except (InputError, json.JSONDecodeError) as e:
        print(f"freeze_episodes: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"freeze_episodes: error: {src}: {e.strerror or e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
