"""The report's background studies go to its processes the longest first (by wave optics
the search and the tolerance study, several times their ray cost), and each study's
seconds in its process are kept for report.json."""

from __future__ import annotations

import time

from opticalstamp.analysis.responsivity import RAY, Optics
from opticalstamp.design import load_design
from opticalstamp.report.background import Background
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
