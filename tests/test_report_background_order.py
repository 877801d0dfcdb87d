"""The report's background studies go to its processes the longest first (by wave optics
the search and the tolerance study, several times their ray cost), and each study's
seconds in its process are kept for report.json."""

from __future__ import annotations

import os
import time

import pytest

from opticalstamp.analysis.responsivity import RAY, Optics
from opticalstamp.design import load_design
from opticalstamp.report import background
from opticalstamp.report.background import Background, study_workers
from opticalstamp.report.studies import job_order, study_jobs
from opticalstamp.report.work import report_work

WAVE = Optics("wave", "wave", "asked")


def test_by_wave_optics_the_search_and_tolerance_study_go_first():
    jobs = dict.fromkeys(["parameter_study", "rodlens", "search", "tolerance"], [])
    assert job_order(jobs, WAVE) == ["search", "tolerance", "parameter_study", "rodlens"]
    assert job_order(jobs, RAY) == list(jobs)  # as they were: the parts end with the rest
    # a design whose holes the studies cannot evaluate (circles): nothing to move
    assert job_order({"rodlens": []}, WAVE) == ["rodlens"]
    d = load_design("paper2016")
    work = report_work(False)
    assert list(study_jobs(d, 0, False, work, 200.0, optics=WAVE)) == job_order(jobs, WAVE)
    assert list(study_jobs(d, 0, False, work, 200.0, optics=RAY)) == list(jobs)


def test_each_study_keeps_its_seconds():
    jobs = {"nap": [(time.sleep, (0.4,)), (time.sleep, (0.3,))], "fails": [(int, ("x",))]}
    with Background(jobs, lambda name, results: results) as bg:
        assert bg.result("nap") == [None, None]  # its tasks' results (sleep's), unwrapped
        for _ in bg.as_completed():
            pass
        got = bg.seconds()
    assert set(got) == {"nap"}  # a failed job has no seconds
    assert got["nap"]["wall_s"] >= 0.7  # the two tasks' sum
    assert 0.0 <= got["nap"]["cpu_s"] < 0.5  # asleep: little CPU


def _square(payload: dict) -> dict:  # an evaluation (runs in a study's own processes)
    return {"y": payload["x"] ** 2}


def _spread_study(n: int, pid_file: str = "", nap: float = 0.0) -> list:
    """A background task that spreads its evaluations over two processes of its own, as
    the report's search and tolerance study do on a machine with idle cores; with
    ``pid_file``: those processes' ids written there, then a nap while they are alive."""
    import multiprocessing as mp

    from opticalstamp.studies.runner import WorkerPool, run_tasks

    with WorkerPool(2) as pool:
        if pid_file:
            ex = pool.executor()
            list(ex.map(abs, range(4)))  # started
            with open(pid_file, "w") as f:
                f.write(" ".join(str(p.pid) for p in mp.active_children()))
            ex.submit(time.sleep, 60.0)
            time.sleep(nap)
        recs = run_tasks(_square, [(str(i), {"x": i}) for i in range(n)], workers=2)
    return sorted(r["result"]["y"] for r in recs.values())


def test_a_background_study_may_spread_over_processes_of_its_own():
    """The report's processes are not daemons: a study in one of them starts a pool of
    its own (the search and the tolerance study where cores are idle) and gives its
    result; the task's cores count in what the report's sections leave themselves."""
    with Background({"spread": [(_spread_study, (6,), 3)]}) as bg:
        assert bg.running() == 3  # the study's process and its own two
        assert bg.result("spread") == [0, 1, 4, 9, 16, 25]
        for _ in bg.as_completed():
            pass
        assert bg.running() == 0
        cpu = bg.seconds()["spread"]["cpu_s"]
    # the CPU seconds of the study's own two processes too (each imported the library)
    assert cpu > 0.5, cpu


def _dies() -> None:  # a background process killed mid-task (the OOM killer, say)
    import os

    os._exit(9)


def test_a_study_whose_process_dies_is_not_measurable_and_the_rest_goes_on():
    """A study whose process dies gives "not measurable" with the reason (the report
    writes every other section); the report's figures are drawn here then."""
    from opticalstamp.report.section import NotMeasurable, measure

    with Background({"dies": [(_dies, ())], "nap": [(time.sleep, (0.2,))]}) as bg:
        res = measure(bg.result, "dies")
        assert isinstance(res, NotMeasurable) and "ended without" in res.reason
        for _ in bg.as_completed():
            pass
        assert bg.submit(abs, -1) is None  # the pool is broken: drawn here


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] not in "ZX"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")
def test_a_report_that_fails_leaves_no_study_process_behind(tmp_path):
    """A report that fails while a study runs ends its processes at once, and those the
    study started for its evaluations with them (none left behind asleep)."""
    pids = tmp_path / "pids"
    t0 = time.perf_counter()
    with pytest.raises(RuntimeError, match="a section failed"):
        with Background({"spread": [(_spread_study, (2, str(pids), 60.0), 3)]}):
            for _ in range(600):  # the study's processes started
                if pids.exists() and pids.read_text():
                    break
                time.sleep(0.1)
            raise RuntimeError("a section failed")
    assert time.perf_counter() - t0 < 60  # not the study's 60-s nap
    children = [int(p) for p in pids.read_text().split()]
    assert len(children) == 2
    for _ in range(100):
        if not any(map(_alive, children)):
            break
        time.sleep(0.1)
    assert not any(map(_alive, children))


KILLED = """
import sys, time
from opticalstamp.report.background import Background
if __name__ == "__main__":
    bg = Background({"nap": [(time.sleep, (60.0,)), (time.sleep, (60.0,))]})
    import multiprocessing as mp
    print(" ".join(str(p.pid) for p in mp.active_children()), flush=True)
    time.sleep(60.0)
"""


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")
def test_a_killed_report_leaves_no_background_process_behind(tmp_path):
    """A report killed outright (SIGKILL: no clean-up runs) leaves none of its background
    processes waiting for work that will never come: each ends with its parent."""
    import signal
    import subprocess
    import sys

    script = tmp_path / "killed.py"
    script.write_text(KILLED)
    with subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True) as proc:
        try:
            pids = [int(p) for p in proc.stdout.readline().split()]
            assert len(pids) == 2 and all(map(_alive, pids))
        finally:
            proc.send_signal(signal.SIGKILL)
            proc.wait()
    for _ in range(100):
        if not any(map(_alive, pids)):
            break
        time.sleep(0.1)
    assert not any(map(_alive, pids))


def test_the_studies_share_the_cores_the_report_leaves_idle(monkeypatch):
    """On 2 cores the search and the tolerance study run in their own process each, as
    before; on 16, with 5 tasks in 5 processes and one core for the sections, the 10 idle
    cores go 5 to each (6 processes each), by either optics; the report's jobs say so."""
    d = load_design("paper2016")
    work = report_work(False)
    for cores, want in [(1, 1), (2, 1), (4, 1), (8, 2), (16, 6)]:
        monkeypatch.setattr(background, "usable_cores", lambda c=cores: c)
        assert study_workers(5, 2) == want, cores
        for optics in (WAVE, RAY):
            jobs = study_jobs(d, 0, False, work, 200.0, optics=optics)
            for name in ("search", "tolerance"):
                ((fn, args, cores_of_task),) = jobs[name]
                assert cores_of_task == want and args[-1] == want, (cores, optics, name)
            assert all(len(t) == 2 for k in ("parameter_study", "rodlens") for t in jobs[k])
