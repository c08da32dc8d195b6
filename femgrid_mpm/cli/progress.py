"""The progress bars on a terminal: a run's (steps, simulated time and the time left) and
``reproduce``'s (its simulations, the last one done)."""

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


#: seconds between two lines of the count of runs where stderr is not a terminal
LINE_EVERY = 60.0


def runs_bar(total: int, enabled: bool):
    """A tqdm bar over ``total`` simulations on stderr, and the callback that counts one
    (its argument, the run's label, shown beside the bar); if not ``enabled`` (stderr is not a
    terminal: a log file, a CI job), no bar, and a line of the count at most every
    :data:`LINE_EVERY` seconds (the cost-accuracy study's 20 minutes were silent)."""
    if not enabled:
        import time

        started = last = time.monotonic()
        done = 0

        def line(label: str) -> None:
            nonlocal last, done
            done += 1
            now = time.monotonic()
            if now - last >= LINE_EVERY:
                last = now
                print(f"  {done} of {total} runs, {(now - started) / 60:.0f} min ({label})", file=sys.stderr, flush=True)

        return None, line
    from tqdm import tqdm

    bar = tqdm(total=total, unit="run", file=sys.stderr, dynamic_ncols=True,
               bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} runs{postfix} [{elapsed}<{remaining}]")

    def count(label: str) -> None:
        bar.set_postfix_str(label, refresh=False)
        bar.update(1)

    return bar, count
