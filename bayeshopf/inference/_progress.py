"""Chunked, jitted optimisation loops with a tqdm progress bar."""

from __future__ import annotations

import sys

import jax
import numpy as np
from tqdm.auto import tqdm


def run_chunked(step, carry, n_steps: int, *, desc: str, progress: bool, chunk: int = 100):
    """Run ``carry, loss = step(carry)`` ``n_steps`` times in jitted chunks of ``chunk``.

    Returns:
        The final carry and the losses, shape ``(n_steps,)``.
    """

    @jax.jit
    def run(carry):
        return jax.lax.scan(lambda c, _: step(c), carry, None, length=chunk)

    losses = []
    with tqdm(total=n_steps, desc=desc, disable=not progress, file=sys.stderr, leave=False) as bar:
        done = 0
        while done < n_steps:
            carry, loss = run(carry)
            take = min(chunk, n_steps - done)
            losses.append(np.asarray(loss)[:take])
            done += chunk
            bar.update(take)
            bar.set_postfix(loss=f"{float(losses[-1][-1]):.4g}")
    return carry, np.concatenate(losses) if losses else np.zeros(0)
