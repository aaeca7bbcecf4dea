"""Expert demonstrations: the classical stack's episodes as a dataset for imitation and
offline RL.

:func:`sim.rl.demo_recording.record_demonstrations` records them and writes one ``.npz``
that plain numpy reads (``np.load(path)``; no project import needed).
:func:`load_demonstrations` reads it back into a :class:`Demonstrations`;
:func:`export_minari` writes it as a Minari dataset.

The file (format ``depthnav-demonstrations``, version 1) holds N steps of E episodes one
after another: ``obs/<key>`` (N, ...) in the observation space's dtypes, ``actions``
(N, 3) float32, ``rewards``, ``terminations``, ``truncations`` (N,), ``final_obs/<key>``
(E, ...), the episode boundaries ``episode_starts`` and ``episode_lengths`` (E,), per
episode ``episode_index``, ``building_seed``, ``reset_seed``, ``success``, ``spl``,
``soft_spl``, ``collisions``, and a JSON ``meta`` string; docs/rl.md has the table. Within
an episode the observation after step t is ``obs[t + 1]``, after its last step
``final_obs[e]``. The actions are exactly the ones applied (float32, the action space's
type), so replaying them from the reset seed reproduces every observation bit for bit.

The dataset imports nothing else of :mod:`sim.rl`: behaviour cloning reads it, and the
recording (which runs the evaluation, which loads behaviour-cloned policies) sits above.
"""

from __future__ import annotations

import json
import os
import warnings
import zipfile
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, fields, is_dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from autonomy.common.errors import InputError
from autonomy.common.files import atomic_write

FORMAT = "depthnav-demonstrations"
VERSION = 1

#: Per-episode arrays and their dtypes (besides the boundaries and ``final_obs/``).
_EPISODE_FIELDS = {
    "episode_index": np.int64,
    "building_seed": np.int64,
    "reset_seed": np.int64,
    "success": np.bool_,
    "spl": np.float32,
    "soft_spl": np.float32,
    "collisions": np.int64,
}


@dataclass(frozen=True)
class Episode:
    """One episode of a :class:`Demonstrations` (views into its arrays)."""

    index: int
    building_seed: int
    reset_seed: int
    success: bool
    spl: float
    observations: Mapping[str, np.ndarray]
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    final_observation: Mapping[str, np.ndarray]

    def __len__(self) -> int:
        return len(self.actions)


