"""A fault's record in the run's log, and the state of one that is active.

Every fault, applied or skipped, is one record (a dict, written to the run's report as
it is): what started it, the true pose before and after, its parameters, and what its
kind adds (where it landed, why it was skipped ...). :class:`ActiveFault` ties a record
to the parameters it runs with and when it ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.simulator.fault_config import KIND_PARAMS, FaultParams


@dataclass
class ActiveFault:
    """A fault in progress: its record (``t_end`` set when it ends), its parameters and
    the simulated time it ends at (inf: the rest of the run)."""

    record: dict
    params: FaultParams
    end_t: float


def pose_list(p: np.ndarray) -> list[float]:
    """A pose as plain floats, for the record."""
    return [float(v) for v in p]


def new_record(kind: str, params: FaultParams, trigger: str, t: float, distance_m: float, before: np.ndarray) -> dict:
    """The record of a fault of ``kind`` starting now (``t_end`` and ``truth_after`` still
    None), with the parameters its kind uses."""
    return {
        "kind": kind,
        "t_start": float(t),
        "t_end": None,
        "distance_m": float(distance_m),
        "trigger": trigger,
        "truth_before": pose_list(before),
        "truth_after": None,
        "params": {k: getattr(params, k) for k in KIND_PARAMS[kind]},
    }
