"""Seeds of a campaign: one ``numpy.random.SeedSequence`` per run index, derived from the master seed.

Run i's sequence is ``SeedSequence(master).spawn(N)[i]`` for any N > i, which equals
``SeedSequence(master, spawn_key=(i,))``; building it directly means a run's seed depends only on
(master, i): never on the number of runs, the number of workers or the order runs execute in.
Inside a run, the sequence splits again: one child per dispersion (keyed by the dispersion's NAME, so
adding or removing another dispersion leaves this one's draws alone) and one for the simulation
(noise processes in the world and the sensors).
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

_DISPERSION_BRANCH = 0
_SIMULATION_BRANCH = 1


def run_sequence(master_seed: int, run_index: int) -> np.random.SeedSequence:
    """The SeedSequence of run ``run_index`` (identical to ``SeedSequence(master).spawn(n)[run_index]``)."""
    if run_index < 0:
        raise ValueError(f"run index must be >= 0, got {run_index}")
    return np.random.SeedSequence(master_seed, spawn_key=(run_index,))


def _name_key(name: str) -> int:
    # A stable 32-bit key (Python's hash() is salted per process, so it cannot be used here).
    return int.from_bytes(hashlib.sha256(name.encode()).digest()[:4], "little")


@dataclass(frozen=True)
class RunSeeds:
    """Everything random about one run, derived from (master seed, run index)."""

    master_seed: int
    run_index: int

    @property
    def sequence(self) -> np.random.SeedSequence:
        return run_sequence(self.master_seed, self.run_index)

    def dispersion_rng(self, name: str) -> np.random.Generator:
        """Generator for the dispersion called ``name`` in this run."""
        seq = np.random.SeedSequence(self.master_seed,
                                     spawn_key=(self.run_index, _DISPERSION_BRANCH, _name_key(name)))
        return np.random.default_rng(seq)

    @property
    def simulation_seed(self) -> int:
        """Integer seed for the simulation's noise processes (the mission's ``seed`` key, 32 bits)."""
        seq = np.random.SeedSequence(self.master_seed, spawn_key=(self.run_index, _SIMULATION_BRANCH))
        return int(seq.generate_state(1, dtype=np.uint32)[0])
