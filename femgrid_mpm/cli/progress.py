"""The progress bar of a run on a terminal: steps, simulated time and the time left."""

from __future__ import annotations

import os
import sys


def progress_bar(simulation, enabled: bool):
    """A tqdm bar of steps, simulated time and ETA on stderr, and its update callback; (None, None) if not enabled."""
    if not enabled:
        return None, None
    from tqdm import tqdm

    end = simulation.n_steps * simulation.dt
    try:  # a terminal that reports no size (some ptys) would get no bar at all
        sized = min(os.get_terminal_size(sys.stderr.fileno())) > 0
    except (OSError, ValueError):
        sized = False
    bar = tqdm(
        total=simulation.n_steps,
        initial=simulation.step_index,  # a resumed run starts at its checkpoint
        unit="step",
        file=sys.stderr,
        dynamic_ncols=sized,
        ncols=None if sized else 100,
        nrows=None if sized else 24,
        bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} steps{postfix} [{elapsed}<{remaining}]",
    )
    bar.set_postfix_str(f"t = 0/{end:.4g} s", refresh=False)

    def progress(step: int, time: float) -> None:
        bar.set_postfix_str(f"t = {time:.4g}/{end:.4g} s", refresh=False)
        bar.update(step - bar.n)

    return bar, progress
