"""The wave fit's runs (issue 24): the wave model's spreads at the fit's points, each
run once and kept, side by side on a pool of processes (a Jacobian's columns, the
geodesic acceleration's probes, the secant check's probes with their nuisance refitted,
the starts)."""

from __future__ import annotations

import os
from collections import OrderedDict
from contextlib import contextmanager

import numpy as np
from threadpoolctl import threadpool_limits

from ..design import Design
from .fitmodel import with_params
from .fitproblem import Problem
from .fitwave import WaveModel

#: Processes at most for the wave runs of a Jacobian (:func:`wave_pool`), and the fewest
#: runs at once worth them.
WAVE_WORKERS = 4
POOL_MIN_RUNS = 6
#: Wave runs kept for reading again (a Jacobian's, the points the optimiser revisits).
MEMO_RUNS = 64


def refit_job(job):  # pragma: no cover - runs in the pool's processes
    """A point's wave run (or the one given), its nuisance fitted again and its sum of
    squares, as :func:`~.fitident.secant_estimate` does them in the fit's own process:
    (point, sum or NaN, the run's spreads or None)."""
    wave, design, obs, lay, hold, prior, zs, smear, made, theta = job
    with threadpool_limits(limits=1, user_api="blas"):  # as the fit's own process
        if made is None:
            try:
                made = wave(with_params(design, list(lay.params), lay.physical(theta)), zs, smear)
            except ValueError:  # a rule broken or no light: not measured
                return theta, np.nan, None
        prob = Problem(design, obs, lay, hold=hold, prior=prior, model=lambda d, z, s, v: made)
        q = prob.fit_nuisance(theta, search=False)
        return q, float(np.sum(prob.residuals(q) ** 2)), made


def wave_run(job):  # pragma: no cover - runs in the pool's processes
    model, design, zs, smear = job
    with threadpool_limits(limits=1, user_api="blas"):  # as the fit's own process
        try:
            return model(design, zs, smear)
        except ValueError:  # no light: the fit's own process says so where it reads it
            return None


@contextmanager
def wave_pool(jobs: int = 0):
    """Processes (one a core, or ``jobs`` where more, at most WAVE_WORKERS; none on one
    core) for the wave runs of a Jacobian's columns and the starts, independent runs each
    in a process: a callable ``(fn, jobs) -> results``, which starts them at its first
    call (spawning costs a few seconds: a fit that never runs POOL_MIN_RUNS at once never
    starts them). The starts side by side on as many processes as there are starts: on 2
    cores 3 starts took the longest after one of the first two (45 s of the benchmark's
    fit), all three at once share the cores to the end; a Jacobian's 15 columns make 5
    rounds of 3 rather than 8 of 2."""
    cores = os.cpu_count() or 1
    n = min(max(cores, jobs), WAVE_WORKERS)
    if cores < 2:
        yield None
        return
    from .runner import process_pool

    made = []

    def run(fn, jobs):
        if not made:
            made.append(process_pool(n))  # spawned: no fork of numba's threads
        return list(made[0].map(fn, jobs))

    try:
        yield run
    finally:
        for pool in made:
            pool.shutdown()


class WaveRuns:
    """The wave model's spreads of the design at physical values of the fit's parameters,
    each point run once (the last MEMO_RUNS kept): a call reads (or runs) one point,
    :meth:`prefetch` runs the points not run yet side by side on the pool (batches of
    POOL_MIN_RUNS or more; a point whose design breaks a rule or passes no light is left
    to the call, which raises as a run of its own would)."""

    def __init__(self, wave: WaveModel, design: Design, params: list, zs, smear, pool):
        self.wave, self.design, self.params = wave, design, params
        self.zs, self.smear, self.pool = zs, smear, pool
        self.memo: OrderedDict[bytes, dict] = OrderedDict()
        self.runs = 0

    def _keep(self, key: bytes, spreads: dict) -> None:
        self.memo[key] = spreads
        self.runs += 1
        while len(self.memo) > MEMO_RUNS:
            self.memo.popitem(last=False)

    def __call__(self, phys) -> dict:
        key = np.asarray(phys, dtype=np.float64).tobytes()
        if key not in self.memo:
            d = with_params(self.design, self.params, phys)
            self._keep(key, self.wave(d, self.zs, self.smear))
        return self.memo[key]

    def refits(self, prob: Problem, points, min_runs: int = POOL_MIN_RUNS) -> list | None:
        """Each point of ``prob`` (a problem of this fit on the wave model, its hold and
        prior included) with its images' nuisance fitted again from where it is, and its
        sum of squares (the data, the held directions' penalty and the prior's): the wave
        run (unless kept), the refit and the sum side by side on the pool, each new run
        kept; NaN where the point's design breaks a rule or passes no light. None where
        there is no pool or fewer than ``min_runs`` points (the caller does them)."""
        if self.pool is None or len(points) < min_runs:
            return None
        keys = [prob.lay.physical(p).tobytes() for p in points]
        fixed = (self.wave, prob.design, prob.obs, prob.lay, prob.hold, prob.prior)
        jobs = [
            fixed + (self.zs, self.smear, self.memo.get(k), p)
            for k, p in zip(keys, points, strict=True)
        ]
        out = []
        for key, job, (q, value, made) in zip(keys, jobs, self.pool(refit_job, jobs), strict=True):
            if made is not None and job[-2] is None:
                self._keep(key, made)
            out.append((q, value))
        return out

    def prefetch(self, points, min_runs: int = POOL_MIN_RUNS) -> None:
        if self.pool is None:
            return
        todo = {}
        for phys in points:
            key = np.asarray(phys, dtype=np.float64).tobytes()
            if key in self.memo or key in todo:
                continue
            try:
                todo[key] = with_params(self.design, self.params, phys)
            except ValueError:  # a rule broken: the call says so
                continue
        if len(todo) < min_runs:
            return
        jobs = [(self.wave, d, self.zs, self.smear) for d in todo.values()]
        for key, sp in zip(todo, self.pool(wave_run, jobs), strict=True):
            if sp is not None:
                self._keep(key, sp)
