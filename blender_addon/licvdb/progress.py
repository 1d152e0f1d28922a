"""How far a bake is and how long it has left, from licvdb's ``progress FRACTION STAGE`` lines
(``--progress lines``). Pure functions: no Blender, no clock (tests/blender/test_progress.py).

licvdb reports each stage's own fraction (0 → 1 for "fast LIC", again for "writing"); a sequence
names its frame: "frame 2 (2/3): fast LIC". ``task_fraction`` makes one rising fraction of them.
"""

import re

#: No estimate before this much of the bake is done, or this many seconds have passed: the first
#: percent of a bake says little about its pace.
ETA_MIN_FRACTION = 0.05
ETA_MIN_SECONDS = 2.0

_OF_N = re.compile(r"\((\d+)/(\d+)\)")


def task_fraction(stage: str, stage_fraction: float) -> float:
    """One bake's overall fraction in [0, 1] from licvdb's stage and its fraction: a frame k of n
    ("(k/n)" in the stage) counts (k − 1 + f)/n; a writing stage counts its frame's convolution as
    done (writing is short, and its own fraction would send the total back to 0)."""
    f = min(1.0, max(0.0, stage_fraction))
    if "writing" in stage:
        f = 1.0
    m = _OF_N.search(stage)
    if m:
        k, n = int(m.group(1)), max(1, int(m.group(2)))
        return min(1.0, (min(k, n) - 1 + f) / n)
    return f


def remaining_seconds(elapsed: float, fraction: float) -> float | None:
    """Seconds left at this pace, or None while too little is done (ETA_MIN_*) to tell."""
    if fraction < ETA_MIN_FRACTION or elapsed < ETA_MIN_SECONDS or fraction >= 1.0:
        return None
    return elapsed * (1.0 - fraction) / fraction


def format_duration(seconds: float) -> str:
    """"45 s", "1 min 20 s", "2 h 5 min": rounded to 5 s above 10 s, 10 s above a minute."""
    s = max(0, round(seconds))
    if s > 10:
        s = round(s / 5) * 5
    if s >= 60:
        s = round(s / 10) * 10
    if s >= 3600:
        m = round(s / 60)
        return f"{m // 60} h {m % 60} min" if m % 60 else f"{m // 60} h"
    if s >= 60:
        return f"{s // 60} min {s % 60} s" if s % 60 else f"{s // 60} min"
    return f"{s} s"


def eta_text(elapsed: float, fraction: float) -> str:
    """"about 1 min 20 s left", or "" while too little is done to tell."""
    left = remaining_seconds(elapsed, fraction)
    if left is None:
        return ""
    if left < 1.0:
        return "almost done"
    return f"about {format_duration(left)} left"