@dataclass(frozen=True)
class Demonstrations:
    """A demonstration dataset: step arrays (N, ...) and per-episode arrays (E,)
    as the table in docs/rl.md lays them out."""

    observations: Mapping[str, np.ndarray]
    actions: np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    final_observations: Mapping[str, np.ndarray]
    episode_starts: np.ndarray
    episode_lengths: np.ndarray
    episode_index: np.ndarray
    building_seed: np.ndarray
    reset_seed: np.ndarray
    success: np.ndarray
    spl: np.ndarray
    soft_spl: np.ndarray
    collisions: np.ndarray
    meta: Mapping[str, Any] = field(default_factory=dict)

    @property
    def n_steps(self) -> int:
        return len(self.actions)

    @property
    def n_episodes(self) -> int:
        return len(self.episode_starts)

    def episodes(self) -> Iterator[Episode]:
        """The episodes in order."""
        for e in range(self.n_episodes):
            s = int(self.episode_starts[e])
            t = s + int(self.episode_lengths[e])
            yield Episode(
                index=int(self.episode_index[e]),
                building_seed=int(self.building_seed[e]),
                reset_seed=int(self.reset_seed[e]),
                success=bool(self.success[e]),
                spl=float(self.spl[e]),
                observations=MappingProxyType({k: v[s:t] for k, v in self.observations.items()}),
                actions=self.actions[s:t],
                rewards=self.rewards[s:t],
                terminations=self.terminations[s:t],
                truncations=self.truncations[s:t],
                final_observation=MappingProxyType({k: v[e] for k, v in self.final_observations.items()}),
            )

    def next_observations(self) -> dict[str, np.ndarray]:
        """The observation after every step, (N, ...) per key: ``obs[t + 1]`` within an
        episode, ``final_obs[e]`` after its last step."""
        ends = self.episode_starts + self.episode_lengths - 1
        out = {}
        for k, v in self.observations.items():
            nxt = np.empty_like(v)
            nxt[:-1] = v[1:]
            nxt[ends] = self.final_observations[k]
            out[k] = nxt
        return out

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the dataset to ``path`` (``.npz``, compressed), atomically."""
        p = Path(path)
        arrays: dict[str, np.ndarray] = {f"obs/{k}": v for k, v in self.observations.items()}
        arrays.update({f"final_obs/{k}": v for k, v in self.final_observations.items()})
        arrays.update(
            actions=self.actions, rewards=self.rewards, terminations=self.terminations, truncations=self.truncations,
            episode_starts=self.episode_starts, episode_lengths=self.episode_lengths,
        )
        arrays.update({k: getattr(self, k) for k in _EPISODE_FIELDS})
        arrays["meta"] = np.array(json.dumps(dict(self.meta), default=_jsonable))
        try:
            return atomic_write(p, lambda f: np.savez_compressed(f, **arrays))
        except OSError as e:
            raise InputError(f"{p}: cannot write the demonstrations ({e.strerror or e})") from None



def export_minari(demos: Demonstrations, dataset_id: str, description: str | None = None, data_format: str = "arrow"):
    """Write the dataset as a Minari dataset ``dataset_id`` (``namespace/name-vN``, under
    ``MINARI_DATASETS_PATH`` or ``~/.minari/datasets``) and return it. Needs the optional
    ``minari`` package (and pyarrow, or h5py for ``data_format="hdf5"``). Images are stored
    raw (Minari's JPEG encoding is lossy); each episode's observations are its T
    observations and the final one, Minari's T + 1."""
    try:
        import minari
        from minari.data_collector import EpisodeBuffer
        from minari.dataset.minari_dataset import parse_dataset_id
    except ImportError:
        raise InputError("Minari export needs the minari package (pip install minari)") from None
    try:  # before Minari makes any directory for it
        parse_dataset_id(str(dataset_id))
    except (ValueError, TypeError):  # TypeError: no -vN version
        raise InputError(f"Minari dataset {dataset_id!r}: expected an id (namespace/)name-vN, "
                         "e.g. depthnav/classical-train-v0 (a namespace has at least two characters)") from None
    from sim.envs.depthnav import make

    kw = {k: tuple(v) if isinstance(v, list) else v for k, v in demos.meta.get("env_kwargs", {}).items()}
    # The TimeLimit (in the spec Minari stores) at the recording's own max_steps.
    env = make(**kw, building_seeds=tuple(demos.meta.get("split_building_seeds", ())))
    buffers = [
        EpisodeBuffer(
            id=e,
            seed=ep.reset_seed,
            observations={k: np.concatenate([v, ep.final_observation[k][None]]) for k, v in ep.observations.items()},
            actions=ep.actions,
            rewards=ep.rewards.tolist(),
            terminations=ep.terminations.tolist(),
            truncations=ep.truncations.tolist(),
        )
        for e, ep in enumerate(demos.episodes())
    ]
    desc = description or (
        f"depthnav: the classical stack (FSPF, CGR, avoidance, navigator) on {demos.n_episodes} episodes of the "
        f"{demos.meta.get('split')!r} split (seed {demos.meta.get('seed')}), DepthNav-v0 with the learned-policy observations"
    )
    try:
        with warnings.catch_warnings():  # Minari's advice to name an author, a permalink, an eval env
            warnings.filterwarnings("ignore", message=r"`\w+` is set to None", category=UserWarning)
            return minari.create_dataset_from_buffers(
                dataset_id, buffers, env=env, algorithm_name=f"depthnav {demos.meta.get('policy', 'classical')}",
                description=desc, data_format=data_format, jpeg_encoding=False,
            )
    except ValueError as e:  # an existing or malformed id, an unknown data format
        raise InputError(f"Minari dataset {dataset_id!r}: {e}") from None
    finally:
        env.close()



def load_demonstrations(path: str | os.PathLike[str]) -> Demonstrations:
    """Read a dataset written by :func:`sim.rl.demo_recording.record_demonstrations`; a
    missing, corrupt or other-version file is a one-line :class:`InputError`."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"{p}: a directory, not a demonstrations file (expected the .npz of `depthnav demos record`)")
    if not p.is_file():
        raise InputError(f"{p}: demonstrations file not found")
    if not zipfile.is_zipfile(p):  # np.load would try it as a pickle and say so
        raise InputError(f"{p}: not a depthnav demonstrations file (not an .npz archive)")
    try:
        with np.load(p, allow_pickle=False) as z:
            names = set(z.files)
            if "meta" not in names:
                raise InputError(f"{p}: not a depthnav demonstrations file (no 'meta' entry)")
            meta = json.loads(str(z["meta"]))
            if not isinstance(meta, dict) or meta.get("format") != FORMAT:
                raise InputError(f"{p}: not a depthnav demonstrations file (format {meta.get('format') if isinstance(meta, dict) else None!r})")
            if meta.get("version") != VERSION:
                raise InputError(f"{p}: demonstrations format version {meta.get('version')!r}; this depthnav reads version {VERSION} (record it again)")
            arrays = {k: z[k] for k in names}
    except InputError:
        raise
    except Exception as e:  # zip, zlib, npy header, JSON ...
        raise InputError(f"{p}: not a depthnav demonstrations file ({type(e).__name__}: {e})") from None
    try:
        demos = Demonstrations(
            observations=MappingProxyType({k[4:]: v for k, v in sorted(arrays.items()) if k.startswith("obs/")}),
            final_observations=MappingProxyType({k[10:]: v for k, v in sorted(arrays.items()) if k.startswith("final_obs/")}),
            **{k: arrays[k] for k in ("actions", "rewards", "terminations", "truncations", "episode_starts", "episode_lengths", *_EPISODE_FIELDS)},
            meta=MappingProxyType(meta),
        )
    except KeyError as e:
        raise InputError(f"{p}: not a depthnav demonstrations file (no {e.args[0]!r} entry)") from None
    problem = _inconsistency(demos)
    if problem:
        raise InputError(f"{p}: corrupt demonstrations file ({problem})")
    return demos


def _inconsistency(d: Demonstrations) -> str:
    """What is wrong with the arrays' shapes and episode boundaries ('' if nothing)."""
    n, e = d.n_steps, d.n_episodes
    if d.actions.ndim != 2 or d.actions.shape[1] != 3:
        return f"actions of shape {d.actions.shape}, expected (N, 3)"
    if not d.observations or set(d.observations) != set(d.final_observations):
        return "observation keys of obs/ and final_obs/ differ"
    for k, v in d.observations.items():
        if len(v) != n:
            return f"obs/{k} has {len(v)} rows for {n} steps"
        f = d.final_observations[k]
        if f.shape != (e, *v.shape[1:]) or f.dtype != v.dtype:
            return f"final_obs/{k} of shape {f.shape}, expected {(e, *v.shape[1:])}"
    for k in ("rewards", "terminations", "truncations"):
        if getattr(d, k).shape != (n,):
            return f"{k} of shape {getattr(d, k).shape}, expected ({n},)"
    for k in ("episode_lengths", *_EPISODE_FIELDS):
        if getattr(d, k).shape != (e,):
            return f"{k} of shape {getattr(d, k).shape}, expected ({e},)"
    starts = np.concatenate([[0], np.cumsum(d.episode_lengths)[:-1]]) if e else np.zeros(0)
    if e and (np.any(d.episode_lengths < 1) or not np.array_equal(d.episode_starts, starts) or d.episode_lengths.sum() != n):
        return "episode_starts and episode_lengths do not tile the steps"
    if n and not e:
        return "steps without episodes"
    return ""


def _jsonable(o: Any) -> Any:
    """JSON for the meta record: dataclasses as their fields, tuples as lists, the rest as text."""
    if is_dataclass(o) and not isinstance(o, type):
        return {"__type__": type(o).__name__, **{f.name: getattr(o, f.name) for f in fields(o)}}
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    return repr(o)
