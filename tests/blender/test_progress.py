"""The bake's progress and ETA (licvdb.progress: pure functions) and the status text the modal
bake operators show (BakeJob.status)."""

import time

import pytest

from licvdb import ops_bake, progress


@pytest.mark.parametrize("stage, f, expected", [
    ("fast LIC", 0.4, 0.4),
    ("writing", 0.2, 1.0),  # the convolution is done; writing's own fraction would restart at 0
    ("frame 1 (1/4): fast LIC", 0.5, 0.125),
    ("frame 3 (3/4): writing", 0.0, 0.75),
    ("frame 4 (4/4): fast LIC", 1.0, 1.0),
    ("splat", -1.0, 0.0),  # (licvdb's "unknown" fraction)
    ("splat", 1.7, 1.0),
])
def test_task_fraction(stage, f, expected):
    assert progress.task_fraction(stage, f) == pytest.approx(expected)


def test_no_estimate_too_early():
    assert progress.remaining_seconds(10.0, 0.04) is None  # under 5 % done
    assert progress.remaining_seconds(1.5, 0.5) is None  # under 2 s
    assert progress.remaining_seconds(10.0, 1.0) is None  # done
    assert progress.eta_text(1.0, 0.9) == ""
    assert progress.remaining_seconds(10.0, 0.25) == pytest.approx(30.0)


@pytest.mark.parametrize("seconds, text", [
    (0.4, "0 s"), (7, "7 s"), (12, "10 s"), (57, "55 s"), (59, "1 min"), (80, "1 min 20 s"), (124, "2 min"),
    (3599, "1 h"), (3725, "1 h 2 min"), (7300, "2 h 2 min")])
def test_format_duration(seconds, text):
    assert progress.format_duration(seconds) == text


def test_eta_text():
    assert progress.eta_text(20.0, 0.2) == "about 1 min 20 s left"
    assert progress.eta_text(30.0, 0.5) == "about 30 s left"
    assert progress.eta_text(100.0, 0.999) == "almost done"


def test_status_shows_stage_and_eta():
    """What the status bar and the 3D view header say while a bake runs (no licvdb is started)."""
    job = ops_bake.BakeJob("licvdb", [("F.vdb", {})])
    try:
        job.index = 0
        job.stage, job.stage_fraction = "fast LIC", 0.01
        job.started = time.monotonic() - 1.0
        assert job.status().startswith("licvdb: baking F.vdb (1/1, fast LIC 1%), 1 s, Esc")  # too early to tell
        job.stage, job.stage_fraction = "frame 2 (2/4): fast LIC", 0.5  # 37.5 % of the sequence
        job.started = time.monotonic() - 30.0
        text = job.status()
        assert "frame 2 (2/4): fast LIC 50%" in text and "30 s, about 50 s left, Esc to cancel" in text, text
        assert job.fraction == pytest.approx(0.375)
    finally:
        job.cancelled = True
        assert job.finished  # (removes the job's folder)
